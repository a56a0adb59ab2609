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

from aerosid.estimation.findings import Finding, dilate, sample_interval, span_findings
from aerosid.identification.vanes import MAX_DELAY_S, kinematic_alpha_rate, kinematic_mismatch_z, vane_delay
from aerosid.vehicles.vehicle import Vehicle

#: An airspeed scale beyond this (3 sigma; the lower bound is the vehicle's [plausibility]
#: airspeed_scale_min) is reported: true airspeeds read 0.908-1.058 on 128 calm bench flights.
AIRSPEED_SCALE_MAX = 1.15
#: The airdata_delay finding names a calibrated airspeed as a look-alike where, at the flight's
#: altitude, one is below this share of the true airspeed (about 600 m and up).
CAS_HINT_SHARE_MAX = 0.97
#: A ``kinematic_mismatch``: the vane's rate and the flight-path kinematics' alpha-dot apart by
#: this many robust sigma (vanes.kinematic_mismatch_z) for at least KINEMATIC_MISMATCH_MIN_S.
#: Healthy JSBSim flights (c172x, pa28, J3Cub, c182) reach 2.4-5.0; a 1.5 s step of 0.03 rad/s on
#: q 13.8-26.3, of 2 m/s^2 on a_z 24.9-38.0 (2026-11-29, docs/estimation.md).
KINEMATIC_MISMATCH_Z = 8.0
KINEMATIC_MISMATCH_MIN_S = 0.25


def airdata_findings(t, ok, clean: dict, bl, vehicle: Vehicle, segment: str,
                     explained: np.ndarray | None = None) -> tuple[list[Finding], dict | None, np.ndarray]:
    """(findings, record, condemned): the vanes' delay behind the IMU, the airspeed's scale and
    the spans where the vane and the IMU's kinematics disagree, on the band path's signals (clean:
    the preprocessed ``*_clean`` arrays; ok: the rows used); the record for the run's audit trail,
    None when the delay has no estimate; condemned: the samples of ``kinematic_mismatch`` findings,
    to be cut from every channel (explained: samples already condemned on a_z, left out of that
    test).  The smoother path applies the vehicle file's delay_s but estimates none."""
    def grid(x):
        return np.where(ok, x, np.nan)

    signals = (t, grid(clean[vehicle.alpha_column] - vehicle.alpha_bias_rad),
               grid(clean[vehicle.beta_column] - vehicle.beta_bias_rad),
               *(grid(bl.rates_rad_s[:, j]) for j in range(3)), *(grid(bl.accel_cg_m_s2[:, j]) for j in range(3)),
               grid(clean["V_m_s"]))
    vd, mismatch, condemned = _timing_and_mismatch(signals, vehicle, bl.band_hz, explained, segment)
    scale = _airspeed_scale(t[ok], clean, ok, vehicle)
    found = [f for f in (_airspeed_finding(scale, t[ok], vehicle, segment),) if f is not None] + mismatch
    if vd is None:
        return found, None, condemned
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
                                "suspect: check the vane and its calibration before using them")], record, condemned
    if not vd.detected:
        return found, record, condemned
    total = vd.delay_s + vd.applied_s
    return found + [Finding("airdata_delay", segment, vehicle.alpha_column, float(ts[0]), float(ts[-1]), vd.n, False,
                            f"{vd.summary()}; equation error pairs each coefficient with the angle read at the same "
                            f"time stamp, so a late vane biases C_N,delta, C_m,alpha and C_m,q. If the air-data system "
                            f"has this delay, set `delay_s = {total:.3f}` in the vehicle file's [air_data] table (both "
                            f"vanes are then advanced by it) and run again; a vane ahead of the CG whose angle was not "
                            f"moved to the CG (it reads alpha - x q / V) looks alike, and a time shift is not its cure: "
                            f"give its position as [air_data] vane_position_m instead"
                            f"{_calibrated_airspeed_hint(scale, clean, ok)}")], record, condemned


def _timing_and_mismatch(signals: tuple, vehicle: Vehicle, band_hz: float, explained: np.ndarray | None,
                         segment: str):
    """(the vanes' delay, ``kinematic_mismatch`` findings, their samples).  A gyro or a_z step
    leaves the integrated kinematics off the vane for the rest of the run, which the delay's fit
    cannot absorb (c172x seed 0, q +0.03 rad/s for 1.5 s: gain 0.29, read as a vane that does not
    follow), so the mismatch is found first on the rates (no delay, gain 1), the delay fitted
    without those spans, and the mismatch looked for again with the fitted delay and gain (a
    vane that lags, the real Twin Otter's 25 ms, leaves its own rate error).  Nothing is condemned
    when the vane does not follow the kinematics even so, or in turbulence."""
    t = signals[0]
    none = np.zeros(len(t), bool)
    kin = None if vehicle.turbulent_air else kinematic_alpha_rate(*signals)
    pad = int(round(1.0 / (band_hz * sample_interval(t)))) if len(t) > 1 and band_hz > 0 else 0

    def without(mask):  # the delay's fit on the runs between the spans (one band period on each side)
        cut = dilate(mask, pad)
        return vane_delay(t, *(np.where(cut, np.nan, x) for x in signals[1:]), applied_s=vehicle.vane_delay_s)

    if kin is None:
        return without(none), [], none
    _, hit = _kinematic_mismatch(t, signals[1], kin, band_hz, 0.0, 1.0, explained, segment)
    vd = without(hit)
    if vd is None or not vd.follows:
        return (without(none) if hit.any() else vd), [], none
    found, again = _kinematic_mismatch(t, signals[1], kin, band_hz, vd.delay_s, vd.gain, explained, segment)
    if not np.array_equal(again, hit):
        vd = without(again)
    return vd, found, again


def _kinematic_mismatch(t, alpha, kin: tuple, band_hz: float, delay_s: float, gain: float,
                        explained: np.ndarray | None, segment: str) -> tuple[list[Finding], np.ndarray]:
    """``kinematic_mismatch`` findings (cut) and their samples: spans where the vane's rate and the
    kinematic alpha-dot disagree by KINEMATIC_MISMATCH_Z.  The filter follows a gyro step as a
    manoeuvre and may follow an a_z step, so nothing else sees them; the vane is the one sensor
    that does not move with them."""
    z = kinematic_mismatch_z(t, alpha, kin[0], kin[1], band_hz, delay_s, gain)
    with np.errstate(invalid="ignore"):
        off = z > KINEMATIC_MISMATCH_Z
    if explained is not None:
        off &= ~np.asarray(explained, bool)
    dt = sample_interval(t)
    return span_findings("kinematic_mismatch", segment, "q/az/alpha", t, off,
                         int(np.ceil(KINEMATIC_MISMATCH_MIN_S / dt)), True,
                         f"the vane alpha's rate and the flight-path kinematics' alpha-dot (q, a_z, V) disagree by "
                         f"more than {KINEMATIC_MISMATCH_Z:g} robust sigma: a step or drift of the pitch gyro or the "
                         "normal accelerometer the filter followed as a manoeuvre, or a vane glitch; cut from every "
                         "channel (the pitch gyro feeds them all)")


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
