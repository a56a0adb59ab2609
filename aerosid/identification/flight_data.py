"""From a smoothed segment to the flight data the regression reads (method.md §7–§10):
air data (the US-1976 atmosphere, or the measured ``rho_kg_m3``, ``qbar_pa``,
``p_static_pa``, ``T_total_K`` columns when the telemetry has them: see
``aerosid.vehicles.atmosphere.air_data`` and ``flight_air_data_sources``), flight coefficients,
control mixing, and alpha/beta, either inverted from the force database (the finned
class) or read from air-data vanes (a vehicle file with ``[air_data] source = "vanes"``)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pandas as pd

from aerosid.vehicles.aerodb import AeroDatabase
from aerosid.vehicles.atmosphere import MEASURED, H_MAX_M, H_MIN_M, AirDataError, air_data, air_data_sources
from aerosid.identification.flight_coefficients import flight_coefficients
from aerosid.identification.derivatives import zero_phase_low_pass
from aerosid.estimation.findings import (ACCEL_CHANNEL, CUT_COLUMN, DEPARTURE_MIN_S, DEPARTURE_SIGMA,
                                         KEPT_SUSPECT_COLUMN, Finding, dilate, kept_note, kept_sensors, span_findings)
from aerosid.identification.band import (accel_at_cg, band_limited_signals, band_noise_gain, bridge_spikes,
                                         finite_runs, low_pass_runs, white_noise_sigma)
from aerosid.identification.band_order import WIDEBAND_COLUMNS
from aerosid.identification.low_qbar import low_qbar_rows
from aerosid.identification.airdata_findings import airdata_findings
from aerosid.identification.vanes import advance, angles_at_cg, vane_white_noise_rad
from aerosid.identification.crb import R_COLUMNS
from aerosid.identification.inversion import invert_alpha_beta, total_angles
from aerosid.vehicles.vehicle import Vehicle

FIN_COLUMNS = ("d1_rad", "d2_rad", "d3_rad", "d4_rad")
#: The margin cut around a condemned span: one band period, at most this [s].
MAX_MARGIN_S = 1.0
BAND_IMU = ("ax_m_s2", "ay_m_s2", "az_m_s2", "p_rad_s", "q_rad_s", "r_rad_s")
#: The accelerometer each departure column of the smoother is compared with.
DEPARTURE_SENSOR = {"X1_m_s2": "ax", "Y1_m_s2": "ay", "Z1_m_s2": "az"}


class SegmentUnusable(ValueError):
    """A segment with nothing left for the regression (every run too short or condemned)."""


def load_database(vehicle: Vehicle) -> AeroDatabase | None:
    """The vehicle's force database, or None when alpha/beta come from vanes without one."""
    if vehicle.air_data_source == "vanes" and vehicle.database_path is None:
        return None
    return AeroDatabase.load(vehicle.database_path)


def _vane_angles_low_passed(clean: dict, ok: np.ndarray, vehicle: Vehicle, t: np.ndarray):
    """alpha, beta [rad] from the vanes' clean columns (zero-phase low-passed) minus the
    calibration bias, and the total angle of attack alpha_r and aerodynamic roll angle
    phi_r derived from them (the smoother path).  clean: build_flight_data's clean signals (the
    vanes as :func:`vane_angles` gives them)."""
    ts = t[ok]
    fs = 1.0 / float(np.median(np.diff(ts))) if ts.size > 1 else 1.0
    a, b = (zero_phase_low_pass(clean[col][ok], fs, vehicle.vane_cutoff_hz)
            - bias for col, bias in ((vehicle.alpha_column, vehicle.alpha_bias_rad),
                                     (vehicle.beta_column, vehicle.beta_bias_rad)))
    return (a, b, *total_angles(a, b))


def vane_angles(t: np.ndarray, measured: pd.DataFrame, vehicle: Vehicle) -> tuple[np.ndarray, np.ndarray]:
    """The vanes' clean columns of a preprocessed frame as the IMU would have them: advanced by
    the vehicle file's delay_s, then moved to the CG from vane_position_m with the clean gyros
    and airspeed (aerosid.identification.vanes); the calibration bias is left in."""
    a, b = (advance(t, measured[f"{c}_clean"].to_numpy(dtype=float), vehicle.vane_delay_s)
            for c in (vehicle.alpha_column, vehicle.beta_column))
    if any(vehicle.vane_position_m):
        p, q, r, V = (measured[f"{c}_clean"].to_numpy(dtype=float) for c in ("p_rad_s", "q_rad_s", "r_rad_s", "V_m_s"))
        a, b = angles_at_cg(a, b, p, q, r, V, vehicle.vane_position_m)
    return a, b


