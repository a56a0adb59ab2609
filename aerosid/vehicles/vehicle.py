"""Vehicle descriptions: mass properties, reference geometry, sensors, fin mixing,
and the preflight aerodynamic model, read from a TOML file.

Built-in vehicles live in ``aerosid/data/<name>/vehicle.toml``; a path to any
other TOML file with the same layout works too.
"""
from __future__ import annotations

import math
import os
import stat
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from aerosid.plausibility.envelope import Plausibility, plausibility_for
from aerosid.vehicles.rigid_body import InertiaConstants, inertia_constants
from aerosid.vehicles.keys import MAX_DATABASE_BYTES, MAX_VEHICLE_FILE_BYTES, VehicleKeyError, check_document

DATA_DIR = Path(__file__).parents[1] / "data"


class VehicleError(ValueError):
    """A vehicle file is missing a value or holds a non-physical one."""

    def __init__(self, file: str, key: str, message: str):
        self.file, self.key = file, key
        super().__init__(f"{file}: [{key}] {message}")


@dataclass(frozen=True)
class PreflightAero:
    """Preflight aerodynamic coefficients, SI per radian, nose moment reference.

    Pitch/yaw fin derivatives are per radian of delta_p/2 and delta_y/2 (per
    "pair"); Cl_delta_r per radian of delta_r = d1+d2+d3+d4.
    """

    CN_alpha: float
    Cm_alpha_nose: float
    CN_delta_p: float
    Cm_delta_p_nose: float
    CN_0: float
    Cm_0_nose: float
    CY_delta_y: float
    Cn_delta_y_nose: float
    Cl_0: float
    Cl_alpha_r: float
    Cl_cos4phi: float
    Cl_delta_r: float
    CA_0: float
    CA_alpha2: float
    mach_breakpoints: tuple[float, ...]
    slope_factor: tuple[float, ...]

    def slope_multiplier(self, mach):
        """Mach multiplier on the normal-force and pitching-moment slopes [-]."""
        return np.interp(mach, self.mach_breakpoints, self.slope_factor)


