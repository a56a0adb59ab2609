"""From a smoothed segment to the flight data the regression reads (method.md §7–§10):
air data, flight coefficients, control mixing, and alpha/beta, either inverted from
the force database (the finned class) or read from air-data vanes (a vehicle file
with ``[air_data] source = "vanes"``)."""
from __future__ import annotations

import numpy as np
import pandas as pd

from aerosid.aerodb import AeroDatabase
from aerosid.atmosphere import H_MAX_M, H_MIN_M
from aerosid.flight_coefficients import flight_coefficients
from aerosid.derivatives import zero_phase_low_pass
from aerosid.identification.band import band_limited_signals, finite_runs, low_pass_runs
from aerosid.inversion import invert_alpha_beta, total_angles
from aerosid.vehicle import Vehicle

FIN_COLUMNS = ("d1_rad", "d2_rad", "d3_rad", "d4_rad")
BAND_IMU = ("ax_m_s2", "ay_m_s2", "az_m_s2", "p_rad_s", "q_rad_s", "r_rad_s")


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


def _span(t: np.ndarray) -> str:
    """A time span for messages: 't0..t1 s (first t_s [...])'."""
    return f"{t[0]:.2f}..{t[-1]:.2f} s (first t_s {[round(float(v), 3) for v in t[:5]]})" if len(t) else "-"


def build_flight_data(smoothed: pd.DataFrame, measured: pd.DataFrame, vehicle: Vehicle, db: AeroDatabase | None,
                      flight: str = "flight", signals: str = "band") -> pd.DataFrame:
    """smoothed: a SmoothedSegment frame; measured: the preprocessed rows of the same
    segment (same t_s), whose ``*_clean`` columns give fins, V and h.  Rows where V, h
    or a fin is unavailable (inside an unfilled gap) are left out.

    signals: "band" (default) -- rates, angular and linear accelerations from the
    measured gyros and accelerometers, and every regressor, through one common
    low-pass (aerosid.identification.band: the band edge from the flight's gyro
    spectrum, or the vehicle file's ``[estimation] band_hz``); the smoother's states
    then serve the checks (NIS, gates, divergence) and the per-sample sigma.
    "smoother" -- the smoother's states as the method's seed has it (each chain with
    the bandwidth its process noise gives it)."""
    t = smoothed["t_s"].to_numpy()
    if len(measured) != len(t) or not np.allclose(measured["t_s"].to_numpy(), t, atol=1e-9, rtol=0):
        raise ValueError("smoothed and measured frames are not on the same time grid")
    segment = str(smoothed["segment"].iloc[0]) if len(smoothed) else "?"
    vanes = vehicle.air_data_source == "vanes"
    cols = (*FIN_COLUMNS, "V_m_s", "h_m") + ((vehicle.alpha_column, vehicle.beta_column) if vanes else ())
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
    band_hz = np.nan
    if signals == "band":
        imu = {c: measured[f"{c}_clean"].to_numpy(dtype=float) for c in BAND_IMU}
        bl = band_limited_signals(t, np.column_stack([imu[c] for c in BAND_IMU[3:]]),
                                  np.column_stack([imu[c] for c in BAND_IMU[:3]]),
                                  (vehicle.Ixx_kg_m2, vehicle.Iyy_kg_m2, vehicle.Izz_kg_m2, vehicle.Ixz_kg_m2),
                                  vehicle.accel_offset_m, vehicle.band_hz, ok)
        fs = 1.0 / float(np.median(np.diff(t)))
        runs = finite_runs(bl.used)
        clean = {c: low_pass_runs(v, fs, bl.band_hz, runs) for c, v in clean.items()}
        if not bl.used.any():
            raise ValueError(f"segment {segment}: no run of {int(np.ceil(0.5 * fs / bl.band_hz))} consecutive samples "
                             f"with every IMU channel, control, V and h available (t = {_span(t)}): nothing to "
                             "low-pass for the regression")
        ok = bl.used
        band_hz = bl.band_hz
        band_rates = bl.rates_rad_s[ok]
        acc, ang = bl.accel_cg_m_s2[ok], bl.ang_accel_rad_s2[ok]
    elif signals != "smoother":
        raise ValueError(f"signals must be 'band' or 'smoother', not {signals!r}")
    s = smoothed.loc[ok].reset_index(drop=True)
    fins = [clean[c][ok] for c in FIN_COLUMNS]
    V, h = clean["V_m_s"][ok], clean["h_m"][ok]
    delta_r, delta_p, delta_y = (np.asarray(x) for x in vehicle.mix(*fins))
    if signals == "smoother":
        acc = s[["X1_m_s2", "Y1_m_s2", "Z1_m_s2"]].to_numpy()
        ang = s[["L1_rad_s2", "M1_rad_s2", "N1_rad_s2"]].to_numpy()
    acc_sig = s[["sigma_X1_m_s2", "sigma_Y1_m_s2", "sigma_Z1_m_s2"]].to_numpy()
    ang_sig = s[["sigma_L1_rad_s2", "sigma_M1_rad_s2", "sigma_N1_rad_s2"]].to_numpy()
    fc = flight_coefficients(vehicle, V, h, acc, ang, acc_sig, ang_sig)
    if vanes and signals == "band":  # the vanes went through the common low-pass above
        alpha = clean[vehicle.alpha_column][ok] - vehicle.alpha_bias_rad
        beta = clean[vehicle.beta_column][ok] - vehicle.beta_bias_rad
        alpha_r, phi_r = total_angles(alpha, beta)
        inv_J = np.zeros(len(alpha))
    elif vanes:
        alpha, beta, alpha_r, phi_r = _vane_angles(measured, ok, vehicle, t)
        inv_J = np.zeros(len(alpha))
    else:
        alpha, beta, alpha_r, phi_r, inv_J = _inverted_angles(fc, s, delta_p, delta_y, vehicle, db, segment)
    # errors in variables: the 1-sigma of the white noise whose band-limited part is in the
    # angles (vanes: the vehicle file's vane noise; inverted angles: the accelerometers' noise
    # through the inversion's sensitivity), for the SIMEX correction of aerosid.eiv
    eiv_a = eiv_b = np.full(len(V), vehicle.vane_noise_rad if vanes else 0.0)
    if not vanes and signals == "band":
        eiv_a, eiv_b = _inversion_noise(fc, delta_p, delta_y, vehicle, db, alpha, beta, bl.accel_noise_m_s2)
    coef = {"CA": fc.CA, "CY": fc.CY, "CN": fc.CN, "Cl": fc.Cl, "Cm": fc.Cm, "Cn": fc.Cn}
    rates = {c: s[c].to_numpy() for c in ("p_rad_s", "q_rad_s", "r_rad_s")}
    if signals == "band":
        rates = {c: band_rates[:, j] for j, c in enumerate(("p_rad_s", "q_rad_s", "r_rad_s"))}
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
        "band_hz": np.full(len(V), band_hz),
        "eiv_sigma_alpha_rad": eiv_a, "eiv_sigma_beta_rad": eiv_b,
    })


