"""Kinematic consistency of the raw channels: unit and sign mistakes that need no envelope
(aerosid.plausibility.units runs these after its magnitude tests).

Per window of the flight, one channel is regressed on another integrated through the
kinematics that bind them, with an intercept and a slope in time for the unknown initial
state and slow biases; the pooled slope is 1 when both are right:

* pitch: the vane alpha plus the flight path's change (from az and V) against the integrated
  pitch rate (deg/s: 1/57.3; a flipped gyro: -1), and alpha against [Q, G] jointly, whose
  signs tell a flipped gyro (alpha = -Q - G) from a flipped vane (alpha = -Q + G) and a vane
  in degrees (57.3);
* altitude: h against the doubly integrated -(az + g) (1 m, 0.001 km, 3.28 ft);
* attitude (phi_rad, theta_rad when the telemetry has them): each angle against the gyros
  through the Euler kinematics (-1: the rate or the angle flipped, the vanes telling which;
  57.3: the angle in degrees);
* sideslip: the vane beta against the integrated -r cos alpha, ay / V and the bank's gravity,
  whose signs tell a flipped vane, yaw gyro or lateral accelerometer apart.

Evidence is believed at |slope| / se >= MIN_T_STAT, a candidate within SLOPE_TOLERANCE.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from aerosid.plausibility.units import ALTITUDE_UNITS, DEG, G0, UnitFinding, _fmt_range

#: Kinematic windows [s] and the evidence they need.
ALPHA_WINDOW_S = 2.0
ALTITUDE_WINDOW_S = 6.0
MIN_T_STAT = 10.0  # pooled slope / its standard error, before a kinematic slope is believed
SLOPE_TOLERANCE = 2.0  # a candidate unit fits when the slope is within this factor of its value


def _windows(t: np.ndarray, length_s: float, max_gap_s: float = 0.25):
    """Index arrays of consecutive windows of about length_s without a gap > max_gap_s."""
    if len(t) < 3:
        return
    breaks = np.flatnonzero(np.diff(t) > max_gap_s) + 1
    for run in np.split(np.arange(len(t)), breaks):
        if len(run) < 3:
            continue
        tt = t[run]
        start = tt[0]
        while start + length_s <= tt[-1] + 1e-9:
            idx = run[(tt >= start) & (tt < start + length_s)]
            if len(idx) >= 20:
                yield idx
            start += length_s


def _cumtrapz(y: np.ndarray, t: np.ndarray) -> np.ndarray:
    out = np.zeros_like(y)
    out[1:] = np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))
    return out


def _despike(x: np.ndarray) -> np.ndarray:
    """A running median of 5 samples: isolated spikes do not integrate into steps."""
    return pd.Series(x).rolling(5, center=True, min_periods=1).median().to_numpy()


def _pooled_fit(triples, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients b (width of them) of y = X b + nuisance (per window), pooled over windows,
    and their standard errors (NaN when X is not determined)."""
    xs, ys, n_nuis = [], [], 0
    for X, y, nuisance in triples:
        xs.append(X - nuisance @ np.linalg.lstsq(nuisance, X, rcond=None)[0])
        ys.append(y - nuisance @ np.linalg.lstsq(nuisance, y, rcond=None)[0])
        n_nuis += nuisance.shape[1]
    undetermined = np.full(width, math.nan), np.full(width, math.nan)
    if not xs:
        return undetermined
    X, y = np.concatenate(xs), np.concatenate(ys)
    dof = len(y) - n_nuis - width
    xtx = X.T @ X
    if dof <= 0 or not np.all(np.diag(xtx) > 0) or np.linalg.cond(xtx) > 1e12:
        return undetermined
    b = np.linalg.solve(xtx, X.T @ y)
    r = y - X @ b
    return b, np.sqrt(np.diag(np.linalg.inv(xtx)) * float(r @ r) / dof)