def measured_air_data_columns(columns) -> tuple[str, ...]:
    """The measured air-data channels a preprocessed frame carries (as ``<name>_clean``)."""
    have = set(columns)
    return tuple(c for c in MEASURED if f"{c}_clean" in have)


def flight_air_data_sources(columns, airspeed_kind: str = "true") -> dict[str, str]:
    """Where the flight data of a preprocessed frame with these columns takes its
    density, static temperature, Mach and dynamic pressure from, and what its airspeed is
    (airspeed_kind: the vehicle file's [air_data] airspeed, aerosid.vehicles.airspeed)."""
    airspeed = ("the telemetry, taken as the true airspeed ([air_data] airspeed)" if airspeed_kind == "true" else
                f"the telemetry's {airspeed_kind} airspeed, converted to the true one at preprocessing "
                "([air_data] airspeed)")
    return {**air_data_sources(measured_air_data_columns(columns)), "V_m_s": airspeed}


def _span(t: np.ndarray) -> str:
    """A time span for messages: 't0..t1 s (first t_s [...])'."""
    return f"{t[0]:.2f}..{t[-1]:.2f} s (first t_s {[round(float(v), 3) for v in t[:5]]})" if len(t) else "-"


def build_flight_data(smoothed: pd.DataFrame, measured: pd.DataFrame, vehicle: Vehicle, db: AeroDatabase | None,
                      flight: str = "flight", signals: str = "band") -> pd.DataFrame:
    """smoothed: a SmoothedSegment frame; measured: the preprocessed rows of the same
    segment (same t_s), whose ``*_clean`` columns give fins, V, h and any measured air
    data.  Rows where V, h, a fin or a measured air-data value is unavailable (inside
    an unfilled gap) are left out.

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
    airdata = measured_air_data_columns(measured.columns)
    cols = (*FIN_COLUMNS, "V_m_s", "h_m", *airdata) + ((vehicle.alpha_column, vehicle.beta_column, "q_rad_s", "az_m_s2")
                                                        if vanes else ())
    missing = [c for c in cols if f"{c}_clean" not in measured]
    if missing:
        raise ValueError(f"segment {segment}: the preprocessed telemetry has no column(s) "
                         f"{[c + '_clean' for c in missing]} (vehicle {vehicle.name}, {vehicle.source})")
    clean = {c: measured[f"{c}_clean"].to_numpy(dtype=float) for c in cols}
    if vanes:
        clean[vehicle.alpha_column], clean[vehicle.beta_column] = vane_angles(t, measured, vehicle)
    ok = np.all(np.isfinite(np.column_stack(list(clean.values()))), axis=1) & (clean["V_m_s"] > 0)
    h_out = ok & ~((clean["h_m"] >= H_MIN_M) & (clean["h_m"] <= H_MAX_M))
    if h_out.any():
        raise ValueError(f"segment {segment}: column 'h_m' outside the US-1976 atmosphere's {H_MIN_M:g}.."
                         f"{H_MAX_M:g} m at {int(h_out.sum())} rows, t = {_span(t[h_out])}")
    band_hz = np.nan
    findings: list = []
    timing = None
    marked = {}
    drop_rows = None  # frame rows condemned after the band (database edge, kinematic mismatch)
    if signals == "band":
        # measured air data and altitude are scale factors of the coefficients (through the
        # density and qbar), not regressors: left as measured, and a gap in them does not
        # split the filter's runs (their rows are dropped afterwards)
        scale_cols = (*airdata, "h_m")
        scales_ok = np.all(np.isfinite(np.column_stack([clean[c] for c in scale_cols])), axis=1)
        filt_ok = np.all(np.isfinite(np.column_stack([v for c, v in clean.items() if c not in scale_cols])),
                         axis=1) & (clean["V_m_s"] > 0)
        bl, used, findings, marked = _band_signals(t, measured, smoothed, vehicle, filt_ok, segment)
        fs = 1.0 / float(np.median(np.diff(t)))
        raw = clean
        clean = {c: (v if c in scale_cols else bl.low_pass(v, fs)) for c, v in clean.items()}
        ok = used & scales_ok
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
    try:
        air = air_data(V, h, **{c: clean[c][ok] for c in airdata})
    except AirDataError as exc:
        raise ValueError(f"segment {segment}: {exc}, t = {_span(s['t_s'].to_numpy()[exc.positions])}") from None
    fc = flight_coefficients(vehicle, V, h, acc, ang, acc_sig, ang_sig, air=air)
    if vanes and signals == "band":  # the vanes went through the common low-pass above
        alpha = clean[vehicle.alpha_column][ok] - vehicle.alpha_bias_rad
        beta = clean[vehicle.beta_column][ok] - vehicle.beta_bias_rad
        alpha_r, phi_r = total_angles(alpha, beta)
        inv_J = np.zeros(len(alpha))
        found, timing, mismatch = airdata_findings(t, ok, clean, bl, vehicle, segment, explained=marked["CN"])
        findings += found
        if mismatch.any():
            pad = int(np.ceil(min(0.5 / band_hz, MAX_MARGIN_S) * fs))
            drop_rows = dilate(mismatch, pad)[ok]
    elif vanes:
        alpha, beta, alpha_r, phi_r = _vane_angles_low_passed(clean, ok, vehicle, t)
        inv_J = np.zeros(len(alpha))
    else:
        alpha, beta, alpha_r, phi_r, inv_J, edge = _inverted_angles(fc, s, delta_p, delta_y, vehicle, db, segment,
                                                                    strict=signals != "band")
        if edge.any() and signals == "band":
            ts = s["t_s"].to_numpy()
            margin = int(np.ceil(min(0.5 / band_hz, MAX_MARGIN_S) / float(np.median(np.diff(ts))))) if len(ts) > 1 else 0
            f, _ = span_findings("database_edge", segment, "alpha/beta", ts, edge, 1, True,
                                 "alpha/beta inverted at the force database's edge (alpha_r at the table's "
                                 f"limit or Mach outside {db.mach_range()[0]:g}..{db.mach_range()[1]:g}): "
                                 "the table is clamped there, the angle would be made up")
            findings += f
            drop_rows = dilate(edge, margin)
    wide = {}
    if signals == "band":
        wide = _wideband_signals(raw, ok, s, fc, vehicle, db, segment)
        wide.update(_control_noise(raw, vehicle, bl, len(V)))
    # errors in variables: the 1-sigma of the white noise whose band-limited part is in the
    # angles (vanes: the vehicle file's vane noise; inverted angles: the accelerometers' noise
    # through the inversion's sensitivity), for the SIMEX correction of aerosid.identification.eiv
    eiv_a = eiv_b = np.full(len(V), vehicle.vane_noise_rad if vanes else 0.0)
    if vanes and not math.isfinite(vehicle.vane_noise_rad):  # not stated: each vane's own white noise
        eiv_a, eiv_b = (np.full(len(V), np.nan_to_num(vane_white_noise_rad(measured[f"{c}_clean"].to_numpy(float))))
                        for c in (vehicle.alpha_column, vehicle.beta_column))
    if not vanes and signals == "band":
        eiv_a, eiv_b = _inversion_noise(fc, delta_p, delta_y, vehicle, db, alpha, beta, bl.accel_noise_m_s2)
    eiv_rates = gyro_eiv_sigma(s, bl.rate_noise_rad_s if signals == "band" else None)
    coef = {"CA": fc.CA, "CY": fc.CY, "CN": fc.CN, "Cl": fc.Cl, "Cm": fc.Cm, "Cn": fc.Cn}
    rates = {c: s[c].to_numpy() for c in ("p_rad_s", "q_rad_s", "r_rad_s")}
    if signals == "band":
        rates = {c: band_rates[:, j] for j, c in enumerate(("p_rad_s", "q_rad_s", "r_rad_s"))}
    frame = pd.DataFrame({
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
        "eiv_sigma_alpha_rad": eiv_a, "eiv_sigma_beta_rad": eiv_b, **eiv_rates, **wide,
        **{c: s[c].to_numpy(float) for c in R_COLUMNS if c in s},  # the filter's R (Cramér-Rao bounds)
        **{CUT_COLUMN[ch]: m[ok] for ch, m in marked.items()},
    })
    if drop_rows is not None and drop_rows.any():
        frame = frame.loc[~drop_rows].reset_index(drop=True)
        if frame.empty:
            raise ValueError(f"segment {segment}: every sample condemned ({findings[-1].summary()})")
    frame.attrs["findings"] = [f.as_dict() for f in findings]
    frame.attrs["vane_timing"] = [timing] if timing else []
    return frame


def gyro_eiv_sigma(smoothed: pd.DataFrame, band_white_rad_s) -> dict[str, np.ndarray]:
    """eiv_sigma_p/q/r_rad_s: per sample, the 1-sigma [rad/s] of the gyros' white noise whose
    band-limited part is in the flight data's rates (errors in variables, for the rates' part
    of the SIMEX correction, aerosid.identification.eiv).  The measurement noise the run's
    filter used for the gyros (its R: the noise dispersion above the signal band, then the
    smoother's EM update), carried as R_sigma_p/q/r_rad_s; without those columns the band
    module's first-difference estimate (band_white_rad_s, BandLimitedSignals.rate_noise_rad_s).
    On the simulators R was within 4.5 % of the noise actually added on every seed, the
    first-difference estimate within 9 % (the signal's own change leaks into it on a fast
    manoeuvre).  band_white_rad_s None (the smoother's rates, not a band-limited gyro): zero,
    the rates are taken as exact."""
    n = len(smoothed)
    out = {}
    for j, c in enumerate(("p_rad_s", "q_rad_s", "r_rad_s")):
        if band_white_rad_s is None:
            out[f"eiv_sigma_{c}"] = np.zeros(n)
        else:
            r = smoothed[f"R_sigma_{c}"].to_numpy(float) if f"R_sigma_{c}" in smoothed else np.full(n, np.nan)
            out[f"eiv_sigma_{c}"] = np.where(np.isfinite(r) & (r > 0), r, float(band_white_rad_s[j]))
    return out


def _band_signals(t, measured: pd.DataFrame, smoothed: pd.DataFrame, vehicle: Vehicle, ok: np.ndarray, segment: str):
    """The band-limited signals of a segment with the smoother's condemned samples (the
    ``suspect`` column) and the spans where the smoothed signals depart from their
    measurement cut out, each with a margin of one band period.  Returns the signals, the
    rows kept, the findings (aerosid.estimation.findings) and {channel: rows whose coefficient
    reads a condemned sample of a sensor that feeds that channel alone} (CUT_COLUMN: the sensors
    of aerosid.estimation.findings.kept_sensors, whose samples the other channels keep)."""
    imu = np.column_stack([measured[f"{c}_clean"].to_numpy(dtype=float) for c in BAND_IMU])
    # spikes the preprocessing left (it leaves 5-7 sigma ones to the filter) would go through
    # the derivative and the band into a band period of C_m: bridge them as the preprocessing
    # does its own outliers (aerosid.identification.band.bridge_spikes), against the smoother
    ws = smoothed[["p_rad_s", "q_rad_s", "r_rad_s"]].to_numpy(float)
    if {"X1_m_s2", "Y1_m_s2", "Z1_m_s2"} <= set(smoothed.columns):
        wd = np.gradient(ws, t, axis=0) if len(t) > 2 else np.zeros_like(ws)
        a_cg_meas = accel_at_cg(imu[:, :3], ws, wd, vehicle.accel_offset_m)
        ref = np.column_stack([smoothed[c].to_numpy(float) for c in ("X1_m_s2", "Y1_m_s2", "Z1_m_s2")])
        imu[:, :3] = bridge_spikes(imu[:, :3], a_cg_meas - ref)
    imu[:, 3:] = bridge_spikes(imu[:, 3:], imu[:, 3:] - ws)
    inertia = (vehicle.Ixx_kg_m2, vehicle.Iyy_kg_m2, vehicle.Izz_kg_m2, vehicle.Ixz_kg_m2)
    fs = 1.0 / float(np.median(np.diff(t)))

    first = band_limited_signals(t, imu[:, 3:], imu[:, :3], inertia, vehicle.accel_offset_m, vehicle.band_hz, ok)

    def signals(keep):
        # the band edge stays the one of the segment before any cut: it comes from the longest
        # run, and a cut span split that run (J3Cub seed 1: a 0.16 s gated q run in the first
        # 3-2-1-1 left a longest run with only the lateral doublets, 3.0 -> 1.6 Hz, and C_m's
        # estimates +32..+51 %): a cut costs the samples it touches, not the segment's band
        cut = band_limited_signals(t, imu[:, 3:], imu[:, :3], inertia, vehicle.accel_offset_m, first.band_hz, keep)
        return dataclasses.replace(cut, band_source=first.band_source)

    bl = first
    margin = int(np.ceil(min(1.0 / bl.band_hz, MAX_MARGIN_S) * fs))
    suspect = smoothed["suspect"].to_numpy(bool) if "suspect" in smoothed else np.zeros(len(t), bool)
    kept = kept_sensors(vehicle.air_data_source)
    marked = {ch: np.zeros(len(t), bool) for ch in CUT_COLUMN}
    for sensor, col in KEPT_SUSPECT_COLUMN.items():  # the smoothing stage kept these for the other channels
        if col in smoothed:
            marked[ACCEL_CHANNEL[sensor]] |= smoothed[col].to_numpy(bool)
    keep = ok & ~dilate(suspect, margin)
    if suspect.any():
        bl = signals(keep)
    findings = []
    if bl.used.any():  # departures: smoothed states against the band-limited measurements
        runs = finite_runs(bl.used)
        pairs = [("p_rad_s", bl.rates_rad_s[:, 0]), ("q_rad_s", bl.rates_rad_s[:, 1]), ("r_rad_s", bl.rates_rad_s[:, 2]),
                 ("X1_m_s2", bl.accel_cg_m_s2[:, 0]), ("Y1_m_s2", bl.accel_cg_m_s2[:, 1]),
                 ("Z1_m_s2", bl.accel_cg_m_s2[:, 2])]
        gain = band_noise_gain(fs, bl.band_hz)
        noise = dict(zip(("p_rad_s", "q_rad_s", "r_rad_s", "X1_m_s2", "Y1_m_s2", "Z1_m_s2"),
                         (*bl.rate_noise_rad_s, *bl.accel_noise_m_s2)))
        gone = np.zeros(len(t), bool)
        for col, meas in pairs:
            sm = low_pass_runs(smoothed[col].to_numpy(float), fs, bl.band_hz, runs)
            white = noise[col]
            sig_sm = smoothed[f"sigma_{col}"].to_numpy(float) if f"sigma_{col}" in smoothed else 0.0
            diff = meas - sm
            d = diff[np.isfinite(diff)]
            typical = 1.4826 * float(np.median(np.abs(d - np.median(d)))) if d.size else 0.0
            # the larger of the expected (noise through the band, smoother sigma) and the
            # typical difference: a departure stands out from this segment's own agreement
            sigma = np.maximum(np.hypot(gain * white, sig_sm), typical)
            with np.errstate(invalid="ignore"):
                off = np.abs(diff) > DEPARTURE_SIGMA * sigma
            sensor = DEPARTURE_SENSOR.get(col)
            own = sensor in kept
            f, hit = span_findings("departure", segment, col, t, off & bl.used, int(np.ceil(DEPARTURE_MIN_S * fs)),
                                   not own, f"the smoothed {col} departs from its band-limited measurement by more "
                                   f"than {DEPARTURE_SIGMA:g} sigma" + (kept_note(sensor, kept[sensor]) if own else ""))
            findings += f
            if own:
                marked[kept[sensor]] |= hit
            else:
                gone |= hit
        if gone.any():
            keep &= ~dilate(gone, margin)
            bl = signals(keep)
    if not bl.used.any():
        raise SegmentUnusable(f"segment {segment}: no run of {int(np.ceil(0.5 * fs / bl.band_hz))} consecutive samples "
                         f"with every IMU channel, control, V and h available and not condemned (t = {_span(t)}): "
                         "nothing to low-pass for the regression")
    return bl, bl.used, findings, {ch: dilate(m, margin) for ch, m in marked.items()}


def _inverted_angles(fc, s: pd.DataFrame, delta_p, delta_y, vehicle: Vehicle, db: AeroDatabase, segment: str,
                     strict: bool = True):
    """alpha, beta, alpha_r, phi_r [rad], the inversion cost, and the samples at the force
    database's edge (alpha_r at the table's first or last angle, or Mach outside the table:
    the table is clamped there).  strict: Mach outside the table is an error (the seed's
    smoother path); else those samples are marked as edge and their angles left NaN."""
    m_lo, m_hi = db.mach_range()
    outside = ~((fc.air.mach >= m_lo) & (fc.air.mach <= m_hi))
    if outside.any() and (strict or outside.all()):
        # the inversion would clamp the table at its edge: alpha and beta there would be made up
        ts = s["t_s"].to_numpy()[outside]
        m = fc.air.mach[outside]
        origin = ("from columns 'V_m_s' and 'h_m'" if "T_total_K" not in fc.air.sources["mach"]
                  else "from columns 'V_m_s' and 'T_total_K'")
        raise ValueError(f"segment {segment}: Mach ({origin}) is {m.min():.3g}..{m.max():.3g} "
                         f"at {int(outside.sum())} samples, t = {_span(ts)}, outside the aerodynamic database's "
                         f"Mach {m_lo:g}..{m_hi:g} ({vehicle.database_path}); alpha/beta cannot be inverted "
                         "there: restrict the run to the database's range (--window T0 T1) or extend the database")
    mach = np.clip(fc.air.mach, m_lo, m_hi)
    inv = invert_alpha_beta(fc.CN, fc.CY, mach, delta_p, delta_y, db, vehicle.preflight)
    grid = np.asarray(db.alpha_r_rad, float)
    step = float(np.min(np.diff(grid))) if grid.size > 1 else 0.0
    edge = outside | ~np.isfinite(inv.alpha_r_rad) | (inv.alpha_r_rad >= grid[-1] - 1e-3 * step)
    if grid[0] > 0:
        edge |= inv.alpha_r_rad <= grid[0] + 1e-3 * step
    return inv.alpha_rad, inv.beta_rad, inv.alpha_r_rad, inv.phi_r_rad, inv.J, edge


def _wideband_signals(raw: dict, ok: np.ndarray, s: pd.DataFrame, fc, vehicle: Vehicle, db: AeroDatabase | None,
                      segment: str) -> dict[str, np.ndarray]:
    """The regressor signals on the flight-data rows *before* the band's low-pass, as
    WIDEBAND_COLUMNS names them, for the band order of the model's non-linear columns
    (aerosid.identification.band_order): the clean fins (mixed) and V, the
    smoother's rates, and the vanes' clean angles minus their bias or the angles inverted from
    the smoother's accelerations (the smoother's own bandwidth, wider than the band).  NaN
    where the inversion is at the database's edge."""
    delta_r, delta_p, delta_y = (np.asarray(x) for x in vehicle.mix(*[raw[c][ok] for c in FIN_COLUMNS]))
    if vehicle.air_data_source == "vanes":
        alpha = raw[vehicle.alpha_column][ok] - vehicle.alpha_bias_rad
        beta = raw[vehicle.beta_column][ok] - vehicle.beta_bias_rad
    else:
        acc = s[["X1_m_s2", "Y1_m_s2", "Z1_m_s2"]].to_numpy(float)
        ang = s[["L1_rad_s2", "M1_rad_s2", "N1_rad_s2"]].to_numpy(float)
        fc_w = flight_coefficients(vehicle, None, None, acc, ang, air=fc.air)  # the same air data
        alpha, beta, _, _, _, edge = _inverted_angles(fc_w, s, delta_p, delta_y, vehicle, db, segment, strict=False)
        alpha, beta = np.where(edge, np.nan, alpha), np.where(edge, np.nan, beta)
    values = {"alpha_rad": alpha, "beta_rad": beta, "delta_p_rad": delta_p, "delta_y_rad": delta_y,
              "delta_r_rad": delta_r, "V_m_s": raw["V_m_s"][ok],
              **{c: s[c].to_numpy(float) for c in ("p_rad_s", "q_rad_s", "r_rad_s")}}
    return {WIDEBAND_COLUMNS[c]: v for c, v in values.items()}