@dataclass(frozen=True)
class Vehicle:
    """A flight vehicle. Masses [kg], inertias [kg m^2], lengths [m], areas [m^2]."""

    name: str
    description: str
    mass_kg: float
    Ixx_kg_m2: float
    Iyy_kg_m2: float
    Izz_kg_m2: float
    Ixz_kg_m2: float
    S_m2: float
    d_m: float
    x_cg_m: float
    accel_offset_m: tuple[float, float, float]
    mixing: tuple[tuple[float, ...], ...]
    fin_limit_rad: float
    mach_reference: float
    database_path: Path | None  # None: no force database (alpha/beta from vanes)
    preflight: PreflightAero | None
    estimation: dict = field(default_factory=dict)  # smoother option defaults for this vehicle (EBMOptions names)
    source: str = field(default="<memory>", compare=False)
    #: "finned" (seed-rlv: cruciform fins, one reference length d) or "aircraft"
    #: (elevator/aileron/rudder, chord for pitch, span for roll and yaw)
    vehicle_class: str = "finned"
    chord_m: float | None = None  # pitch reference length (aircraft) [m]
    span_m: float | None = None  # roll/yaw reference length (aircraft) [m]
    #: where alpha and beta come from: "database" (invert the force database, method.md §10)
    #: or "vanes" (air-data vanes, columns below, minus a known calibration bias)
    air_data_source: str = "database"
    alpha_column: str = "alpha_vane_rad"
    beta_column: str = "beta_vane_rad"
    alpha_bias_rad: float = 0.0  # vane calibration bias subtracted from the vane reading [rad]
    beta_bias_rad: float = 0.0
    vane_noise_rad: float = 0.0  # 1-sigma of the vanes' raw noise [rad] (errors-in-variables check); NaN: measured
    #: corner of the zero-phase low-pass applied to the vane angles [Hz] (None: unfiltered)
    vane_cutoff_hz: float | None = None
    #: the vanes' delay behind the inertial sensors [s]: the vane angles are read this much
    #: later (advanced) before anything uses them (aerosid.identification.vanes)
    vane_delay_s: float = 0.0
    #: what V_m_s holds ([air_data] airspeed, aerosid.vehicles.airspeed.AIRSPEED_KINDS): anything but
    #: "true" is converted to the true airspeed before the preprocessing (as_true_airspeed)
    airspeed_kind: str = "true"
    #: the vanes' position from the CG, body axes [m]: their angles are moved to the CG with the
    #: gyros before anything uses them ((0, 0, 0): at the CG, or already corrected)
    vane_position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: half-length of the Savitzky-Golay window of alpha_dot_hat, beta_dot_hat [s]
    derivative_half_window_s: float = 0.25
    surfaces: tuple[str, ...] = ("fin 1", "fin 2", "fin 3", "fin 4")  # what d1..d4 are
    #: the vehicle's default model terms per channel (None: method.md §11 defaults)
    default_terms: dict | None = None
    #: the regression's common low-pass edge [Hz] ([estimation] band_hz; None: from each
    #: segment's gyro spectrum, aerosid.identification.band)
    band_hz: float | None = None
    #: the prior on the pitch-damping split C_m,alpha_dot / (C_m,q + C_m,alpha_dot) of an aircraft
    #: ([estimation] pitch_damping_split): True = the default (aerosid.identification.damping_prior),
    #: False = none, (centre, 1-sigma) = this vehicle's own
    pitch_damping_split: tuple[float, float] | bool = True
    #: the flight was flown in turbulent air ([estimation] turbulent_air): the regression fits by
    #: instrumental variables, the controls as instruments (aerosid.identification.instrumental)
    turbulent_air: bool = False
    #: preprocessing thresholds from the [preprocess] table (PreprocessParams keyword
    #: arguments, per-sensor tables under "sensors"; docs/preprocessing.md)
    preprocess: dict = field(default_factory=dict)
    #: shortest segment the pipeline smooths [s] ([preprocess] min_segment_s; None: default)
    min_segment_s: float | None = None
    #: the flight envelope the unit check compares telemetry with ([plausibility]; class defaults)
    plausibility: Plausibility | None = None

    @property
    def envelope(self) -> Plausibility:
        return self.plausibility or plausibility_for(self.vehicle_class)

    @property
    def length_pitch_m(self) -> float:
        """Reference length of C_m and of q d/(2V) [m]: the chord, else d."""
        return self.chord_m if self.chord_m is not None else self.d_m

    @property
    def length_lateral_m(self) -> float:
        """Reference length of C_l, C_n and of p, r d/(2V) [m]: the span, else d."""
        return self.span_m if self.span_m is not None else self.d_m

    @property
    def inertia(self) -> InertiaConstants:
        return inertia_constants(self.Ixx_kg_m2, self.Iyy_kg_m2, self.Izz_kg_m2, self.Ixz_kg_m2)

    @property
    def xcg_over_d(self) -> float:
        return self.x_cg_m / self.d_m

    def mix(self, d1, d2, d3, d4):
        """Fin deflections [rad] -> (delta_r, delta_p, delta_y) [rad] (seed Table 1)."""
        m = self.mixing
        fins = (d1, d2, d3, d4)
        return tuple(sum(m[i][j] * fins[j] for j in range(4)) for i in range(3))

    def unmix(self, delta_r, delta_p, delta_y):
        """(delta_r, delta_p, delta_y) [rad] -> fin deflections d1..d4 [rad] (minimum-norm)."""
        pinv = np.linalg.pinv(np.asarray(self.mixing))
        cmd = np.array([delta_r, delta_p, delta_y], dtype=float)
        return tuple(pinv @ cmd)

    def summary(self) -> str:
        p = self.preflight
        deg = math.pi / 180.0
        rows = [
            f"vehicle {self.name}: {self.description}",
            f"  mass {self.mass_kg:g} kg; Ixx {self.Ixx_kg_m2:g}, Iyy {self.Iyy_kg_m2:g}, "
            f"Izz {self.Izz_kg_m2:g}, Ixz {self.Ixz_kg_m2:g} kg m^2",
            f"  S {self.S_m2:.4f} m^2, d {self.d_m:g} m, x_cg {self.x_cg_m:g} m (x_cg/d {self.xcg_over_d:.3f})",
            f"  accelerometer offset from CG {self.accel_offset_m} m",
        ]
        if p is None:
            rows[2] = (f"  S {self.S_m2:.4f} m^2, chord {self.length_pitch_m:g} m, span {self.length_lateral_m:g} m")
            rows.append(f"  controls d1..d4 = {', '.join(self.surfaces)}; alpha/beta from {self.air_data_source}")
            return "\n".join(rows)
        rows += [
            f"  preflight at M {self.mach_reference}: CN_alpha {p.CN_alpha * deg:.4f}/deg, "
            f"Cm_alpha(nose) {p.Cm_alpha_nose * deg:.4f}/deg, CN_delta_p {p.CN_delta_p * deg:.5f}/deg pair, "
            f"Cm_delta_p(nose) {p.Cm_delta_p_nose * deg:.5f}/deg pair",
        ]
        return "\n".join(rows)