def _pooled_slope(pairs) -> tuple[float, float]:
    """Slope k of y = k x + nuisance (per window), pooled over windows: (k, se)."""
    b, se = _pooled_fit([(x[:, None], y, nuisance) for x, y, nuisance in pairs], 1)
    return float(b[0]), float(se[0])


def _clean_rows(frame: pd.DataFrame, cols: list[str]) -> pd.DataFrame:
    rows = frame[["t_s", *cols]].copy()
    ok = np.isfinite(rows.to_numpy(float)).all(axis=1)
    return rows[ok].reset_index(drop=True)


def _vane_pitch_slopes(rows: pd.DataFrame, vane: str, t: np.ndarray, q: np.ndarray, gdot: np.ndarray):
    """Pooled over windows: ((k, se) of alpha + G against Q, (a, se) of alpha against Q - G,
    (b, se) of alpha against [Q, G]), Q the integrated pitch rate, G the flight path's change:
    k = a = 1 and b = (1, -1) for a healthy pitch gyro and vane; the sign of b's G part tells
    a flipped gyro (alpha = -Q - G) from a flipped vane (alpha = -Q + G)."""
    alpha = _despike(rows[vane].to_numpy(float))
    pairs, vane_pairs, triples = [], [], []
    for idx in _windows(t, ALPHA_WINDOW_S * 2):
        tt = t[idx] - t[idx][0]
        Q, G = _cumtrapz(q[idx], tt), _cumtrapz(gdot[idx], tt)
        nuisance = np.column_stack([np.ones_like(tt), tt])
        pairs.append((Q, alpha[idx] + G, nuisance))
        vane_pairs.append((Q - G, alpha[idx], nuisance))
        triples.append((np.column_stack([Q, G]), alpha[idx], nuisance))
    return _pooled_slope(pairs), _pooled_slope(vane_pairs), _pooled_fit(triples, 2)


def _pitch_inputs(frame: pd.DataFrame, vehicle):
    """(rows, vane column or None, t, despiked q, flight-path rate -(az + g)/V) or None."""
    vane = vehicle.alpha_column if vehicle.air_data_source == "vanes" else None
    vane = vane if vane and vane in frame.columns else None
    rows = _clean_rows(frame, ["q_rad_s", "az_m_s2", "V_m_s"] + ([vane] if vane else []))
    if len(rows) < 100:
        return None
    t = rows["t_s"].to_numpy(float)
    q = _despike(rows["q_rad_s"].to_numpy(float))
    gdot = -(rows["az_m_s2"].to_numpy(float) + G0) / np.maximum(rows["V_m_s"].to_numpy(float), 1.0)
    return rows, vane, t, q, gdot


def _vane_confirms_q(frame: pd.DataFrame, vehicle) -> bool:
    """The vane angle of attack follows +q (the slope of alpha + G on Q significant and within
    SLOPE_TOLERANCE of 1)."""
    inputs = _pitch_inputs(frame, vehicle)
    if inputs is None or inputs[1] is None:
        return False
    (k, se), _, _ = _vane_pitch_slopes(*inputs)
    return math.isfinite(k) and k > 0 and k / se >= MIN_T_STAT and abs(math.log(k)) < math.log(SLOPE_TOLERANCE)


def _near(x: float, target: float) -> bool:
    """x has target's sign and is within SLOPE_TOLERANCE of it."""
    return math.isfinite(x) and x * target > 0 and abs(math.log(x / target)) < math.log(SLOPE_TOLERANCE)


