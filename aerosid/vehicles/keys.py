"""The keys a vehicle file may hold, as one declarative table, and the check of a parsed
file against it: unknown keys are refused with the valid ones listed, every number must
be finite and inside its range, every vector and matrix of the right shape.

To add a key, add one line to :data:`TABLES` (a table may be given a whole new entry,
e.g. ``TABLES["preprocess"] = {...}``); :func:`check_document` and the error messages
follow.  ``load_vehicle`` (aerosid/vehicles/vehicle.py) runs the check before it reads any value,
so its own checks (required keys, Gamma > 0, ...) see only well-formed numbers.

The ranges are wide, physical sanity bounds (a 1e300 m accelerometer offset, a NaN CG,
an infinite reference Mach are refused), not a vehicle's design limits; those are the
``[plausibility]`` table's (aerosid/plausibility).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from aerosid.vehicles.airspeed import AIRSPEED_KINDS

#: Largest aerodynamic database file read [bytes] (seed-rlv's is ~0.2 MB).
MAX_DATABASE_BYTES = 50_000_000
#: Largest vehicle file read [bytes].
MAX_VEHICLE_FILE_BYTES = 1_000_000

ANGLE_MAX_RAD = math.pi


@dataclass(frozen=True)
class Key:
    """One key: its kind and its closed range [lo, hi] (for vectors: of every element).

    kind: "number", "int", "bool", "string", "choice", "vector" (``length`` numbers, or
    any length >= 1 when None), "matrix" (``shape`` rows x columns), "range" (two
    numbers lo < hi), "strings" (a list of ``length`` strings), "terms" (a list of model
    terms, checked by aerosid.modelling.models), "path" (a file name, checked by load_vehicle),
    "switch" (true, false, or a vector as above: a setting that is on by default, off, or given).
    """

    kind: str
    lo: float = -math.inf
    hi: float = math.inf
    length: int | None = None
    shape: tuple[int, int] | None = None
    choices: tuple[str, ...] = ()
    positive: bool = False  # lo is exclusive (> lo rather than >= lo)
    doc: str = ""

    def range_text(self) -> str:
        return f"{'(' if self.positive else '['}{self.lo:g}, {self.hi:g}]"

    def describe(self) -> str:
        if self.kind == "choice":
            return f"one of {', '.join(map(repr, self.choices))}"
        if self.kind == "switch":
            return "true, false or " + Key("vector", self.lo, self.hi, self.length, positive=self.positive).describe()
        rng = f" in {self.range_text()}" if self.kind in ("number", "int", "vector", "matrix", "range") else ""
        shape = {"vector": f"{self.length} numbers" if self.length else "a list of numbers",
                 "matrix": f"{self.shape[0]} rows of {self.shape[1]} numbers" if self.shape else "",
                 "range": "two numbers [low, high]", "strings": f"{self.length or 'a list of'} strings",
                 "number": "a number", "int": "an integer", "bool": "true or false", "string": "a string",
                 "terms": "a list of model terms", "path": "a file name"}.get(self.kind, self.kind)
        return shape + (" each" if self.kind in ("vector", "matrix") and rng else "") + rng


def num(lo=-math.inf, hi=math.inf, doc="", positive=False) -> Key:
    return Key("number", lo, hi, positive=positive, doc=doc)


def pos(hi=math.inf, doc="") -> Key:
    return Key("number", 0.0, hi, positive=True, doc=doc)


def vec(length, lo=-math.inf, hi=math.inf, positive=False, doc="") -> Key:
    return Key("vector", lo, hi, length=length, positive=positive, doc=doc)


def rng(lo, hi, doc="") -> Key:
    return Key("range", lo, hi, doc=doc)


LENGTH_M = 1e4  # lengths and positions of any flight vehicle [m]

#: Top-level keys (not tables).
TOP = {
    "name": Key("string", doc="vehicle name"),
    "description": Key("string"),
    "class": Key("choice", choices=("finned", "aircraft")),
}

#: table -> key -> Key.  A sub-table (``[aero.preflight]``) is its own entry "aero.preflight".
TABLES: dict[str, dict[str, Key] | None] = {
    "mass": {
        "mass_kg": pos(1e7), "Ixx_kg_m2": pos(1e12), "Iyy_kg_m2": pos(1e12), "Izz_kg_m2": pos(1e12),
        "Ixz_kg_m2": num(-1e12, 1e12),
    },
    "reference": {
        "S_m2": pos(1e5), "d_m": pos(LENGTH_M), "chord_m": pos(LENGTH_M), "span_m": pos(LENGTH_M),
        "x_cg_m": num(-LENGTH_M, LENGTH_M),
        # for reference only (not read by the pipeline): the importers and c172x write them
        "y_cg_m": num(-LENGTH_M, LENGTH_M), "z_cg_m": num(-LENGTH_M, LENGTH_M),
        "x_aerorp_m": num(-LENGTH_M, LENGTH_M), "z_aerorp_m": num(-LENGTH_M, LENGTH_M),
    },
    "sensors": {
        "accel_offset_m": vec(3, -100.0, 100.0, doc="accelerometer position from the CG, body axes [m]"),
    },
    "controls": {
        "layout": Key("string"),
        "mixing": Key("matrix", -100.0, 100.0, shape=(3, 4), doc="rows delta_r, delta_p, delta_y; columns d1..d4"),
        "fin_limit_rad": pos(ANGLE_MAX_RAD), "surface_limit_rad": pos(ANGLE_MAX_RAD),
        "surface_limits_rad": Key("matrix", -ANGLE_MAX_RAD, ANGLE_MAX_RAD, shape=(4, 2)),
        "surfaces": Key("strings", length=4),
    },
    "air_data": {
        "source": Key("choice", choices=("database", "vanes")),
        "alpha_column": Key("string"), "beta_column": Key("string"),
        "alpha_bias_rad": num(-0.5, 0.5), "beta_bias_rad": num(-0.5, 0.5), "noise_rad": num(0.0, 0.5),
        "cutoff_hz": pos(1e4), "derivative_half_window_s": pos(60.0),
        "delay_s": num(-0.5, 0.5, doc="the vanes' delay behind the IMU [s]: the vane angles are advanced by it"),
        "vane_position_m": vec(3, -100.0, 100.0, doc="the vanes' position from the CG, body axes [m]"),
        "airspeed": Key("choice", choices=AIRSPEED_KINDS,
                        doc="what the telemetry's V_m_s holds; not true: converted at preprocessing"),
    },
    "aero": {
        "database": Key("path", doc="the aerodynamic database, a file in the vehicle's folder"),
        "mach_reference": pos(50.0),
    },
    "aero.preflight": {
        **{k: num(-1e3, 1e3) for k in (
            "CN_alpha", "Cm_alpha_nose", "CN_delta_p", "Cm_delta_p_nose", "CN_0", "Cm_0_nose", "CY_delta_y",
            "Cn_delta_y_nose", "Cl_0", "Cl_alpha_r", "Cl_cos4phi", "Cl_delta_r", "CA_0", "CA_alpha2")},
        "mach_breakpoints": vec(None, 0.0, 50.0, positive=True), "slope_factor": vec(None, 0.0, 100.0, positive=True),
    },
    # Smoother defaults: aerosid.estimation.EBMOptions fields (tests/vehicles/test_vehicle_keys.py keeps
    # the two lists equal), plus band_hz (the regression's low-pass edge), pitch_damping_split
    # (the prior on an aircraft's C_m,alpha_dot share, aerosid.identification.damping_prior) and
    # turbulent_air (aerosid.identification.instrumental), read by load_vehicle.
    "estimation": {
        "f_max_hz": pos(1e4), "gate_probability": Key("number", 0.0, 1.0, positive=True),
        "auto_tune": Key("bool"), "tune_r": Key("bool"), "max_tuning_iterations": Key("int", 0, 1000),
        "nis_tolerance": pos(1e3), "use_numba": Key("bool"), "segment_length": Key("int", 1, 1_000_000),
        "spectrum_kappa": pos(1e6), "divergence_window_s": pos(1e4),
        "divergence_probability": Key("number", 0.0, 1.0, positive=True), "divergence_min_s": pos(1e4),
        "divergence_max_fraction": Key("number", 0.0, 1.0, positive=True),
        "q_scale_bounds": vec(2, 0.0, 1e9, positive=True), "q_chain_scale": vec(6, 0.0, 1e9, positive=True),
        "q_scale": pos(1e9), "r_scale": pos(1e9), "band_hz": pos(1e4),
        "gyro_gate_hold_s": pos(1e4, "the longest run of samples the innovation gate may hold a gyro out [s]"),
        "pitch_damping_split": Key("switch", -10.0, 10.0, length=2,
                                   doc="[centre, 1-sigma] of C_m,alpha_dot / (C_m,q + C_m,alpha_dot); false: no prior"),
        "turbulent_air": Key("bool", doc="the flight was flown in turbulent air: instrumental-variable fit, the "
                                         "controls as instruments (aerosid.identification.instrumental)"),
    },
    "models": {ch: Key("terms") for ch in ("CN", "Cm", "CY", "Cn", "Cl")},
    # aerosid/plausibility: the flight envelope the unit check compares the telemetry with
    "plausibility": {
        "rate_rad_s": pos(100.0, "largest plausible |p|, |q|, |r| (99th percentile) [rad/s]"),
        "specific_force_m_s2": rng(0.0, 10_000.0, "median |(ax, ay, az)| [m/s^2]"),
        "V_m_s": rng(0.0, 20_000.0, "median airspeed [m/s]"),
        "h_m": rng(-1000.0, 1e6, "median altitude [m]"),
        "qbar_pa": rng(0.0, 1e8, "median dynamic pressure from V and h (US-1976) [Pa]"),
        "alpha_rad": rng(-ANGLE_MAX_RAD, ANGLE_MAX_RAD, "angle of attack the flight stays within [rad]"),
        "az_m_s2": rng(-10_000.0, 10_000.0, "median normal specific force az, body z down [m/s^2]"),
        "cn_alpha_per_rad": rng(-1e9, 1e9, "range of the estimated normal-force slope C_N,alpha [1/rad]"),
        "cl_p_per_rad": rng(-1e9, 1e9, "range of the estimated roll damping C_l,p [1/rad]"),
        "vane_noise_factor": Key("number", 1.0, 1e9, positive=True,
                                 doc="[air_data] noise_rad may differ from the vanes' measured white noise by "
                                     "this factor"),
        "preflight_factor": Key("number", 1.0, 1e6, positive=True,
                                doc="warn when an estimate differs from its preflight value by more than this factor"),
        "chord_ratio": rng(0.0, 1e6, "range of chord_m / (S_m2 / span_m), the chord over the mean chord the "
                           "wing area and span give [-]"),
        "airspeed_scale_min": Key("number", 0.0, 1.0, doc="refuse V_m_s as a calibrated airspeed when the pitch "
                                  "kinematics put it below this share of the true airspeed [-]"),
    },
    # the vehicle's flight-test limits, read by the experiment design (aerosid/design/limits.py)
    "limits": {
        "surface_rate_limit_rad_s": pos(1e3, "largest surface (fin) rate [rad/s]"),
        "alpha_rad": rng(-ANGLE_MAX_RAD, ANGLE_MAX_RAD, "angle of attack a manoeuvre may reach [rad]"),
        "load_factor": rng(-100.0, 100.0, "normal load factor n = -az/g a manoeuvre may reach [-]"),
        "duration_max_s": pos(1e5, "longest manoeuvre on condition [s]"),
        "surface_margin": Key("number", 0.0, 0.9, doc="share of each surface limit kept in reserve [-]"),
    },
    # per-sensor preprocessing thresholds: owned by aerosid/preprocess, which checks its keys
    # (None: any key accepted here; replace with its key table when it has one)
    "preprocess": None,
}


class VehicleKeyError(ValueError):
    """A key that is unknown or holds a value outside its kind or range: (table.key, message)."""

    def __init__(self, key: str, message: str):
        self.key = key
        super().__init__(message)


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _check_number(where: str, x, spec: Key) -> None:
    if not _is_number(x):
        raise VehicleKeyError(where, f"must be a number, got {x!r}")
    if spec.kind == "int" and not isinstance(x, int):
        raise VehicleKeyError(where, f"must be an integer, got {x!r}")
    if not math.isfinite(x):
        raise VehicleKeyError(where, f"must be a finite number, got {x!r}")
    if spec.positive and spec.lo == 0.0 and x <= 0:
        raise VehicleKeyError(where, f"must be a positive number, got {x!r}")
    low_ok = x > spec.lo if spec.positive else x >= spec.lo
    if not (low_ok and x <= spec.hi):
        raise VehicleKeyError(where, f"{x!r} is outside the range {spec.range_text()}")


def check_value(where: str, value, spec: Key) -> None:
    """Raise VehicleKeyError if value does not fit spec."""
    kind = spec.kind
    if kind in ("number", "int"):
        _check_number(where, value, spec)
    elif kind == "bool":
        if not isinstance(value, bool):
            raise VehicleKeyError(where, f"must be true or false, got {value!r}")
    elif kind in ("string", "path"):
        if not isinstance(value, str) or not value.strip() or len(value) > 1000:
            raise VehicleKeyError(where, f"must be a non-empty string (at most 1000 characters), got {str(value)[:60]!r}")
    elif kind == "choice":
        if value not in spec.choices:
            raise VehicleKeyError(where, f"must be {spec.describe()}, got {value!r}")
    elif kind == "switch":
        if not isinstance(value, bool):
            if not isinstance(value, list) or (spec.length is not None and len(value) != spec.length):
                raise VehicleKeyError(where, f"must be {spec.describe()}, got {str(value)[:80]}")
            check_value(where, value, Key("vector", spec.lo, spec.hi, spec.length, positive=spec.positive))
    elif kind in ("vector", "range"):
        n = 2 if kind == "range" else spec.length
        if not isinstance(value, list) or (n is not None and len(value) != n) or not value:
            raise VehicleKeyError(where, f"needs {spec.describe()}, got {str(value)[:80]}")
        for i, x in enumerate(value):
            _check_number(f"{where}[{i}]", x, spec)
        if kind == "range" and not value[0] < value[1]:
            raise VehicleKeyError(where, f"needs low < high, got {value!r}")
    elif kind == "matrix":
        rows, cols = spec.shape
        if (not isinstance(value, list) or len(value) != rows
                or any(not isinstance(r, list) or len(r) != cols for r in value)):
            raise VehicleKeyError(where, f"needs {spec.describe()}")
        for i, row in enumerate(value):
            for j, x in enumerate(row):
                _check_number(f"{where}[{i}][{j}]", x, spec)
    elif kind == "strings":
        if (not isinstance(value, list) or (spec.length is not None and len(value) != spec.length)
                or not all(isinstance(s, str) for s in value)):
            raise VehicleKeyError(where, f"needs {spec.describe()}")
    elif kind == "terms":
        if not isinstance(value, list) or not all(isinstance(s, str) for s in value):
            raise VehicleKeyError(where, "needs a list of terms (strings)")
    else:  # pragma: no cover - a table entry with a kind this function does not know
        raise AssertionError(f"unknown key kind {kind!r}")


def _unknown(table: str, key: str, valid) -> VehicleKeyError:
    where = f"{table}.{key}" if table else key
    inside = f" in [{table}]" if table else " at the top level"
    return VehicleKeyError(where, f"unknown key {key!r}{inside}; valid: {', '.join(valid)}")


def check_document(doc: dict) -> None:
    """Check a parsed vehicle file against TOP and TABLES; raises VehicleKeyError naming the key."""
    for key, value in doc.items():
        if key in TOP:
            check_value(key, value, TOP[key])
        elif key in TABLES:
            if not isinstance(value, dict):
                raise VehicleKeyError(key, "must be a table ([" + key + "])")
            _check_table(key, value)
        else:
            raise _unknown("", key, [*TOP, *(f"[{t}]" for t in TABLES if "." not in t)])


def _check_table(name: str, table: dict) -> None:
    keys = TABLES[name]
    if keys is None:  # a table whose owner checks its keys
        return
    subtables = {t.split(".", 1)[1] for t in TABLES if t.startswith(name + ".")}
    for key, value in table.items():
        if key in subtables:
            if not isinstance(value, dict):
                raise VehicleKeyError(f"{name}.{key}", f"must be a table ([{name}.{key}])")
            _check_table(f"{name}.{key}", value)
        elif key in keys:
            check_value(f"{name}.{key}", value, keys[key])
        else:
            raise _unknown(name, key, [*keys, *(f"[{name}.{s}]" for s in sorted(subtables))])