_REQUIRED = {
    "mass": ["mass_kg", "Ixx_kg_m2", "Iyy_kg_m2", "Izz_kg_m2", "Ixz_kg_m2"],
    "reference": ["S_m2", "x_cg_m"],
    "sensors": ["accel_offset_m"],
    "controls": ["mixing"],
    "aero": ["mach_reference"],
}
CLASSES = ("finned", "aircraft")
AIR_DATA_SOURCES = ("database", "vanes")
#: Folders besides the vehicle file's own where its aerodynamic database may live
#: (resolved): the built-in vehicles' data.
DATABASE_ALLOWED_DIRS: tuple[Path, ...] = (DATA_DIR,)


def builtin_vehicles() -> list[str]:
    return sorted(p.parent.name for p in DATA_DIR.glob("*/vehicle.toml"))


def resolve_vehicle_path(name_or_path: str | Path) -> Path:
    """A built-in vehicle name (``seed-rlv``) or a path to a vehicle TOML file."""
    candidate = DATA_DIR / str(name_or_path) / "vehicle.toml"
    if candidate.is_file():
        return candidate
    path = Path(name_or_path)
    if path.is_file():
        return path
    raise VehicleError(str(name_or_path), "-", f"no such vehicle file or built-in vehicle "
                       f"(built-in: {', '.join(builtin_vehicles())})")


#: A moment of inertia may exceed the sum of the other two by this fraction of that sum and the
#: file is still read.  An aircraft is nearly flat (Izz = Ixx + Iyy exactly for a plate), so
#: estimated mass properties can cross the bound by their own error: JSBSim's A4 by 0.16 %,
#: c310 0.4 %, global5000 0.9 %.  Beyond it (L410 4.7 %, MD11 7.8 %, Concorde 36 %) the file is refused.
INERTIA_TRIANGLE_TOLERANCE = 0.02


def inertia_triangle_excess(Ixx: float, Iyy: float, Izz: float) -> tuple[str, float]:
    """The moment [kg m^2] that exceeds the sum of the other two the most, and by how much as a
    fraction of that sum (<= 0: the triangle inequality of a rigid body's moments holds).  It
    holds for the diagonal of the inertia tensor in any axes, Ixz or not."""
    rows = (("Ixx", Ixx, Iyy + Izz), ("Iyy", Iyy, Ixx + Izz), ("Izz", Izz, Ixx + Iyy))
    name, value, others = max(rows, key=lambda r: r[1] / r[2])
    return name, value / others - 1.0