def _pitch_sign_finding(k: float, b: np.ndarray, se_b: np.ndarray, vane: str) -> UnitFinding | None:
    """A flipped pitch gyro (alpha = -Q - G) or vane (alpha = -Q + G), from b of alpha against
    [Q, G]; when G's part is not determined and alpha + G = -Q, either."""
    determined = bool(np.all(np.isfinite(b)) and np.all(np.abs(b) >= MIN_T_STAT * se_b))
    said = (f"alpha = {b[0]:.3g} Q {b[1]:+.3g} G over windows (Q: the integrated pitch rate, G: the flight "
            f"path's change from az_m_s2 and V; +1 Q - 1 G expected)")
    if determined and _near(b[0], -1.0) and _near(b[1], -1.0):
        return UnitFinding(("q_rad_s",), "q positive nose up", "the opposite sign", -1.0,
                           f"{said}: the pitch gyro disagrees with both the vane ({vane}) and the accelerometers",
                           kind="sign", overridable=False)
    if determined and _near(b[0], -1.0) and _near(b[1], 1.0):
        return UnitFinding((vane,), "alpha positive nose up (relative wind from below)", "the opposite sign", -1.0,
                           f"{said}: the vane disagrees with both the pitch gyro and the accelerometers",
                           kind="sign", overridable=False)
    if not determined and _near(k, -1.0):
        return UnitFinding(("q_rad_s", vane), "q and alpha positive nose up", "the opposite sign", -1.0,
                           f"integrated, the pitch rate changes the pitch attitude {1 / k:.3g} times as much as "
                           f"the vane angle of attack and the flight path change together (+1 expected): q_rad_s "
                           f"or {vane} is flipped", kind="sign", overridable=False)
    return None


def _pitch_rate_kinematic(frame: pd.DataFrame, vehicle) -> UnitFinding | None:
    """Integrated q against the vanes' alpha (with the flight-path change from az), or
    against the vehicle's alpha range when there are no vanes."""
    env = vehicle.envelope
    inputs = _pitch_inputs(frame, vehicle)
    if inputs is None:
        return None
    rows, vane, t, q, gdot = inputs
    if vane is not None:  # vanes: alpha + flight-path change = k * integral of q
        (k, se), (a, se_a), (b, se_b) = _vane_pitch_slopes(*inputs)
        if not (math.isfinite(k) and abs(k) / se >= MIN_T_STAT):
            k = math.nan  # not determined (a flipped vane leaves alpha + G little to do with Q)
        elif k > 0 and abs(math.log(k / DEG)) < math.log(SLOPE_TOLERANCE) and abs(math.log(k)) > math.log(5.0):
            return UnitFinding(("q_rad_s",), "rad/s", "deg/s", DEG,
                               f"integrated, the pitch rate changes the pitch attitude {1 / k:.3g} times as much "
                               f"as the vane angle of attack ({vane}) and the flight path (from az_m_s2) change "
                               f"together (1 for rad/s, 57.3 for deg/s)")
        sign = _pitch_sign_finding(k, b, se_b, vane)
        if sign is not None:
            return sign
        # a vane in degrees: alpha = a x (integral of q - flight-path change), a = 57.3
        if math.isfinite(a) and a > 0 and a / se_a >= MIN_T_STAT and abs(math.log(a * DEG)) < math.log(SLOPE_TOLERANCE):
            return UnitFinding((vane,), "rad", "deg", DEG,
                               f"the vane angle of attack changes {a:.3g} times as much as the integrated pitch rate "
                               "less the flight path's change (from az_m_s2) says it does (1 for rad, 57.3 for deg)",
                               overridable=False)
        return None
    width = env.alpha_rad[1] - env.alpha_rad[0]
    swings = []
    for idx in _windows(t, ALPHA_WINDOW_S):
        tt = t[idx] - t[idx][0]
        d = _cumtrapz(q[idx], tt) - _cumtrapz(gdot[idx], tt)
        d = d - np.polyval(np.polyfit(tt, d, 1), tt)
        swings.append(float(np.ptp(d)))
    if len(swings) < 3:
        return None
    swing = float(np.percentile(swings, 90))
    if swing > width and swing * DEG <= 0.5 * width:
        return UnitFinding(("q_rad_s",), "rad/s", "deg/s", DEG,
                           f"integrated over {ALPHA_WINDOW_S:g} s windows, pitch rate minus flight-path rate "
                           f"(the change of angle of attack) swings by {swing:.3g} rad in 10 % of the windows, more "
                           f"than the vehicle's whole angle-of-attack range {_fmt_range(env.alpha_rad)} rad "
                           f"([plausibility] alpha_rad); as deg/s it is {swing * DEG:.3g} rad")
    return None


