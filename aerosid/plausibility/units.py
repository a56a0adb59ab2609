"""Unit mistakes in raw telemetry: a channel whose values fit another unit far better
than the declared one (deg/s for rad/s, g for m/s^2, km or ft for m, kt for m/s).

Two kinds of evidence, each compared for the declared unit and the candidates:

* **Magnitude** against the vehicle's envelope (``Vehicle.envelope``, the vehicle
  file's ``[plausibility]`` table or its class defaults): the 99th percentile of |p|,
  |q|, |r| against ``rate_rad_s``; the medians of the specific force |(ax, ay, az)|,
  the airspeed, the altitude and the dynamic pressure (US-1976 density) against their
  ranges; the median Mach against the preflight model's Mach range (finned vehicles).
  A channel is refused only when its declared unit is outside the envelope *and* a
  candidate unit puts it inside.
* **Kinematics**, which need no envelope: (a) the pitch rate integrates to the
  change of pitch attitude; with the flight path's change from the normal
  acceleration, what is left is the change of angle of attack, which the vanes
  measure (aircraft) or which stays within ``alpha_rad`` (finned): a pitch gyro in
  deg/s integrates to 57 times too much.  (b) The altitude's second derivative is the
  vertical acceleration: per window, h is regressed on the doubly integrated
  -(az + g) (with a quadratic for the unknown initial climb rate and attitude); the
  slope is 1 for metres, 0.001 for kilometres and 3.28 for feet.

Found mistakes raise ``TelemetryError`` naming the file, the column, the likely unit
and the evidence.  Neither test fires on the shipped flights (seed-rlv, JSBSim c172x,
the SIDPAC Twin Otter data): tests/test_plausibility_units.py.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

G0 = 9.80665
DEG = math.pi / 180.0

#: Candidate units per quantity: name -> factor to SI (SI value = factor x declared value).
RATE_UNITS = {"deg/s": DEG}
ACCEL_UNITS = {"g": G0, "ft/s^2": 0.3048}
SPEED_UNITS = {"kt": 0.514444, "km/h": 1.0 / 3.6, "ft/s": 0.3048, "mph": 0.44704}
ALTITUDE_UNITS = {"km": 1000.0, "ft": 0.3048}

#: Kinematic windows [s] and the evidence they need.
ALPHA_WINDOW_S = 2.0
ALTITUDE_WINDOW_S = 6.0
MIN_T_STAT = 10.0  # pooled slope / its standard error, before a kinematic slope is believed
SLOPE_TOLERANCE = 2.0  # a candidate unit fits when the slope is within this factor of its value


@dataclass(frozen=True)
class UnitFinding:
    """A column (or a sensor triad) whose values fit `likely` far better than `declared`."""

    columns: tuple[str, ...]
    declared: str
    likely: str
    factor: float  # SI value = factor x value as written
    evidence: str

    def message(self) -> str:
        cols = ", ".join(self.columns)
        return (f"values look like {self.likely}, not {self.declared}: {self.evidence}. Convert "
                f"{'the column' if len(self.columns) == 1 else 'the columns ' + cols} to {self.declared} "
                f"(multiply by {self.factor:.6g}); if the values are right, widen the vehicle file's "
                "[plausibility] table")


def _usable(x: np.ndarray) -> np.ndarray:
    from schemas.telemetry import sentinel_mask

    x = np.asarray(x, dtype=float)
    return x[np.isfinite(x) & ~sentinel_mask(x)]


def _inside(x: float, bounds) -> bool:
    return bounds[0] <= x <= bounds[1]


def _fmt_range(bounds) -> str:
    return f"{bounds[0]:g}..{bounds[1]:g}"


#: Density scale height above the US-1976 model's top [m] (the model ends at 81 km;
#: an altitude in feet can read 100 km and more).
SCALE_HEIGHT_M = 5500.0


def _qbar_pa(V: np.ndarray, h: np.ndarray) -> np.ndarray:
    from aerosid.vehicles.atmosphere import H_MAX_M, H_MIN_M, density_kg_m3

    rho = density_kg_m3(np.clip(h, H_MIN_M, H_MAX_M)) * np.exp(-np.clip(h - H_MAX_M, 0.0, None) / SCALE_HEIGHT_M)
    return 0.5 * rho * V**2


def _mach(V: np.ndarray, h: np.ndarray) -> np.ndarray:
    from aerosid.vehicles.atmosphere import H_MAX_M, H_MIN_M, speed_of_sound_m_s

    return V / speed_of_sound_m_s(np.clip(h, H_MIN_M, H_MAX_M))


def _air_rows(frame: pd.DataFrame, n_max: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    """V and h on rows where both are usable, thinned to at most n_max rows."""
    from schemas.telemetry import sentinel_mask

    V, h = frame["V_m_s"].to_numpy(float), frame["h_m"].to_numpy(float)
    ok = np.isfinite(V) & np.isfinite(h) & ~sentinel_mask(V) & ~sentinel_mask(h) & (V > 0)
    V, h = V[ok], h[ok]
    step = max(1, len(V) // n_max)
    return V[::step], h[::step]


# --------------------------------------------------------------------------- magnitude
def _accel_finding(frame: pd.DataFrame, env) -> UnitFinding | None:
    cols = ("ax_m_s2", "ay_m_s2", "az_m_s2")
    a = frame[list(cols)].to_numpy(float)
    a = a[np.all(np.isfinite(a), axis=1)]
    if len(a) < 10:
        return None
    f = float(np.median(np.linalg.norm(a, axis=1)))
    if _inside(f, env.specific_force_m_s2):
        return None
    for unit, k in ACCEL_UNITS.items():
        if _inside(f * k, env.specific_force_m_s2):
            return UnitFinding(cols, "m/s^2", unit, k,
                               f"the median specific force |(ax, ay, az)| is {f:.4g}, outside the vehicle's "
                               f"plausible {_fmt_range(env.specific_force_m_s2)} m/s^2; as {unit} it is "
                               f"{f * k:.4g} m/s^2")
    return None


def _rate_findings(frame: pd.DataFrame, env) -> list[UnitFinding]:
    out = []
    for col in ("p_rad_s", "q_rad_s", "r_rad_s"):
        x = _usable(frame[col].to_numpy(float))
        if len(x) < 10:
            continue
        p99 = float(np.percentile(np.abs(x), 99))
        if p99 <= env.rate_rad_s:
            continue
        for unit, k in RATE_UNITS.items():
            if p99 * k <= env.rate_rad_s:
                out.append(UnitFinding((col,), "rad/s", unit, k,
                                       f"the 99th percentile of |{col.split('_')[0]}| is {p99:.4g}, beyond the "
                                       f"vehicle's plausible {env.rate_rad_s:g} rad/s ([plausibility] rate_rad_s); "
                                       f"as {unit} it is {p99 * k:.3g} rad/s"))
                break
    return out


def _air_data_findings(frame: pd.DataFrame, vehicle) -> list[UnitFinding]:
    """V and h against the envelope (airspeed, altitude, dynamic pressure, Mach range)."""
    env = vehicle.envelope
    V, h = _air_rows(frame)
    if len(V) < 10:
        return []
    mach_range = None
    if vehicle.preflight is not None and len(vehicle.preflight.mach_breakpoints) >= 2:
        mach_range = (vehicle.preflight.mach_breakpoints[0], vehicle.preflight.mach_breakpoints[-1])

    def problems(Vs, hs) -> list[str]:
        out = []
        for name, value, bounds, unit in (("airspeed", np.median(Vs), env.V_m_s, "m/s"),
                                          ("altitude", np.median(hs), env.h_m, "m"),
                                          ("dynamic pressure", np.median(_qbar_pa(Vs, hs)), env.qbar_pa, "Pa")):
            if not _inside(float(value), bounds):
                out.append(f"median {name} {value:.4g} {unit} outside the plausible {_fmt_range(bounds)} {unit}")
        if mach_range is not None:
            m = float(np.median(_mach(Vs, hs)))
            if not _inside(m, mach_range):
                out.append(f"median Mach {m:.3g} outside the preflight model's Mach {_fmt_range(mach_range)}")
        return out

    declared = problems(V, h)
    if not declared:
        return []
    fits = []  # (column, unit, factor, distance of the median Mach from the reference)
    for col, units in (("V_m_s", SPEED_UNITS), ("h_m", ALTITUDE_UNITS)):
        for unit, k in units.items():
            Vs, hs = (V * k, h) if col == "V_m_s" else (V, h * k)
            if not problems(Vs, hs):
                dist = abs(math.log(max(float(np.median(_mach(Vs, hs))), 1e-9) / vehicle.mach_reference))
                fits.append((dist, col, unit, k))
    if not fits:
        return []
    fits.sort()
    _, col, unit, k = fits[0]
    others = [u for _, c, u, _ in fits[1:] if c == col]
    declared_unit = "m/s" if col == "V_m_s" else "m"
    alternatives = f" (or {', '.join(others)})" if others else ""
    return [UnitFinding((col,), declared_unit, unit + alternatives, k,
                        f"as {declared_unit}: {'; '.join(declared)}; as {unit} all of them are plausible "
                        f"and the median Mach is the closest to the vehicle's reference Mach "
                        f"{vehicle.mach_reference:g}")]


# --------------------------------------------------------------------------- kinematics
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


def _pooled_slope(pairs) -> tuple[float, float, int]:
    """Slope k of y = k x + nuisance (per window), pooled over windows: (k, se, n)."""
    sxx = sxy = 0.0
    resid_parts, n_nuis = [], 0
    xs, ys = [], []
    for x, y, nuisance in pairs:
        bx = np.linalg.lstsq(nuisance, x, rcond=None)[0]
        by = np.linalg.lstsq(nuisance, y, rcond=None)[0]
        xt, yt = x - nuisance @ bx, y - nuisance @ by
        xs.append(xt), ys.append(yt)
        sxx += float(xt @ xt)
        sxy += float(xt @ yt)
        n_nuis += nuisance.shape[1]
    n = sum(len(x) for x in xs)
    if sxx <= 0 or n <= n_nuis + 1:
        return math.nan, math.nan, n
    k = sxy / sxx
    for xt, yt in zip(xs, ys):
        resid_parts.append(yt - k * xt)
    r = np.concatenate(resid_parts)
    se = math.sqrt(float(r @ r) / (n - n_nuis - 1) / sxx)
    return k, se, n


def _clean_rows(frame: pd.DataFrame, cols: list[str]) -> pd.DataFrame:
    rows = frame[["t_s", *cols]].copy()
    ok = np.isfinite(rows.to_numpy(float)).all(axis=1)
    return rows[ok].reset_index(drop=True)


def _pitch_rate_kinematic(frame: pd.DataFrame, vehicle) -> UnitFinding | None:
    """Integrated q against the vanes' alpha (with the flight-path change from az), or
    against the vehicle's alpha range when there are no vanes."""
    env = vehicle.envelope
    vane = vehicle.alpha_column if vehicle.air_data_source == "vanes" else None
    cols = ["q_rad_s", "az_m_s2", "V_m_s"] + ([vane] if vane and vane in frame.columns else [])
    rows = _clean_rows(frame, cols)
    if len(rows) < 100:
        return None
    t = rows["t_s"].to_numpy(float)
    q = _despike(rows["q_rad_s"].to_numpy(float))
    gdot = -(rows["az_m_s2"].to_numpy(float) + G0) / np.maximum(rows["V_m_s"].to_numpy(float), 1.0)
    if len(cols) == 4:  # vanes: alpha + flight-path change = k * integral of q
        alpha = _despike(rows[vane].to_numpy(float))
        pairs = []
        for idx in _windows(t, ALPHA_WINDOW_S * 2):
            tt = t[idx] - t[idx][0]
            Q, G = _cumtrapz(q[idx], tt), _cumtrapz(gdot[idx], tt)
            pairs.append((Q, alpha[idx] + G, np.column_stack([np.ones_like(tt), tt])))
        k, se, _ = _pooled_slope(pairs)
        if not (math.isfinite(k) and k > 0 and k / se >= MIN_T_STAT):
            return None
        if abs(math.log(k / DEG)) < math.log(SLOPE_TOLERANCE) and abs(math.log(k)) > math.log(5.0):
            return UnitFinding(("q_rad_s",), "rad/s", "deg/s", DEG,
                               f"integrated, the pitch rate changes the pitch attitude {1 / k:.3g} times as much "
                               f"as the vane angle of attack ({vane}) and the flight path (from az_m_s2) change "
                               f"together (1 for rad/s, 57.3 for deg/s)")
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
    k, se, _ = _pooled_slope(pairs)
    if not (math.isfinite(k) and k > 0 and k / se >= MIN_T_STAT) or abs(math.log(k)) < math.log(2.5):
        return None
    unit, f = min(ALTITUDE_UNITS.items(), key=lambda u: abs(math.log(k * u[1])))
    if abs(math.log(k * f)) >= math.log(SLOPE_TOLERANCE):
        return None
    return UnitFinding(("h_m",), "m", unit, f,
                       f"the altitude changes {k:.3g} times as much as the vertical acceleration (-(az_m_s2 + g), "
                       f"integrated twice) says it does (1 for metres, 0.001 for km, 3.28 for ft)")