def load_vehicle(name_or_path: str | Path = "seed-rlv") -> Vehicle:
    """Read and check a vehicle description; raises VehicleError naming file and key."""
    path = resolve_vehicle_path(name_or_path)
    src = str(path)
    doc = read_toml_file(path, MAX_VEHICLE_FILE_BYTES, lambda msg: VehicleError(src, "-", msg))
    try:
        check_document(doc)
    except VehicleKeyError as exc:
        raise VehicleError(src, exc.key, str(exc)) from None
    for section, keys in _REQUIRED.items():
        if section not in doc:
            raise VehicleError(src, section, "section missing")
        for key in keys:
            if key not in doc[section]:
                raise VehicleError(src, f"{section}.{key}", "value missing")
    m, ref = doc["mass"], doc["reference"]

    def positive(section, key):
        value = doc[section][key]
        if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise VehicleError(src, f"{section}.{key}", f"must be a positive number, got {value!r}")
        return float(value)

    mass = positive("mass", "mass_kg")
    Ixx, Iyy, Izz = (positive("mass", k) for k in ("Ixx_kg_m2", "Iyy_kg_m2", "Izz_kg_m2"))
    Ixz = float(m["Ixz_kg_m2"])
    if Ixx * Izz - Ixz**2 <= 0:
        raise VehicleError(src, "mass.Ixz_kg_m2",
                           f"Gamma = Ixx*Izz - Ixz^2 = {Ixx * Izz - Ixz**2:g} <= 0: not a physical inertia")
    axis, excess = inertia_triangle_excess(Ixx, Iyy, Izz)
    if excess > INERTIA_TRIANGLE_TOLERANCE:
        raise VehicleError(src, "mass", f"inertias Ixx={Ixx}, Iyy={Iyy}, Izz={Izz} violate the triangle inequality: "
                           f"{axis} exceeds the sum of the other two by {100 * excess:.1f} % (no rigid body has "
                           f"them; up to {100 * INERTIA_TRIANGLE_TOLERANCE:g} % is taken as an estimate's error)")
    vclass = str(doc.get("class", "finned"))
    if vclass not in CLASSES:
        raise VehicleError(src, "class", f"unknown vehicle class {vclass!r}; known: {', '.join(CLASSES)}")
    S = positive("reference", "S_m2")
    chord = positive("reference", "chord_m") if "chord_m" in ref else None
    span = positive("reference", "span_m") if "span_m" in ref else None
    if "d_m" in ref:
        d = positive("reference", "d_m")
    elif chord is not None and span is not None:
        d = chord
    else:
        raise VehicleError(src, "reference.d_m", "value missing (or give both chord_m and span_m)")
    offset = doc["sensors"]["accel_offset_m"]
    if len(offset) != 3:
        raise VehicleError(src, "sensors.accel_offset_m", "needs three numbers (x, y, z) [m]")
    mixing = doc["controls"]["mixing"]
    if len(mixing) != 3 or any(len(row) != 4 for row in mixing):
        raise VehicleError(src, "controls.mixing", "needs 3 rows (roll, pitch, yaw) of 4 fin weights")
    for i, name in enumerate(("delta_r (roll)", "delta_p (pitch)", "delta_y (yaw)")):
        if not any(mixing[i]):
            raise VehicleError(src, "controls.mixing", f"row {i + 1}, {name}, is all zero: that control would "
                               "always read 0 and its coefficients could not be identified")
    if np.linalg.matrix_rank(np.asarray(mixing, dtype=float)) < 3:
        raise VehicleError(src, "controls.mixing", f"rows {mixing} are linearly dependent: delta_r, delta_p and "
                           "delta_y must be independent combinations of d1..d4")
    air = doc.get("air_data", {})
    source = str(air.get("source", "database"))
    if source not in AIR_DATA_SOURCES:
        raise VehicleError(src, "air_data.source", f"must be one of {', '.join(AIR_DATA_SOURCES)}, got {source!r}")
    if source == "database" and "database" not in doc["aero"]:
        raise VehicleError(src, "aero.database", "value missing (needed to invert alpha and beta; or set "
                           "[air_data] source = \"vanes\")")
    database_path = _database_path(path, doc["aero"]["database"]) if "database" in doc["aero"] else None
    pre = doc["aero"].get("preflight")
    preflight = None
    if pre is not None or source == "database":
        pre = pre or {}
        names = [f.name for f in PreflightAero.__dataclass_fields__.values()]
        missing = [n for n in names if n not in pre]
        if missing:
            raise VehicleError(src, "aero.preflight", f"missing {', '.join(missing)}")
        preflight = PreflightAero(**{n: (tuple(pre[n]) if isinstance(pre[n], list) else float(pre[n]))
                                     for n in names})
        bp, sf = preflight.mach_breakpoints, preflight.slope_factor
        if not isinstance(bp, tuple) or not isinstance(sf, tuple) or len(bp) != len(sf):
            raise VehicleError(src, "aero.preflight", "mach_breakpoints and slope_factor need one number each "
                               "per breakpoint (two lists of the same length)")
        if any(b <= a for a, b in zip(bp, bp[1:])):
            raise VehicleError(src, "aero.preflight.mach_breakpoints", f"must increase strictly, got {list(bp)}")
    limit_key = "fin_limit_rad" if "fin_limit_rad" in doc["controls"] else "surface_limit_rad"
    # the built-in (finned) simulator's fin limit; an aircraft's identification never reads it, so a
    # file written by hand need not state it (the experiment design has its own default, design/limits)
    unstated_limit = limit_key not in doc["controls"]
    if unstated_limit and vclass != "aircraft":
        raise VehicleError(src, "controls.fin_limit_rad", "value missing (or surface_limit_rad)")
    surfaces = doc["controls"].get("surfaces", ["fin 1", "fin 2", "fin 3", "fin 4"])
    if len(surfaces) != 4:
        raise VehicleError(src, "controls.surfaces", "needs 4 names, one per column d1..d4")
    terms = doc.get("models")
    if terms is not None:
        from aerosid.modelling.models import CHANNELS as MODEL_CHANNELS

        bad = [k for k in terms if k not in MODEL_CHANNELS or not isinstance(terms[k], list)]
        if bad:
            raise VehicleError(src, "models", f"channels {bad}: each entry must be a channel "
                               f"({', '.join(MODEL_CHANNELS)}) with a list of terms")
        from aerosid.modelling.models import ModelSpecError, parse_terms

        for ch, items in terms.items():
            try:
                parse_terms([str(item) for item in items], ch, src)
            except ModelSpecError as exc:
                raise VehicleError(src, f"models.{ch}", str(exc)) from None
    preprocess, min_segment_s = _preprocess_settings(doc.get("preprocess", {}), src)
    return Vehicle(
        name=str(doc.get("name", path.parent.name)),
        description=str(doc.get("description", "")),
        mass_kg=mass,
        Ixx_kg_m2=Ixx,
        Iyy_kg_m2=Iyy,
        Izz_kg_m2=Izz,
        Ixz_kg_m2=Ixz,
        S_m2=S,
        d_m=d,
        x_cg_m=float(ref["x_cg_m"]),
        accel_offset_m=tuple(float(v) for v in offset),
        mixing=tuple(tuple(float(v) for v in row) for row in mixing),
        fin_limit_rad=math.pi / 2 if unstated_limit else positive("controls", limit_key),
        mach_reference=float(doc["aero"]["mach_reference"]),
        database_path=database_path,
        preflight=preflight,
        estimation={k: (tuple(v) if isinstance(v, list) else v) for k, v in doc.get("estimation", {}).items()
                    if k not in ("band_hz", "pitch_damping_split", "turbulent_air")},
        band_hz=positive("estimation", "band_hz") if "band_hz" in doc.get("estimation", {}) else None,
        pitch_damping_split=_damping_split(doc.get("estimation", {}), src),
        turbulent_air=bool(doc.get("estimation", {}).get("turbulent_air", False)),
        source=src,
        vehicle_class=vclass,
        chord_m=chord,
        span_m=span,
        air_data_source=source,
        alpha_column=str(air.get("alpha_column", "alpha_vane_rad")),
        beta_column=str(air.get("beta_column", "beta_vane_rad")),
        alpha_bias_rad=float(air.get("alpha_bias_rad", 0.0)),
        beta_bias_rad=float(air.get("beta_bias_rad", 0.0)),
        # not stated for vanes: NaN, measured from the vanes' own white noise (flight data)
        vane_noise_rad=float(air.get("noise_rad", math.nan if source == "vanes" else 0.0)),
        vane_cutoff_hz=float(air["cutoff_hz"]) if "cutoff_hz" in air else None,
        vane_delay_s=float(air.get("delay_s", 0.0)),
        airspeed_kind=str(air.get("airspeed", "true")),
        vane_position_m=tuple(float(v) for v in air.get("vane_position_m", (0.0, 0.0, 0.0))),
        derivative_half_window_s=float(air.get("derivative_half_window_s", 0.25)),
        surfaces=tuple(str(x) for x in surfaces),
        default_terms={k: list(v) for k, v in terms.items()} if terms is not None else None,
        preprocess=preprocess,
        min_segment_s=min_segment_s,
        plausibility=plausibility_for(vclass, doc.get("plausibility")),
    )