def _altitude_kinematic(frame: pd.DataFrame) -> UnitFinding | None:
    """h against the doubly integrated vertical acceleration -(az + g), per window."""
    rows = _clean_rows(frame, ["h_m", "az_m_s2"])
    if len(rows) < 100:
        return None
    t = rows["t_s"].to_numpy(float)
    h = _despike(rows["h_m"].to_numpy(float))
    acc = -(_despike(rows["az_m_s2"].to_numpy(float)) + G0)
    pairs = []
    for idx in _windows(t, ALTITUDE_WINDOW_S):
        tt = t[idx] - t[idx][0]
        H = _cumtrapz(_cumtrapz(acc[idx], tt), tt)
        pairs.append((H, h[idx], np.column_stack([np.ones_like(tt), tt, tt**2])))
    k, se = _pooled_slope(pairs)
    if not (math.isfinite(k) and k > 0 and k / se >= MIN_T_STAT) or abs(math.log(k)) < math.log(2.5):
        return None
    unit, f = min(ALTITUDE_UNITS.items(), key=lambda u: abs(math.log(k * u[1])))
    if abs(math.log(k * f)) >= math.log(SLOPE_TOLERANCE):
        return None
    return UnitFinding(("h_m",), "m", unit, f,
                       f"the altitude changes {k:.3g} times as much as the vertical acceleration (-(az_m_s2 + g), "
                       f"integrated twice) says it does (1 for metres, 0.001 for km, 3.28 for ft)")


ATTITUDE_PAIRS = (("theta_rad", "q_rad_s", "theta positive nose up, q positive nose up"),
                  ("phi_rad", "p_rad_s", "phi positive right wing down, p positive right wing down"))


def _attitude_kinematic(frame: pd.DataFrame, q_confirmed: bool = False, bank_sign: float = 0.0) -> UnitFinding | None:
    """The attitude columns (phi_rad, theta_rad, when the telemetry has them) against the gyros
    through the Euler kinematics, per window: theta' = q cos phi - r sin phi, phi' = p +
    tan theta (q sin phi + r cos phi).  Slope -1: the rate or the angle has its sign flipped
    (for the pitch pair, q_confirmed: the vanes follow +q, so theta is the flipped one; for the
    roll pair, bank_sign: the sideslip fit's gravity term from phi, -1 phi flipped, +1 phi right
    so p flipped); 57.3: the angle is in degrees."""
    cols = ["p_rad_s", "q_rad_s", "r_rad_s", "phi_rad", "theta_rad"]
    if any(c not in frame.columns for c in cols):
        return None
    rows = _clean_rows(frame, cols)
    if len(rows) < 100:
        return None
    t = rows["t_s"].to_numpy(float)
    p, q, r = (_despike(rows[c].to_numpy(float)) for c in ("p_rad_s", "q_rad_s", "r_rad_s"))
    phi, theta = np.unwrap(_despike(rows["phi_rad"].to_numpy(float))), _despike(rows["theta_rad"].to_numpy(float))
    rates = {"theta_rad": q * np.cos(phi) - r * np.sin(phi),
             "phi_rad": p + np.tan(np.clip(theta, -1.4, 1.4)) * (q * np.sin(phi) + r * np.cos(phi))}
    angles = {"theta_rad": theta, "phi_rad": phi}
    for angle, rate, convention in ATTITUDE_PAIRS:
        pairs = []
        for idx in _windows(t, ALPHA_WINDOW_S * 2):
            tt = t[idx] - t[idx][0]
            pairs.append((_cumtrapz(rates[angle][idx], tt), angles[angle][idx],
                          np.column_stack([np.ones_like(tt), tt])))
        k, se = _pooled_slope(pairs)
        if not (math.isfinite(k) and abs(k) / se >= MIN_T_STAT):
            continue
        said = (f"integrated through the Euler kinematics, the gyros change {angle} {1 / k:.3g} times as much as "
                f"{angle} changes")
        if k > 0 and abs(math.log(k * DEG)) < math.log(SLOPE_TOLERANCE):
            return UnitFinding((angle,), "rad", "deg", DEG, said + " (1 for rad, 1/57.3 for deg)", overridable=False)
        if k < 0 and abs(math.log(-k)) < math.log(SLOPE_TOLERANCE):
            if angle == "theta_rad" and q_confirmed:
                return UnitFinding((angle,), convention, "the opposite sign", -1.0, said + " (+1 expected); the "
                                   "vane angle of attack follows +q, so theta_rad is the flipped one", kind="sign",
                                   overridable=False)
            if angle == "phi_rad" and bank_sign != 0.0:
                culprit = angle if bank_sign < 0 else rate
                return UnitFinding((culprit,), convention, "the opposite sign", -1.0, said + " (+1 expected); the "
                                   f"sideslip vane and the yaw gyro {'disagree' if bank_sign < 0 else 'agree'} with "
                                   f"the bank's gravity from phi_rad, so {culprit} is the flipped one", kind="sign",
                                   overridable=False)
            return UnitFinding((rate, angle), convention, "the opposite sign", -1.0,
                               said + f" (+1 expected): {rate} or {angle} is flipped", kind="sign",
                               overridable=False)
    return None