#: The flight data's white-noise 1-sigma of the mixed controls before the band [rad].
CONTROL_NOISE_COLUMNS = {"delta_p": "eiv_sigma_delta_p_rad", "delta_y": "eiv_sigma_delta_y_rad",
                         "delta_r": "eiv_sigma_delta_r_rad"}


def _control_noise(raw: dict, vehicle: Vehicle, bl, n: int) -> dict[str, np.ndarray]:
    """The white noise of the mixed controls [rad] (CONTROL_NOISE_COLUMNS), per row: each fin's
    from its second differences over the band's runs (1.4826 MAD / sqrt(6): a surface's own
    motion, slow next to the sample rate, cancels there where it would bias first differences),
    through the linear mixing.  0 where it cannot be measured this way: a surface quantised, or
    held between updates and interpolated by the preprocessing (its noise is then not seen, and
    identify does not warn).  identify corrects the estimates for this noise by SIMEX (control_eiv)
    and warns where it is a sizeable share of one's variation."""
    runs = [slice(a, b) for a, b in bl.filter_runs]
    fin = np.nan_to_num([white_noise_sigma(raw[c], runs, order=2) for c in FIN_COLUMNS], nan=0.0)
    mixed = dict(zip(("delta_r", "delta_p", "delta_y"), (math.sqrt(float(np.sum((np.asarray(row, float) * fin) ** 2)))
                                                            for row in vehicle.mixing)))
    return {col: np.full(n, mixed[c]) for c, col in CONTROL_NOISE_COLUMNS.items()}


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
    parts, lost = [], []
    for sm in smoothed:
        ts = sm["t_s"].to_numpy()
        start = int(np.searchsorted(t, ts[0] - 1e-9))
        rows = preprocessed.iloc[start:start + len(ts)].reset_index(drop=True)
        try:
            parts.append(build_flight_data(sm, rows, vehicle, db, flight, signals))
        except SegmentUnusable as exc:  # the other segments go on; the run says why this one did not
            seg = str(sm["segment"].iloc[0]) if len(sm) else "?"
            lost.append(Finding("unusable", seg, "", float(ts[0]), float(ts[-1]), len(ts), True, str(exc)).as_dict())
    if not parts:
        raise ValueError("no segment left for the regression: " + "; ".join(f["detail"] for f in lost))
    frame = pd.concat(parts, ignore_index=True)
    low, low_found = low_qbar_rows(frame)
    frame = frame.loc[~low].reset_index(drop=True) if low.any() else frame
    frame.attrs["findings"] = [f for part in parts for f in part.attrs.get("findings", [])] + lost + low_found
    frame.attrs["vane_timing"] = [r for part in parts for r in part.attrs.get("vane_timing", [])]
    return frame