def _damping_split(estimation: dict, src: str) -> tuple[float, float] | bool:
    """[estimation] pitch_damping_split: true/absent (the default prior), false (none) or
    [centre, sigma] (the share of the pitch damping in C_m,alpha_dot and its 1-sigma; the key
    table has checked the form)."""
    value = estimation.get("pitch_damping_split", True)
    if isinstance(value, bool):
        return value
    if not value[1] > 0:
        raise VehicleError(src, "estimation.pitch_damping_split", f"its sigma must be positive, got {value[1]!r}")
    return (float(value[0]), float(value[1]))


def _preprocess_settings(table, src: str) -> tuple[dict, float | None]:
    """The [preprocess] table checked (aerosid.preprocess.parse_settings); errors name
    the file and the key."""
    from aerosid.preprocess.params import SettingsError, parse_settings

    if not isinstance(table, dict):
        raise VehicleError(src, "preprocess", "must be a table of settings")
    try:
        return parse_settings(table)
    except SettingsError as exc:
        raise VehicleError(src, f"preprocess.{exc.key}", exc.reason) from None
    except ValueError as exc:
        raise VehicleError(src, "preprocess", str(exc)) from None


def read_toml_file(path: Path, max_bytes: int, error) -> dict:
    """Parse a TOML file that must be a regular file of at most max_bytes; every failure
    (not a regular file, too large, not UTF-8, not TOML, nested too deep) is raised as
    error(message)."""
    try:
        st = os.stat(path)
    except OSError as exc:
        raise error(f"cannot read: {exc.strerror or exc}") from None
    if not stat.S_ISREG(st.st_mode):
        raise error("not a regular file")
    if st.st_size > max_bytes:
        raise error(f"{st.st_size} bytes: larger than the {max_bytes} bytes a TOML file may have here")
    try:
        with open(path, "rb") as fh:
            text = fh.read(max_bytes + 1).decode("utf-8")
        return tomllib.loads(text)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise error(f"not valid TOML: {exc}") from None
    except RecursionError:
        raise error("not valid TOML here: nested deeper than this reader follows (arrays or tables inside "
                    "each other hundreds of levels deep)") from None
    except OSError as exc:
        raise error(f"cannot read: {exc.strerror or exc}") from None


