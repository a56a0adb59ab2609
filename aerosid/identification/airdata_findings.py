"""The air data against the IMU's kinematics as a run's findings (aerosid.identification.flight_data
calls it per segment with vanes):

* the vanes' timing: the delay aerosid.identification.vanes estimates becomes an ``airdata_delay``
  finding (reported, with the value to set), a vane that does not follow the kinematics a
  ``vane_mismatch`` one;
* the airspeed: V_m_s against the true airspeed the pitch kinematics imply
  (aerosid.plausibility.airspeed_scale); beyond what true airspeeds give, and not a unit or a
  calibrated airspeed the pre-flight would have refused, an ``airspeed_scale`` finding (a ground
  speed with wind, a miscalibrated airspeed);

and a record of both (the delay, the gain, the airspeed scale) for the run's audit trail.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from aerosid.estimation.findings import Finding
from aerosid.identification.vanes import MAX_DELAY_S, vane_delay
from aerosid.vehicles.vehicle import Vehicle

#: An airspeed scale beyond this (3 sigma; the lower bound is the vehicle's [plausibility]
#: airspeed_scale_min) is reported: true airspeeds read 0.908-1.058 on 128 calm bench flights.
AIRSPEED_SCALE_MAX = 1.15
#: The airdata_delay finding names a calibrated airspeed as a look-alike where, at the flight's
#: altitude, one is below this share of the true airspeed (about 600 m and up).
CAS_HINT_SHARE_MAX = 0.97


def airdata_findings(t, ok, clean: dict, bl, vehicle: Vehicle, segment: str) -> tuple[list[Finding], dict | None]:
    """(findings, record): the vanes' delay behind the IMU and the airspeed's scale on the band
    path's signals (clean: the preprocessed ``*_clean`` arrays; ok: the rows used); the record for
    the run's audit trail, None when the delay has no estimate.  The smoother path applies the
    vehicle file's delay_s but estimates none."""
    def grid(x):
        return np.where(ok, x, np.nan)

    vd = vane_delay(t, grid(clean[vehicle.alpha_column] - vehicle.alpha_bias_rad),
                    grid(clean[vehicle.beta_column] - vehicle.beta_bias_rad),
                    *(grid(bl.rates_rad_s[:, j]) for j in range(3)), *(grid(bl.accel_cg_m_s2[:, j]) for j in range(3)),
                    grid(clean["V_m_s"]), applied_s=vehicle.vane_delay_s)
    scale = _airspeed_scale(t[ok], clean, ok, vehicle)
    found = [f for f in (_airspeed_finding(scale, t[ok], vehicle, segment),) if f is not None]
    if vd is None:
        return found, None
    record = {"segment": segment, **{k: (v if not isinstance(v, float) or math.isfinite(v) else None)
                                     for k, v in {**vd.as_dict(), "airspeed_scale": float(scale[0]),
                                                  "airspeed_scale_sigma": float(scale[1])}.items()}}
    ts = t[ok]
    if not vd.follows and not vehicle.turbulent_air:  # in turbulence the vane reads the gusts' angle too
        lost = "" if math.isfinite(vd.delay_s) else f", and no delay within {MAX_DELAY_S:g} s fits"
        return found + [Finding("vane_mismatch", segment, vehicle.alpha_column, float(ts[0]), float(ts[-1]), vd.n, False,
                                f"the vane alpha does not follow the IMU's kinematic alpha (gain {vd.gain:.3g} per "
                                f"rad, about 1 expected{lost}): a dead, floating or miscalibrated vane, the wrong "
                                "column, an airspeed V_m_s in other units (the kinematic alpha reads V: knots turned "
                                "c182's gain to 0.17), or turbulence (the vane reads the air's angle, the kinematics "
                                "the body's: then set [estimation] turbulent_air = true in the vehicle file). Every "
                                "coefficient read through alpha (C_N,alpha, C_m,alpha, the alpha-dot damping) is then "
                                "suspect: check the vane and its calibration before using them")], record
    if not vd.detected:
        return found, record
    total = vd.delay_s + vd.applied_s
    return found + [Finding("airdata_delay", segment, vehicle.alpha_column, float(ts[0]), float(ts[-1]), vd.n, False,
                            f"{vd.summary()}; equation error pairs each coefficient with the angle read at the same "
                            f"time stamp, so a late vane biases C_N,delta, C_m,alpha and C_m,q. If the air-data system "
                            f"has this delay, set `delay_s = {total:.3f}` in the vehicle file's [air_data] table (both "
                            f"vanes are then advanced by it) and run again; a vane ahead of the CG whose angle was not "
                            f"moved to the CG (it reads alpha - x q / V) looks alike, and a time shift is not its cure: "
                            f"give its position as [air_data] vane_position_m instead"
                            f"{_calibrated_airspeed_hint(scale, clean, ok)}")], record


