"""Unit and sign mistakes in raw telemetry: a channel whose values fit another unit far
better than the declared one (deg/s for rad/s, g for m/s^2, km or ft for m, kt for m/s, deg
for rad), or the other sign (an accelerometer z axis pointing up, a flipped gyro or vane).

Two kinds of evidence, each compared for the declared unit and the candidates:

* **Magnitude** against the vehicle's envelope (``Vehicle.envelope``, the vehicle
  file's ``[plausibility]`` table or its class defaults): the 99th percentile of |p|,
  |q|, |r| against ``rate_rad_s``; the medians of the specific force |(ax, ay, az)|,
  the airspeed, the altitude and the dynamic pressure (US-1976 density) against their
  ranges; the median Mach against the preflight model's Mach range (finned vehicles);
  the median az against ``az_m_s2`` (an aircraft's is negative: z down, its lift holds it
  up); the vane angles against 90 deg and the median alpha against ``alpha_rad``.
  A channel is refused only when its declared unit is outside the envelope *and* a
  candidate unit puts it inside.
* **Kinematics**, which need no envelope (aerosid.plausibility.kinematics): the pitch rate
  against the vanes and the flight path, the altitude against the vertical acceleration, the
  attitude columns against the gyros, the sideslip vane against the lateral kinematics.

Found mistakes raise ``TelemetryError`` naming the file, the column, the likely unit (or
sign) and the evidence.  No test fires on the shipped flights (seed-rlv, JSBSim c172x, the
SIDPAC Twin Otter data): tests/test_plausibility_units.py.
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
PRESSURE_UNITS = {"psf": 47.880259, "hPa": 100.0, "kPa": 1000.0, "mmHg": 133.322387, "inHg": 3386.389,
                  "psi": 6894.757}
DENSITY_UNITS = {"slug/ft^3": 515.378818, "lb/ft^3": 16.018463, "g/cm^3": 1000.0}
#: A measured air-data column (rho_kg_m3, qbar_pa, p_static_pa) is refused when its median ratio to
#: the US-1976 value at the record's altitude (for qbar_pa: 0.5 rho V^2 with that density) lies
#: outside this range and a candidate unit brings it inside.  A hot or cold day moves the density
#: by about 20 %; an airspeed column that holds the indicated rather than the true airspeed makes
#: 0.5 rho(h) V^2 low by rho_0 / rho(h), 3 at 10 km; every candidate unit is a factor of 16 or more.
MEASURED_AIR_RATIO = (1.0 / 3.0, 3.0)
#: ... and a measured total temperature's ratio to the US-1976 one (a day 50 K off the standard
#: one is within; degR for K reads x1.8).
TEMPERATURE_RATIO = (0.75, 1.35)



@dataclass(frozen=True)
class UnitFinding:
    """A column (or a sensor triad) whose values fit `likely` far better than `declared`."""

    columns: tuple[str, ...]
    declared: str
    likely: str
    factor: float  # SI value = factor x value as written
    evidence: str
    kind: str = "unit"  # "unit"; "sign": declared is then aerosid's sign convention, factor -1; "setting":
    # a vehicle-file value (declared: its key) the telemetry contradicts, likely: the value it measures;
    # "airspeed": V_m_s is not a true airspeed (factor: about, the conversion depends on the altitude);
    # "pressure": qbar_pa is an impact pressure (factor: about, the conversion depends on the Mach number)
    overridable: bool = True  # a vehicle file's [plausibility] range can accept the values

    def message(self) -> str:
        cols = ", ".join(self.columns)
        widen = "; if the values are right, widen the vehicle file's [plausibility] table" if self.overridable else ""
        if self.kind == "airspeed":
            return (f"values look like {self.likely}, not the {self.declared}: {self.evidence}. State it in the "
                    f"vehicle file, [air_data] airspeed = \"calibrated\" (or \"indicated\", \"equivalent\"), "
                    f"and the preprocessing converts it with the altitude (here about x{self.factor:.3g}); an import "
                    f"map's airspeed key does the same (docs/real-flight.md){widen}")
        if self.kind == "pressure":
            return (f"values look like {self.likely}, not the {self.declared}: {self.evidence}. Convert the column "
                    f"(aerosid.vehicles.airspeed.dynamic_from_impact_pressure_pa; an import map's pressure = "
                    f"\"impact\", docs/real-flight.md), or leave it out: the dynamic pressure then comes from V_m_s "
                    f"and the density")
        if self.kind == "setting":
            return f"the vehicle file's {self.declared} contradicts the telemetry: {self.evidence}"
        if self.kind == "sign":
            return (f"the sign looks flipped: {self.evidence}. aerosid's convention: {self.declared}. Multiply "
                    f"{'the column' if len(self.columns) == 1 else 'the wrong one of ' + cols} by -1 (an import "
                    f"map's sign = -1){widen}")
        return (f"values look like {self.likely}, not {self.declared}: {self.evidence}. Convert "
                f"{'the column' if len(self.columns) == 1 else 'the columns ' + cols} to {self.declared} "
                f"(multiply by {self.factor:.6g}){widen}")


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


def _air_rows(frame: pd.DataFrame, n_max: int = 2000, column: str | None = None, h_bounds=(-math.inf, math.inf)
              ) -> tuple[np.ndarray, ...]:
    """V and h (and `column`, positive) on rows where all are usable and h lies within h_bounds,
    thinned to at most n_max rows."""
    from schemas.telemetry import sentinel_mask

    arrays = [frame[c].to_numpy(float) for c in ("V_m_s", "h_m", *((column,) if column else ()))]
    V, h = arrays[:2]
    ok = np.logical_and.reduce([np.isfinite(a) & ~sentinel_mask(a) for a in arrays])
    ok &= (V > 0) & (h >= h_bounds[0]) & (h <= h_bounds[1]) & (arrays[-1] > 0 if column else True)
    step = max(1, int(ok.sum()) // n_max)
    return tuple(a[ok][::step] for a in arrays)


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


def _az_sign_finding(frame: pd.DataFrame, env) -> UnitFinding | None:
    """An accelerometer z axis pointing up: the median az outside the vehicle's az range
    (an aircraft's is negative, its lift holding it up), inside it with the sign changed."""
    x = _usable(frame["az_m_s2"].to_numpy(float))
    if len(x) < 10:
        return None
    m = float(np.median(x))
    if _inside(m, env.az_m_s2) or not _inside(-m, env.az_m_s2):
        return None
    return UnitFinding(("az_m_s2",), "body axes x forward, y right, z down (level flight reads az = -g)",
                       "the opposite sign", -1.0,
                       f"the median az_m_s2 is {m:+.4g} m/s^2, outside the vehicle's {_fmt_range(env.az_m_s2)} "
                       "m/s^2 ([plausibility] az_m_s2): a z axis pointing up", kind="sign")


#: Largest |angle| [rad] a vane or surface column holds (90 deg): in degrees most values lie beyond.
ANGLE_BOUND_RAD = 1.6


def _vane_findings(frame: pd.DataFrame, vehicle) -> list[UnitFinding]:
    """Vane angles written in degrees: most values beyond ANGLE_BOUND_RAD, or the median alpha
    outside the vehicle's alpha range, where as degrees they are inside."""
    if vehicle.air_data_source != "vanes":
        return []
    out = []
    for col in dict.fromkeys((vehicle.alpha_column, vehicle.beta_column)):
        if col not in frame.columns:
            continue
        x = _usable(frame[col].to_numpy(float))
        if len(x) < 10:
            continue
        beyond, beyond_deg = (float(np.mean(np.abs(v) > ANGLE_BOUND_RAD)) for v in (x, x * DEG))
        if beyond > 0.5 and beyond_deg <= 0.5:
            out.append(UnitFinding((col,), "rad", "deg", DEG, f"{beyond:.0%} of the values lie beyond "
                                   f"{ANGLE_BOUND_RAD:g} rad (90 deg); as deg {beyond_deg:.0%}", overridable=False))
        elif col == vehicle.alpha_column:
            m, env = float(np.median(x)), vehicle.envelope
            if not _inside(m, env.alpha_rad) and _inside(m * DEG, env.alpha_rad):
                out.append(UnitFinding((col,), "rad", "deg", DEG, f"the median alpha {m:.4g} is outside the "
                                       f"vehicle's {_fmt_range(env.alpha_rad)} rad ([plausibility] alpha_rad); "
                                       f"as deg it is {m * DEG:.3g} rad"))
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


def _measured_air_findings(frame: pd.DataFrame) -> list[UnitFinding]:
    """Measured density, dynamic pressure, static pressure and total temperature against the US-1976
    atmosphere at the record's altitude (MEASURED_AIR_RATIO, TEMPERATURE_RATIO): psf for Pa,
    slug/ft^3 for kg/m^3, hPa, inHg, degR for K ...
    (the schema's range alone passes them: a dynamic pressure of 30 psf is a plausible number of Pa)."""
    from aerosid.vehicles.atmosphere import (CP_AIR_J_KG_K, H_MAX_M, H_MIN_M, density_kg_m3, pressure_pa,
                                             temperature_K)

    out = []
    for col in (c for c in ("rho_kg_m3", "qbar_pa", "p_static_pa", "T_total_K") if c in frame.columns):
        V, h, x = _air_rows(frame, column=col, h_bounds=(H_MIN_M, H_MAX_M))
        if len(x) < 10:
            continue
        bounds = MEASURED_AIR_RATIO
        if col == "T_total_K":
            ref = temperature_K(h) + V ** 2 / (2.0 * CP_AIR_J_KG_K)
            what, units, declared, bounds = "US-1976 total temperature", {"degR": 5.0 / 9.0}, "K", TEMPERATURE_RATIO
        elif col == "p_static_pa":
            ref, what, units, declared = pressure_pa(h), "US-1976 static pressure", PRESSURE_UNITS, "Pa"
        elif col == "rho_kg_m3":
            ref, what, units, declared = density_kg_m3(h), "US-1976 density", DENSITY_UNITS, "kg/m^3"
        else:
            ref, what, units, declared = _qbar_pa(V, h), "0.5 rho V^2 (US-1976 density at h_m)", PRESSURE_UNITS, "Pa"
        ratio = float(np.median(x / ref))
        if _inside(ratio, bounds):
            continue
        fits = sorted((abs(math.log(ratio * k)), unit, k) for unit, k in units.items() if _inside(ratio * k, bounds))
        if fits:
            _, unit, k = fits[0]
            out.append(UnitFinding((col,), declared, unit, k,
                                   f"its median is {ratio:.3g} x the {what}, outside {bounds[0]:.2g}.."
                                   f"{bounds[1]:.3g} x; as {unit} it is {ratio * k:.3g} x", overridable=False))
    impact = _impact_pressure_finding(frame) if not out else None
    return out + ([impact] if impact is not None else [])


#: An impact pressure in qbar_pa is told from the dynamic pressure at this Mach and above (q_c / q-bar
#: 1.09) where the air's state is measured (the density, or the static pressure and total temperature:
#: q-bar then needs no weather), when the measured ratio lies within IMPACT_TOLERANCE of q_c / q-bar
#: and beyond halfway to it.
IMPACT_MACH_MIN = 0.6
IMPACT_TOLERANCE = 0.03


def _impact_pressure_finding(frame: pd.DataFrame) -> UnitFinding | None:
    """qbar_pa holding the impact pressure q_c = p_t - p a pitot-static system measures, not the
    dynamic pressure 0.5 rho V^2: q_c exceeds it by about 1 + M^2/4 (every coefficient x0.85 at
    Mach 0.8), and nothing else in the run sees it.  The dynamic pressure to compare with: 0.5 rho
    V^2 with the measured density, else 0.7 p M^2 with the measured static pressure and total
    temperature; the Mach number from the total temperature, else US-1976's at h_m (q_c / q-bar
    moves by 0.35 per unit Mach at Mach 0.7: a weather's temperature hardly matters).  Both from
    aerosid.vehicles.atmosphere.air_data with the measured columns but qbar_pa, as the run takes them."""
    from aerosid.vehicles.airspeed import _qc_over_p
    from aerosid.vehicles.atmosphere import H_MAX_M, H_MIN_M, air_data

    have = set(frame.columns)
    if "qbar_pa" not in have or not ("rho_kg_m3" in have or {"p_static_pa", "T_total_K"} <= have):
        return None
    measured = [c for c in ("rho_kg_m3", "p_static_pa", "T_total_K") if c in have]
    cols = ["V_m_s", "h_m", "qbar_pa", *measured]
    x = frame[cols].to_numpy(float)
    x = x[np.all(np.isfinite(x) & (x > 0), axis=1) & (x[:, 1] >= H_MIN_M) & (x[:, 1] <= H_MAX_M)]
    if len(x) < 10:
        return None
    col = {c: x[:, i] for i, c in enumerate(cols)}
    try:
        air = air_data(col["V_m_s"], col["h_m"], **{c: col[c] for c in measured})
    except ValueError:  # a total temperature too low for the speed: the run's own check names it
        return None
    mach = air.mach
    ratio = float(np.median(col["qbar_pa"] / air.qbar_pa))
    expected = float(np.median(_qc_over_p(mach) / (0.7 * mach**2)))
    if not (np.median(mach) >= IMPACT_MACH_MIN and abs(ratio / expected - 1.0) < IMPACT_TOLERANCE
            and ratio > 0.5 * (1.0 + expected)):
        return None
    source = "rho_kg_m3" if "rho_kg_m3" in col else "p_static_pa and T_total_K"
    return UnitFinding(("qbar_pa",), "dynamic pressure 0.5 rho V^2", "an impact pressure q_c = p_t - p", 1.0 / ratio,
                       f"its median is {ratio:.3g} x the dynamic pressure that V_m_s and {source} give (median "
                       f"Mach {np.median(mach):.2f}), and an impact pressure is {expected:.3g} x; every coefficient "
                       "would be low by that much", kind="pressure", overridable=False)


#: Temperatures in another unit: (unit, to kelvin, how to convert) -- the raw schema refuses a total
#: temperature in degC or degF (below 150 K); one in degR passes it (MEASURED_AIR_RATIO's check).
TEMPERATURE_UNITS = (("degC", lambda x: x + 273.15, "add 273.15"),
                     ("degF", lambda x: (x - 32.0) * 5.0 / 9.0 + 273.15, "subtract 32, multiply by 5/9, add 273.15"))


def _vane_noise_finding(frame: pd.DataFrame, vehicle) -> UnitFinding | None:
    """The vehicle file's vane noise ([air_data] noise_rad, the errors-in-variables correction's
    sigma of the vane angles) more than the vehicle's [plausibility] vane_noise_factor (default 3)
    from the white noise measured on both vane columns, the same way.  The correction trusts it:
    on c182 a noise of 0.15 (degrees written for radians) ran to "ok" with C_N,alpha +473 %,
    C_l,p +489 %; ten times the true noise +88 %, +50 %."""
    from aerosid.identification.vanes import VANE_NOISE_ORDER, vane_white_noise_rad

    declared = float(vehicle.vane_noise_rad)
    if vehicle.air_data_source != "vanes" or not declared > 0:
        return None
    factor = float(vehicle.envelope.vane_noise_factor)
    cols = [c for c in dict.fromkeys((vehicle.alpha_column, vehicle.beta_column)) if c in frame.columns]
    sig = [vane_white_noise_rad(frame[c].to_numpy(float)) for c in cols]
    sig = [v for v in sig if math.isfinite(v) and v > 0]
    outside = [not (1.0 / factor <= declared / v <= factor) for v in sig]
    if not sig or not all(outside) or len({declared > v for v in sig}) > 1:
        return None  # a setting both vanes contradict the same way (one vane alone: that vane's own matter)
    measured = float(np.sqrt(np.mean(np.square(sig))))
    ratio = declared / measured
    degrees = " (degrees written for radians?)" if 1.0 / 3.0 <= ratio * DEG <= 3.0 else ""
    return UnitFinding(tuple(cols), "[air_data] noise_rad", f"{measured:.2g} rad", measured / declared,
                       f"noise_rad = {declared:.4g} rad is {ratio:.3g} x the white noise measured on "
                       f"{' and '.join(cols)} ({measured:.3g} rad, {VANE_NOISE_ORDER}rd differences){degrees}; "
                       f"the errors-in-variables correction of every coefficient trusts it (more than "
                       f"{factor:g} x either way is refused: [plausibility] vane_noise_factor). Set it to about "
                       f"{measured:.2g} rad, or leave it out to have it measured so (0 takes the angles as exact); "
                       "if the data system low-passes the vanes before recording (their noise then hides from the "
                       "differences), keep the sensor's noise and widen [plausibility] vane_noise_factor",
                       kind="setting", overridable=False)


#: Candidate units by a column's unit suffix, for the raw schema's range check (range_unit_hint).
SUFFIX_UNITS = (("_rad_s", "rad/s", RATE_UNITS), ("_rad", "rad", {"deg": DEG}), ("_m_s2", "m/s^2", ACCEL_UNITS),
                ("_m_s", "m/s", SPEED_UNITS), ("_m", "m", ALTITUDE_UNITS))


def range_unit_hint(column: str, values: np.ndarray) -> str:
    """For a column the raw schema refused as mostly outside its physical range: the unit in
    which most of its values would be inside ("" when none is): a control surface in degrees."""
    from schemas.telemetry import PHYSICAL_BOUNDS, RAW_MAX_OUT_OF_RANGE_FRACTION

    x = _usable(values)
    if column not in PHYSICAL_BOUNDS or x.size == 0:
        return ""
    lo, hi = PHYSICAL_BOUNDS[column]
    if column.endswith("_K"):  # temperatures: an offset, not a factor; degC and degF often both fit
        fits = [f"{unit} ({how})" for unit, to_kelvin, how in TEMPERATURE_UNITS
                if np.mean((to_kelvin(x) < lo) | (to_kelvin(x) > hi)) <= RAW_MAX_OUT_OF_RANGE_FRACTION]
        return (f"; the values look like {' or '.join(fits)}, not K: converted they lie inside {lo:g}..{hi:g} K"
                if fits else "")
    declared, units = next(((d, u) for suffix, d, u in SUFFIX_UNITS if column.endswith(suffix)), (None, {}))
    for unit, k in units.items():
        if np.mean((x * k < lo) | (x * k > hi)) <= RAW_MAX_OUT_OF_RANGE_FRACTION:
            return (f"; the values look like {unit}, not {declared}: as {unit} they lie inside {lo:g}..{hi:g} "
                    f"{declared} (multiply the column by {k:.6g})")
    return ""


# --------------------------------------------------------------------------- entry points
def unit_findings(frame: pd.DataFrame, vehicle) -> list[UnitFinding]:
    """Every unit or sign mistake found in a raw telemetry frame (RawTelemetry columns), most
    basic first: the accelerometers (the kinematic tests use az), rates, air data, vanes,
    then the kinematic tests (aerosid.plausibility.kinematics) of the channels that passed."""
    from aerosid.plausibility.airspeed_scale import airspeed_finding
    from aerosid.plausibility.kinematics import (_altitude_kinematic, _attitude_kinematic, _bank_sign,
                                                 _lateral_fit, _lateral_kinematic, _pitch_rate_kinematic,
                                                 _vane_confirms_q)

    env = vehicle.envelope
    for basic in (_accel_finding(frame, env), _az_sign_finding(frame, env)):
        if basic is not None:
            return [basic]
    found = _rate_findings(frame, env) + _air_data_findings(frame, vehicle) + _vane_findings(frame, vehicle)
    if not {f.columns[0] for f in found} & {"V_m_s", "h_m"}:  # the references are built from V and h
        found += _measured_air_findings(frame)
    flagged = {c for f in found for c in f.columns}
    if not flagged & {"q_rad_s", "V_m_s", vehicle.alpha_column}:
        kin = _pitch_rate_kinematic(frame, vehicle) or airspeed_finding(frame, vehicle)
        if kin is not None:
            found.append(kin)
    if "h_m" not in flagged:
        kin = _altitude_kinematic(frame)
        if kin is not None:
            found.append(kin)
    if not found:  # the attitude and the lateral tests read alpha, V and the gyros as they are
        lateral = _lateral_fit(frame, vehicle)  # one sideslip fit for both
        kin = _attitude_kinematic(frame, _vane_confirms_q(frame, vehicle), _bank_sign(lateral)) or \
            _lateral_kinematic(lateral)
        if kin is not None:
            found.append(kin)
    if not found:  # last: a vane in degrees has a noise 57 x too, and its own test names it
        noise = _vane_noise_finding(frame, vehicle)
        if noise is not None:
            found.append(noise)
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