def _inverted_angles(fc, s: pd.DataFrame, delta_p, delta_y, vehicle: Vehicle, db: AeroDatabase, segment: str):
    """alpha, beta, alpha_r, phi_r [rad] and the inversion cost from the force database."""
    m_lo, m_hi = db.mach_range()
    outside = ~((fc.air.mach >= m_lo) & (fc.air.mach <= m_hi))
    if outside.any():
        # the inversion would clamp the table at its edge: alpha and beta there would be made up
        ts = s["t_s"].to_numpy()[outside]
        m = fc.air.mach[outside]
        raise ValueError(f"segment {segment}: Mach (from columns 'V_m_s' and 'h_m') is {m.min():.3g}..{m.max():.3g} "
                         f"at {int(outside.sum())} samples, t = {_span(ts)}, outside the aerodynamic database's "
                         f"Mach {m_lo:g}..{m_hi:g} ({vehicle.database_path}); alpha/beta cannot be inverted "
                         "there: restrict the run to the database's range (--window T0 T1) or extend the database")
    inv = invert_alpha_beta(fc.CN, fc.CY, fc.air.mach, delta_p, delta_y, db, vehicle.preflight)
    return inv.alpha_rad, inv.beta_rad, inv.alpha_r_rad, inv.phi_r_rad, inv.J


def _inversion_noise(fc, delta_p, delta_y, vehicle: Vehicle, db: AeroDatabase, alpha, beta, accel_noise):
    """Per-sample white-noise 1-sigma [rad] of the inverted alpha and beta: the accelerometers'
    white noise (a_z for C_N, a_y for C_Y) scaled to a coefficient by m/(qbar S), through the
    inversion's local sensitivity d alpha/d C_N, d beta/d C_Y (finite differences)."""
    scale = vehicle.mass_kg / (fc.air.qbar_pa * vehicle.S_m2)
    sig_cn, sig_cy = scale * float(accel_noise[2]), scale * float(accel_noise[1])
    eps = 1e-4
    up_n = invert_alpha_beta(fc.CN + eps, fc.CY, fc.air.mach, delta_p, delta_y, db, vehicle.preflight)
    up_y = invert_alpha_beta(fc.CN, fc.CY + eps, fc.air.mach, delta_p, delta_y, db, vehicle.preflight)
    da = np.abs(up_n.alpha_rad - alpha) / eps
    db_ = np.abs(up_y.beta_rad - beta) / eps
    med = lambda x: np.nan_to_num(x, nan=float(np.nanmedian(x)) if np.isfinite(x).any() else 0.0)  # noqa: E731
    return med(da * sig_cn), med(db_ * sig_cy)


def build_flight_data_segments(preprocessed: pd.DataFrame, smoothed: list[pd.DataFrame], vehicle: Vehicle,
                               db: AeroDatabase | None, flight: str = "flight", signals: str = "band") -> pd.DataFrame:
    """Flight data of several smoothed segments of one preprocessed flight, pooled:
    each segment is matched to the preprocessed rows of its own time span."""
    t = preprocessed["t_s"].to_numpy()
    parts = []
    for sm in smoothed:
        ts = sm["t_s"].to_numpy()
        start = int(np.searchsorted(t, ts[0] - 1e-9))
        rows = preprocessed.iloc[start:start + len(ts)].reset_index(drop=True)
        parts.append(build_flight_data(sm, rows, vehicle, db, flight, signals))
    return pd.concat(parts, ignore_index=True)