def _database_path(vehicle_path: Path, name: str) -> Path:
    """The aerodynamic database named in the vehicle file: a regular file of bounded size,
    inside the vehicle file's folder (a relative name without '..') or, resolved, inside
    one of DATABASE_ALLOWED_DIRS."""
    src = str(vehicle_path)
    rel = Path(name)
    candidate = vehicle_path.parent / rel
    inside = not rel.is_absolute() and ".." not in rel.parts
    if not inside:
        try:
            real = candidate.resolve()
        except (OSError, RuntimeError):
            real = None
        inside = real is not None and any(real.is_relative_to(d.resolve()) for d in DATABASE_ALLOWED_DIRS)
    if not inside:
        raise VehicleError(src, "aero.database", f"{name!r} is outside the vehicle file's folder "
                           f"{vehicle_path.parent}: put the database beside the vehicle file and name it "
                           "relative to it")
    try:
        st = os.stat(candidate)
    except OSError as exc:
        raise VehicleError(src, "aero.database", f"{name!r}: {exc.strerror or exc}") from None
    if not stat.S_ISREG(st.st_mode):
        raise VehicleError(src, "aero.database", f"{name!r} is not a regular file")
    if st.st_size > MAX_DATABASE_BYTES:
        raise VehicleError(src, "aero.database", f"{name!r} has {st.st_size} bytes, more than the "
                           f"{MAX_DATABASE_BYTES} an aerodynamic database may have")
    return candidate
