"""From a smoothed segment to the flight data the regression reads (method.md §7–§10):
air data (the US-1976 atmosphere, or the measured ``rho_kg_m3``, ``qbar_pa``,
``p_static_pa``, ``T_total_K`` columns when the telemetry has them: see
``aerosid.atmosphere.air_data`` and ``flight_air_data_sources``), flight coefficients,
control mixing, and alpha/beta, either inverted from the force database (the finned
class) or read from air-data vanes (a vehicle file with ``[air_data] source = "vanes"``)."""
from __future__ import annotations

import numpy as np
import pandas as pd

from aerosid.aerodb import AeroDatabase
from aerosid.atmosphere import MEASURED, H_MAX_M, H_MIN_M, AirDataError, air_data, air_data_sources
from aerosid.flight_coefficients import flight_coefficients
from aerosid.derivatives import zero_phase_low_pass
from aerosid.inversion import invert_alpha_beta, total_angles
from aerosid.vehicle import Vehicle

FIN_COLUMNS = ("d1_rad", "d2_rad", "d3_rad", "d4_rad")


def load_database(vehicle: Vehicle) -> AeroDatabase | None:
    """The vehicle's force database, or None when alpha/beta come from vanes without one."""
    if vehicle.air_data_source == "vanes" and vehicle.database_path is None:
        return None
    return AeroDatabase.load(vehicle.database_path)


def _vane_angles(measured: pd.DataFrame, ok: np.ndarray, vehicle: Vehicle, t: np.ndarray):
    """alpha, beta [rad] from the vanes' clean columns (zero-phase low-passed) minus the
    calibration bias, and the total angle of attack alpha_r and aerodynamic roll angle
    phi_r derived from them.  build_flight_data has checked that the columns exist."""
    ts = t[ok]
    fs = 1.0 / float(np.median(np.diff(ts))) if ts.size > 1 else 1.0
    a, b = (zero_phase_low_pass(measured[f"{col}_clean"].to_numpy(dtype=float)[ok], fs, vehicle.vane_cutoff_hz)
            - bias for col, bias in ((vehicle.alpha_column, vehicle.alpha_bias_rad),
                                     (vehicle.beta_column, vehicle.beta_bias_rad)))
    return (a, b, *total_angles(a, b))


def measured_air_data_columns(columns) -> tuple[str, ...]:
    """The measured air-data channels a preprocessed frame carries (as ``<name>_clean``)."""
    have = set(columns)
    return tuple(c for c in MEASURED if f"{c}_clean" in have)


def flight_air_data_sources(columns) -> dict[str, str]:
    """Where the flight data of a preprocessed frame with these columns takes its
    density, static temperature, Mach and dynamic pressure from."""
    return air_data_sources(measured_air_data_columns(columns))


def _span(t: np.ndarray) -> str:
    """A time span for messages: 't0..t1 s (first t_s [...])'."""
    return f"{t[0]:.2f}..{t[-1]:.2f} s (first t_s {[round(float(v), 3) for v in t[:5]]})" if len(t) else "-"


def build_flight_data(smoothed: pd.DataFrame, measured: pd.DataFrame, vehicle: Vehicle, db: AeroDatabase | None,
                      flight: str = "flight") -> pd.DataFrame:
    """smoothed: a SmoothedSegment frame; measured: the preprocessed rows of the same
    segment (same t_s), whose ``*_clean`` columns give fins, V, h and any measured air
    data.  Rows where V, h, a fin or a measured air-data value is unavailable (inside
    an unfilled gap) are left out."""
    t = smoothed["t_s"].to_numpy()
    if len(measured) != len(t) or not np.allclose(measured["t_s"].to_numpy(), t, atol=1e-9, rtol=0):
        raise ValueError("smoothed and measured frames are not on the same time grid")
    segment = str(smoothed["segment"].iloc[0]) if len(smoothed) else "?"
    vanes = vehicle.air_data_source == "vanes"
    airdata = measured_air_data_columns(measured.columns)
    cols = (*FIN_COLUMNS, "V_m_s", "h_m", *airdata) + ((vehicle.alpha_column, vehicle.beta_column) if vanes else ())
    missing = [c for c in cols if f"{c}_clean" not in measured]
    if missing:
        raise ValueError(f"segment {segment}: the preprocessed telemetry has no column(s) "
                         f"{[c + '_clean' for c in missing]} (vehicle {vehicle.name}, {vehicle.source})")
    clean = {c: measured[f"{c}_clean"].to_numpy(dtype=float) for c in cols}
    ok = np.all(np.isfinite(np.column_stack(list(clean.values()))), axis=1) & (clean["V_m_s"] > 0)
    h_out = ok & ~((clean["h_m"] >= H_MIN_M) & (clean["h_m"] <= H_MAX_M))
    if h_out.any():
        raise ValueError(f"segment {segment}: column 'h_m' outside the US-1976 atmosphere's {H_MIN_M:g}.."
                         f"{H_MAX_M:g} m at {int(h_out.sum())} rows, t = {_span(t[h_out])}")
    s = smoothed.loc[ok].reset_index(drop=True)
    fins = [clean[c][ok] for c in FIN_COLUMNS]
    V, h = clean["V_m_s"][ok], clean["h_m"][ok]
    delta_r, delta_p, delta_y = (np.asarray(x) for x in vehicle.mix(*fins))
    acc = s[["X1_m_s2", "Y1_m_s2", "Z1_m_s2"]].to_numpy()
    ang = s[["L1_rad_s2", "M1_rad_s2", "N1_rad_s2"]].to_numpy()
    acc_sig = s[["sigma_X1_m_s2", "sigma_Y1_m_s2", "sigma_Z1_m_s2"]].to_numpy()
    ang_sig = s[["sigma_L1_rad_s2", "sigma_M1_rad_s2", "sigma_N1_rad_s2"]].to_numpy()
    try:
        air = air_data(V, h, **{c: clean[c][ok] for c in airdata})
    except AirDataError as exc:
        raise ValueError(f"segment {segment}: {exc}, t = {_span(s['t_s'].to_numpy()[exc.positions])}") from None
    fc = flight_coefficients(vehicle, V, h, acc, ang, acc_sig, ang_sig, air=air)
    if vanes:
        alpha, beta, alpha_r, phi_r = _vane_angles(measured, ok, vehicle, t)
        inv_J = np.zeros(len(alpha))
    else:
        alpha, beta, alpha_r, phi_r, inv_J = _inverted_angles(fc, s, delta_p, delta_y, vehicle, db, segment)
    coef = {"CA": fc.CA, "CY": fc.CY, "CN": fc.CN, "Cl": fc.Cl, "Cm": fc.Cm, "Cn": fc.Cn}
    rates = {c: s[c].to_numpy() for c in ("p_rad_s", "q_rad_s", "r_rad_s")}
    return pd.DataFrame({
        "t_s": s["t_s"].to_numpy(),
        "flight": flight,
        "segment": s["segment"].to_numpy(),
        "V_m_s": V, "h_m": h,
        "rho_kg_m3": fc.air.rho_kg_m3, "mach": fc.air.mach, "qbar_pa": fc.air.qbar_pa,
        **coef,
        **{f"sigma_{k}": v for k, v in fc.sigma.items()},
        "alpha_rad": alpha, "beta_rad": beta,
        "alpha_r_rad": alpha_r, "phi_r_rad": phi_r, "inversion_J": inv_J,
        "delta_p_rad": delta_p, "delta_y_rad": delta_y, "delta_r_rad": delta_r,
        **rates,
    })