def build_pooled_flight_data(flights: list[tuple[str, pd.DataFrame, list[pd.DataFrame]]], vehicle: Vehicle,
                             db: AeroDatabase | None) -> pd.DataFrame:
    """Flight data of several manoeuvres of one aircraft, pooled for one regression:
    ``flights`` holds (flight id, preprocessed frame, its smoothed segments) per
    manoeuvre, each preprocessed and smoothed on its own.  The ids must differ (the
    regression's derivatives and residual correction work per flight)."""
    ids = [f for f, _, _ in flights]
    if len(set(ids)) < len(ids):
        raise ValueError(f"pooled flights need distinct ids, got {ids}")
    parts = [build_flight_data_segments(pre, smoothed, vehicle, db, fid) for fid, pre, smoothed in flights]
    frame = pd.concat(parts, ignore_index=True)
    # every manoeuvre has a seg00: a finding names its manoeuvre with its segment ("m1 seg00")
    frame.attrs["findings"] = [{**f, "segment": f"{fid} {f['segment']}"}
                               for fid, part in zip(ids, parts) for f in part.attrs.get("findings", [])]
    frame.attrs["vane_timing"] = [{**r, "segment": f"{fid} {r['segment']}"}
                                  for fid, part in zip(ids, parts) for r in part.attrs.get("vane_timing", [])]
    return frame
