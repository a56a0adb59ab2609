"""The airspeed's kinematic check: V_m_s against the true airspeed the pitch kinematics imply.

The vane alpha is fitted on the integrated pitch rate, the flight path's change (from az and V)
and q/V per window; the flight-path part's share is 1 / (V_m_s / true airspeed), free of the
vane's gain and position.  A scale near 1.9 or 3.3 is an airspeed in kt or ft/s (the magnitude
alone cannot tell an aircraft's 95 kt from 95 m/s); a scale at a calibrated airspeed's share of
the true one at the flight's altitude is a calibrated (indicated, equivalent) airspeed taken for
the true one (aerosid.vehicles.airspeed converts it).  In gusts the vane reads the air's angle
and the kinematics the body's: no verdict.  Called by aerosid.plausibility.units after the pitch
kinematics (aerosid.plausibility.kinematics), whose helpers it shares, and by the vane timing's
airdata_delay finding and the run's airspeed_scale finding (aerosid.identification.airdata_findings).
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from aerosid.plausibility.kinematics import _cumtrapz, _despike, _pitch_inputs, _pooled_fit, _windows
from aerosid.plausibility.units import UnitFinding, _air_rows


#: Windows [s] of the airspeed-scale fit (the Twin Otter's manoeuvre 017 lasts 6 s).
AIRSPEED_WINDOW_S = 4.0
#: A calibrated-airspeed or unit hypothesis fits when the scale is within this factor of it.
AIRSPEED_HYPOTHESIS_TOLERANCE = 1.1
#: A window of the fit ends at a gap longer than this many sample intervals.
AIRSPEED_MAX_GAP_SAMPLES = 1.5
#: An airspeed unit is looked for only above this scale (kt reads 1.94; true airspeeds 0.908-1.058).
AIRSPEED_UNIT_SCALE_MIN = 1.5


def _airspeed_scale(rows: pd.DataFrame, vane: str, t: np.ndarray, q: np.ndarray, gdot: np.ndarray):
    """(s, se): V_m_s over the airspeed the pitch kinematics imply.  The vane alpha is fitted on
    [Q, G, q/V] per window (Q the integrated pitch rate, G the flight path's change from az and
    V, q/V the vane's lever arm); the flight-path part's share -b_G / b_Q is 1 / s, free of the
    vane's gain.  With true airspeeds: 0.908-1.058 on 128 calm JSBSim flights (5-95 %: 0.92-1.02) and
    0.96, 0.97 on the real Twin Otter (its vane's arm, about -1 m, needs the q/V term)."""
    alpha = _despike(rows[vane].to_numpy(float))
    V = np.maximum(rows["V_m_s"].to_numpy(float), 1.0)
    triples = []
    # windows end at any missing sample: the integrals would bridge a gap with a straight line, and in a
    # manoeuvre that step in Q and G biases the scale (pa28 seed 3's dropouts: 0.856 for 0.980)
    for idx in _windows(t, AIRSPEED_WINDOW_S, max_gap_s=AIRSPEED_MAX_GAP_SAMPLES * float(np.median(np.diff(t)))):
        tt = t[idx] - t[idx][0]
        X = np.column_stack([_cumtrapz(q[idx], tt), _cumtrapz(gdot[idx], tt), q[idx] / V[idx]])
        triples.append((X, alpha[idx], np.column_stack([np.ones_like(tt), tt])))
    b, se = _pooled_fit(triples, 3)
    if not (np.all(np.isfinite(b[:2])) and b[0] > 0 and b[1] < 0) or _gusty(triples, b, t):
        return math.nan, math.nan
    s = -b[1] / b[0]
    return s, s * math.hypot(se[0] / b[0], se[1] / b[1])


#: The airspeed-scale fit's residual, low-passed over GUST_SMOOTH_S (the vane's own noise averages
#: out), with a standard deviation above GUST_RESIDUAL_SHARE of the fitted part's, is a gust the vane
#: sees and the kinematics do not: the scale is then biased, and no verdict is given.  Measured with
#: true airspeeds: 22 calm or light-turbulence JSBSim flights at 1-12 km 0.044-0.21 (J3Cub), the real
#: Twin Otter 0.025; in JSBSim's light turbulence at 1.1-1.4 km 0.47-1.26 (scales 0.39-0.99), in
#: moderate 0.25-1.5 (scales 0.14-1.0).
GUST_SMOOTH_S = 0.25
GUST_RESIDUAL_SHARE = 0.3


def _gusty(triples, b: np.ndarray, t: np.ndarray) -> bool:
    width = max(1, int(round(GUST_SMOOTH_S / float(np.median(np.diff(t))))))
    kernel = np.ones(width) / width
    smooth, fitted = [], []
    for X, y, nuisance in triples:
        def detrend(v):
            return v - nuisance @ np.linalg.lstsq(nuisance, v, rcond=None)[0]
        smooth.append(np.convolve(detrend(y - X @ b), kernel, mode="same"))
        fitted.append(detrend(X @ b))
    spread = float(np.std(np.concatenate(fitted)))
    return not spread > 0 or float(np.std(np.concatenate(smooth))) > GUST_RESIDUAL_SHARE * spread


def airspeed_scale(frame: pd.DataFrame, vehicle) -> tuple[float, float]:
    """(s, se): V_m_s over the true airspeed the pitch kinematics imply (_airspeed_scale) on a
    frame with t_s, q_rad_s, az_m_s2, V_m_s and the vehicle's alpha vane; NaN without vanes, in
    gusts or where the fit does not determine it."""
    inputs = _pitch_inputs(frame, vehicle)
    if inputs is None or inputs[1] is None:
        return math.nan, math.nan
    return _airspeed_scale(*inputs)


def _airspeed_unit_finding(s: float, se: float, said: str) -> UnitFinding | None:
    """V_m_s in kt, ft/s, mph or km/h: the pitch kinematics put it at 1.9-3.6 x the true airspeed
    (the magnitude test cannot tell an aircraft's 95 kt from 95 m/s); the closest unit, and the
    others within AIRSPEED_HYPOTHESIS_TOLERANCE (the kinematics' spread is about 10 %)."""
    from aerosid.plausibility.units import SPEED_UNITS

    if not (math.isfinite(s) and s - 3.0 * se > AIRSPEED_UNIT_SCALE_MIN):
        return None
    fits = sorted((abs(math.log(s * f)), unit, f) for unit, f in SPEED_UNITS.items()
                  if abs(math.log(s * f)) < math.log(AIRSPEED_HYPOTHESIS_TOLERANCE))
    if not fits:
        return None
    _, unit, f = fits[0]
    others = f" (or {', '.join(u for _, u, _ in fits[1:])})" if len(fits) > 1 else ""
    return UnitFinding(("V_m_s",), "m/s", unit + others, f,
                       f"{said} x the true airspeed (1 for m/s, {1 / f:.3g} for {unit}); the magnitude alone "
                       "cannot tell an aircraft's speed in one from the other")


def airspeed_finding(frame: pd.DataFrame, vehicle) -> UnitFinding | None:
    """V_m_s in another unit (_airspeed_unit_finding), or holding a calibrated (indicated,
    equivalent) airspeed instead of the true one: the pitch kinematics put V_m_s below the true
    airspeed by the factor a calibrated airspeed has at the flight's altitude (0.73 at 6 km),
    beyond [plausibility] airspeed_scale_min (3 sigma).  Below about 4 km a calibrated airspeed
    is within 18 % of the true one, as close as the kinematics' own spread over flights
    (0.908-1.058): it is not told apart there."""
    from aerosid.vehicles.airspeed import calibrated_share
    from aerosid.vehicles.atmosphere import H_MAX_M, H_MIN_M

    s, se = airspeed_scale(frame, vehicle)
    vane = vehicle.alpha_column
    said = (f"the pitch kinematics (the vane {vane} against the integrated pitch rate and the flight path's "
            f"change from az_m_s2 and V_m_s) put V_m_s at {s:.3g} +/- {se:.2g}")
    unit = _airspeed_unit_finding(s, se, said)
    if unit is not None:
        return unit
    floor = float(vehicle.envelope.airspeed_scale_min)
    if not (math.isfinite(s) and s + 3.0 * se < floor):
        return None
    V, h = _air_rows(frame, h_bounds=(H_MIN_M, H_MAX_M))
    if len(V) < 10:
        return None
    cas = calibrated_share(V, h)
    if abs(math.log(s / cas)) >= math.log(AIRSPEED_HYPOTHESIS_TOLERANCE):
        return None
    return UnitFinding(("V_m_s",), "true airspeed", "a calibrated (or indicated, or equivalent) airspeed", 1.0 / cas,
                       f"{said} x the true airspeed ({floor:g} or more expected, [plausibility] "
                       f"airspeed_scale_min); a calibrated "
                       f"airspeed at the flight's altitude (median h_m {np.median(h):.0f} m) is {cas:.3g} x "
                       f"the true one: q-bar would be low by {cas**2:.2f} and every coefficient high by "
                       f"{1.0 / cas**2:.2f}", kind="airspeed")