def _inverted_angles(fc, s: pd.DataFrame, delta_p, delta_y, vehicle: Vehicle, db: AeroDatabase, segment: str):
    """alpha, beta, alpha_r, phi_r [rad] and the inversion cost from the force database."""
    m_lo, m_hi = db.mach_range()
    outside = ~((fc.air.mach >= m_lo) & (fc.air.mach <= m_hi))
    if outside.any():
        # the inversion would clamp the table at its edge: alpha and beta there would be made up
        ts = s["t_s"].to_numpy()[outside]
        m = fc.air.mach[outside]
        origin = ("from columns 'V_m_s' and 'h_m'" if "T_total_K" not in fc.air.sources["mach"]
                  else "from columns 'V_m_s' and 'T_total_K'")
        raise ValueError(f"segment {segment}: Mach ({origin}) is {m.min():.3g}..{m.max():.3g} "
                         f"at {int(outside.sum())} samples, t = {_span(ts)}, outside the aerodynamic database's "
                         f"Mach {m_lo:g}..{m_hi:g} ({vehicle.database_path}); alpha/beta cannot be inverted "
                         "there: restrict the run to the database's range (--window T0 T1) or extend the database")
    inv = invert_alpha_beta(fc.CN, fc.CY, fc.air.mach, delta_p, delta_y, db, vehicle.preflight)
    return inv.alpha_rad, inv.beta_rad, inv.alpha_r_rad, inv.phi_r_rad, inv.J


def build_flight_data_segments(preprocessed: pd.DataFrame, smoothed: list[pd.DataFrame], vehicle: Vehicle,
                               db: AeroDatabase | None, flight: str = "flight") -> pd.DataFrame:
    """Flight data of several smoothed segments of one preprocessed flight, pooled:
    each segment is matched to the preprocessed rows of its own time span."""
    t = preprocessed["t_s"].to_numpy()
    parts = []
    for sm in smoothed:
        ts = sm["t_s"].to_numpy()
        start = int(np.searchsorted(t, ts[0] - 1e-9))
        rows = preprocessed.iloc[start:start + len(ts)].reset_index(drop=True)
        parts.append(build_flight_data(sm, rows, vehicle, db, flight))
    return pd.concat(parts, ignore_index=True)


def build_pooled_flight_data(flights: list[tuple[str, pd.DataFrame, list[pd.DataFrame]]], vehicle: Vehicle,
                             db: AeroDatabase | None) -> pd.DataFrame:
    """Flight data of several manoeuvres of one aircraft, pooled for one regression:
    ``flights`` holds (flight id, preprocessed frame, its smoothed segments) per
    manoeuvre, each preprocessed and smoothed on its own.  The ids must differ (the
    regression's derivatives and residual correction work per flight)."""
    ids = [f for f, _, _ in flights]
    if len(set(ids)) < len(ids):
        raise ValueError(f"pooled flights need distinct ids, got {ids}")
    return pd.concat([build_flight_data_segments(pre, smoothed, vehicle, db, fid) for fid, pre, smoothed in flights],
                     ignore_index=True)