LATERAL_WINDOW_S = 4.0


def _lateral_fit(frame: pd.DataFrame, vehicle):
    """(b, sure, attitude, vane) of the sideslip fit (_lateral_kinematic), or None: b the
    coefficients of P, R, Y, Gy, sure where each is determined (|t| >= MIN_T_STAT)."""
    if vehicle.air_data_source != "vanes" or vehicle.beta_column not in frame.columns:
        return None
    vane = vehicle.beta_column
    alpha_col = vehicle.alpha_column if vehicle.alpha_column in frame.columns else None
    attitude = {"phi_rad", "theta_rad"} <= set(frame.columns)
    cols = ["p_rad_s", "r_rad_s", "ay_m_s2", "V_m_s", vane] + ([alpha_col] if alpha_col else []) + \
        (["phi_rad", "theta_rad"] if attitude else [])
    rows = _clean_rows(frame, cols)
    if len(rows) < 100:
        return None
    t = rows["t_s"].to_numpy(float)
    p, r, ay, beta = (_despike(rows[c].to_numpy(float)) for c in ("p_rad_s", "r_rad_s", "ay_m_s2", vane))
    V = np.maximum(rows["V_m_s"].to_numpy(float), 1.0)
    alpha = _despike(rows[alpha_col].to_numpy(float)) if alpha_col else np.zeros_like(t)
    triples = []
    for idx in _windows(t, LATERAL_WINDOW_S):
        tt = t[idx] - t[idx][0]
        if attitude:
            bank = G0 * np.cos(rows["theta_rad"].to_numpy(float)[idx]) * np.sin(rows["phi_rad"].to_numpy(float)[idx])
        else:
            bank = G0 * np.sin(_cumtrapz(p[idx], tt))
        X = np.column_stack([_cumtrapz(p[idx] * np.sin(alpha[idx]), tt), _cumtrapz(-r[idx] * np.cos(alpha[idx]), tt),
                             _cumtrapz(ay[idx] / V[idx], tt), _cumtrapz(bank / V[idx], tt)])
        triples.append((X, beta[idx], np.column_stack([np.ones_like(tt), tt])))
    b, se = _pooled_fit(triples, 4)
    with np.errstate(invalid="ignore", divide="ignore"):
        sure = np.isfinite(b) & (np.abs(b) >= MIN_T_STAT * se)
    return b, sure, attitude, vane