def _airspeed_scale(t: np.ndarray, clean: dict, ok: np.ndarray, vehicle: Vehicle) -> tuple[float, float]:
    from aerosid.plausibility.airspeed_scale import airspeed_scale

    cols = ("q_rad_s", "az_m_s2", "V_m_s", vehicle.alpha_column)
    return airspeed_scale(pd.DataFrame({"t_s": t, **{c: clean[c][ok] for c in cols}}), vehicle)


def _airspeed_finding(scale: tuple[float, float], ts: np.ndarray, vehicle: Vehicle, segment: str) -> Finding | None:
    """``airspeed_scale`` (reported) when the scale lies beyond what true airspeeds give by 3
    sigma: a ground speed (GPS) with wind, a miscalibrated airspeed, or a unit or calibrated
    airspeed the vehicle file's [plausibility] airspeed_scale_min let through."""
    s, se = scale
    lo = float(vehicle.envelope.airspeed_scale_min)
    if not (math.isfinite(s) and (s + 3.0 * se < lo or s - 3.0 * se > AIRSPEED_SCALE_MAX)):
        return None
    return Finding("airspeed_scale", segment, "V_m_s", float(ts[0]), float(ts[-1]), len(ts), False,
                   f"the pitch kinematics (the vane alpha against the integrated pitch rate and the flight path's "
                   f"change) put V_m_s at {s:.3g} +/- {se:.2g} x the true airspeed ({lo:g}..{AIRSPEED_SCALE_MAX:g} "
                   f"expected): q-bar reads {s**2:.2f} x and every coefficient {1.0 / s**2:.2f} x what it should. "
                   "V_m_s must be the true airspeed: a ground speed (GPS) is off by the wind, a calibrated or "
                   "indicated one by the density ([air_data] airspeed converts it), a miscalibrated one by its "
                   "error")


def _calibrated_airspeed_hint(scale: tuple[float, float], clean: dict, ok: np.ndarray) -> str:
    """A clause for the airdata_delay finding: a V_m_s holding a calibrated airspeed makes the
    kinematic alpha's flight-path part too large, and the timing fit reads that as a lag (c182,
    J3Cub, pa28, OV10 at 1100-1450 m: 27.7, 17.4, 12.2, 50.6 ms reported, gains 0.91-1.02, as
    healthy vanes' gains spread: the gain does not tell it).  Below about 4 km the unit check
    cannot tell it either (aerosid.plausibility.airspeed_scale), so the finding names it, unless the
    pitch kinematics' airspeed scale lies above a calibrated airspeed's share by 3 sigma (the real
    Twin Otter's 0.965 +- 0.004 against 0.898: its lag is the vane's)."""
    from aerosid.vehicles.airspeed import calibrated_share

    V, h = clean["V_m_s"][ok], clean["h_m"][ok]
    good = np.isfinite(V) & np.isfinite(h) & (V > 0)
    if good.sum() < 10:
        return ""
    share = calibrated_share(V[good], h[good])
    s, se = scale
    if share >= CAS_HINT_SHARE_MAX or s - 3.0 * se > share:
        return ""
    return (f"; a V_m_s holding a calibrated (or indicated) airspeed looks alike too (at this flight's altitude, "
            f"median h_m {np.median(h[good]):.0f} m, one is {share:.3g} of the true airspeed: q-bar then reads low "
            f"and every coefficient high by {1.0 / share**2:.2f}), and a delay_s is not its cure: check that the "
            f"airspeed column is the true airspeed (if it is not, the vehicle file's [air_data] airspeed = "
            f"\"calibrated\" converts it)")