# --------------------------------------------------------------------------- entry points
def unit_findings(frame: pd.DataFrame, vehicle) -> list[UnitFinding]:
    """Every unit mistake found in a raw telemetry frame (RawTelemetry columns), most
    basic first: the accelerometers (the kinematic tests use az), rates, air data,
    then the kinematic tests of the channels that passed."""
    env = vehicle.envelope
    accel = _accel_finding(frame, env)
    if accel is not None:
        return [accel]
    found = _rate_findings(frame, env) + _air_data_findings(frame, vehicle)
    flagged = {c for f in found for c in f.columns}
    if "q_rad_s" not in flagged and "V_m_s" not in flagged:
        kin = _pitch_rate_kinematic(frame, vehicle)
        if kin is not None:
            found.append(kin)
    if "h_m" not in flagged:
        kin = _altitude_kinematic(frame)
        if kin is not None:
            found.append(kin)
    return found


def check_units(frame: pd.DataFrame, vehicle, source: str) -> None:
    """Raise TelemetryError for the first unit mistake found (naming file and column)."""
    from aerosid.preprocess.errors import TelemetryError

    found = unit_findings(frame, vehicle)
    if found:
        first = found[0]
        more = (f" (also: {'; '.join(f'{f.columns[0]} looks like {f.likely}' for f in found[1:])})"
                if len(found) > 1 else "")
        raise TelemetryError(first.message() + more, file=source, column=first.columns[0])