def _bank_sign(fit) -> float:
    """From the sideslip fit (_lateral_fit) with the attitude columns: +1 when the bank's gravity
    (from phi_rad) agrees with the sideslip vane and the yaw gyro, -1 when it has the other sign,
    0 when the fit cannot tell."""
    if fit is None or not fit[2]:
        return 0.0
    b, sure = fit[0], fit[1]
    if not (sure[1] and sure[3] and _near(b[1], 1.0) and _consistent(b, sure)):
        return 0.0
    return _sign_of(b[3])


def _consistent(b: np.ndarray, sure: np.ndarray) -> bool:
    """Every determined coefficient of R, Y, Gy within SLOPE_TOLERANCE of +1 or -1: the lateral
    kinematics fit the vane at all.  In turbulence the vane reads the air's sideslip and the
    fit does not (c182 in moderate turbulence: Y -3.4), and a sign pattern read from it named
    the yaw gyro for a flipped vane."""
    return all(_sign_of(b[i]) != 0.0 for i in (1, 2, 3) if sure[i])


def _lateral_kinematic(fit) -> UnitFinding | None:
    """From the sideslip fit (_lateral_fit): the sideslip vane against the lateral kinematics,
    per window: beta = bP P + bR R + bY Y + bG Gy with P = integral of p sin alpha, R = integral of -r cos alpha, Y = integral of ay / V,
    Gy = integral of g cos theta sin phi / V (with no attitude columns, phi is the integrated roll
    rate: its initial value goes into the window's slope).  Healthy: all 1.  R and Gy 57.3: the
    vane is in degrees; -1: the vane is flipped (sideslip conventions differ between data
    systems); R alone: the yaw gyro; Y alone: the lateral accelerometer; Gy alone (no
    attitude): the roll gyro.  P (small where alpha is) only keeps the roll rate's part out of
    the others."""
    if fit is None:
        return None
    b, sure, attitude, vane = fit
    if not (sure[1] and sure[3]):
        return None
    degrees = _near(b[1] * DEG, 1.0) and _near(b[3] * DEG, 1.0)
    if not (degrees or _consistent(b, sure)):
        return None
    said = (f"beta = {b[1]:.3g} R {b[2]:+.3g} Y {b[3]:+.3g} Gy {b[0]:+.3g} P over windows (R: the integrated -r cos "
            f"alpha, Y: ay / V, Gy: g cos theta sin phi / V{'' if attitude else ', phi from the roll rate'}, P: "
            "p sin alpha; +1 each expected)")
    if degrees:
        return UnitFinding((vane,), "rad", "deg", DEG, f"{said}: the vane changes 57.3 times as much as the "
                           "kinematics say (1 for rad, 57.3 for deg)", overridable=False)
    R, Y, G = (_sign_of(b[i]) if sure[i] else 0.0 for i in (1, 2, 3))
    if R < 0 and G < 0 and Y <= 0:
        column, convention, why = vane, "beta positive with the relative wind from the right (nose left)", \
            "the vane disagrees with the gyros and the accelerometer alike"
    elif R < 0 and G > 0:
        column, convention, why = "r_rad_s", "r positive nose right", "the yaw gyro disagrees with the vane and gravity"
    elif R > 0 and G > 0 and Y < 0:
        column, convention, why = "ay_m_s2", "ay positive to the right (body y axis)", \
            "the lateral accelerometer disagrees with the vane, the yaw gyro and gravity"
    elif R > 0 and G < 0 and not attitude:
        column, convention, why = "p_rad_s", "p positive right wing down", \
            "the bank from the roll rate disagrees with the vane and the yaw gyro"
    else:
        return None
    return UnitFinding((column,), convention, "the opposite sign", -1.0, f"{said}: {why}", kind="sign",
                       overridable=False)


def _sign_of(x: float) -> float:
    """+1 or -1 where x is within SLOPE_TOLERANCE of it, else 0."""
    return 1.0 if _near(x, 1.0) else -1.0 if _near(x, -1.0) else 0.0
