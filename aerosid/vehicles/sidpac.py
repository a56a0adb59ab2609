"""Import a SIDPAC flight-data file (NASA's System IDentification Programs for AirCraft).

SIDPAC keeps a manoeuvre in a MATLAB file: ``fdata`` (one row per sample, 90
columns in SIDPAC's standard layout, unused columns all zero), optionally
``fdatao`` (the same before SIDPAC's data-compatibility corrections), the scalars
``sarea``, ``bspan``, ``cbar`` and a struct ``fds`` whose ``varunits`` labels each
column's unit.  The units used are the file's own labels where it has them (read
through pint), SIDPAC's standard English units otherwise (:data:`COLUMNS`).

What goes where (see docs/real-flight.md):

* telemetry: time from 0 (the file's clock is kept as ``aerosid.time_origin_s``),
  V, p, q, r, h, elevator/aileron/rudder as d1..d4, alpha and beta (SIDPAC's
  corrected angles) as the vane columns, and density, dynamic pressure, roll and
  pitch attitude when the file has them;
* accelerations at the sensor (columns 53-55) when the file fixes the sensor's
  position (aerosid's filter models the lever arm from ``[sensors] accel_offset_m``),
  less the bias SIDPAC's compatibility check removed; else the CG ones (11-13);
* the vehicle file: mass, inertia, CG, S, chord, span from the file, the
  accelerometer offset recovered by aerosid.vehicles.accel, vanes as the air-data
  source, the Mach reference of the manoeuvre.
"""
from __future__ import annotations

import re
from dataclasses import replace
from math import comb
from pathlib import Path

import numpy as np
import pandas as pd

from aerosid.vehicles.accel import recover_accel_offset
from aerosid.vehicles.importers import ImportDataError, ImportedFlight, check_time
from aerosid.vehicles.units import UnitError, conversion, to_si
from aerosid.vehicles.vehicle_toml import AircraftVehicle

#: SIDPAC's fdata columns aerosid reads: name -> (1-based column, standard unit, signal).
COLUMNS: dict[str, tuple[int, str, str]] = {
    "time": (1, "s", "time"), "V": (2, "ft/s", "true airspeed"), "beta": (3, "deg", "sideslip"),
    "alpha": (4, "deg", "angle of attack"), "p": (5, "deg/s", "roll rate"), "q": (6, "deg/s", "pitch rate"),
    "r": (7, "deg/s", "yaw rate"), "phi": (8, "deg", "roll angle"), "theta": (9, "deg", "pitch angle"),
    "ax_cg": (11, "g", "ax at the CG"), "ay_cg": (12, "g", "ay at the CG"), "az_cg": (13, "g", "az at the CG"),
    "elevator": (14, "deg", "elevator"), "aileron": (15, "deg", "aileron"), "rudder": (16, "deg", "rudder"),
    "qbar": (27, "lbf/ft^2", "dynamic pressure"), "mach": (28, "", "Mach number"),
    "rho": (29, "slug/ft^3", "air density"), "alt": (30, "ft", "altitude"),
    "p_dot": (42, "deg/s^2", "roll acceleration"), "q_dot": (43, "deg/s^2", "pitch acceleration"),
    "r_dot": (44, "deg/s^2", "yaw acceleration"),
    "x_cg": (45, "in", "x CG position"), "y_cg": (46, "in", "y CG position"), "z_cg": (47, "in", "z CG position"),
    "mass": (48, "slug", "mass"), "Ixx": (49, "slug*ft^2", "Ixx"), "Iyy": (50, "slug*ft^2", "Iyy"),
    "Izz": (51, "slug*ft^2", "Izz"), "Ixz": (52, "slug*ft^2", "Ixz"),
    "ax_meas": (53, "g", "ax as measured"), "ay_meas": (54, "g", "ay as measured"),
    "az_meas": (55, "g", "az as measured"),
    "S": (77, "ft^2", "wing area"), "b": (78, "ft", "wing span"), "cbar": (79, "ft", "mean aerodynamic chord"),
}
REQUIRED = ("time", "V", "beta", "alpha", "p", "q", "r", "ax_cg", "ay_cg", "az_cg", "elevator", "aileron", "rudder",
            "alt", "mass", "Ixx", "Iyy", "Izz")
#: Optional telemetry columns taken when the file records them (a column of zeros is "not recorded").
OPTIONAL = {"rho_kg_m3": "rho", "qbar_pa": "qbar", "phi_rad": "phi", "theta_rad": "theta"}


def noise_sigma(x: np.ndarray, order: int = 4) -> float:
    """White-noise sigma of a smooth signal plus noise: std of its `order`-th difference
    over sqrt(C(2 order, order)) (the difference cancels the signal, not the noise)."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if x.size <= order + 2:
        return 0.0
    return float(np.std(np.diff(x, order)) / np.sqrt(comb(2 * order, order)))


class _SidpacFile:
    """fdata with its units (the file's labels, else SIDPAC's standard)."""

    def __init__(self, path: Path):
        from scipy.io import loadmat
        from scipy.io.matlab import MatReadError

        self.path, self.src = path, str(path)
        try:
            mat = loadmat(path, squeeze_me=True, struct_as_record=False)
        except (MatReadError, ValueError, TypeError, OSError, NotImplementedError) as exc:
            raise ImportDataError(path, f"not a MATLAB file scipy can read ({exc})") from None
        if "fdata" not in mat:
            names = sorted(k for k in mat if not k.startswith("__"))
            raise ImportDataError(path, "missing .mat variable 'fdata' (SIDPAC's data matrix, one row per sample, "
                                  f"90 columns); the file has {names}")
        self.mat = mat
        self.fdata = np.atleast_2d(np.asarray(mat["fdata"], dtype=float))
        fdatao = mat.get("fdatao")
        self.fdatao = np.atleast_2d(np.asarray(fdatao, dtype=float)) if fdatao is not None else None
        fds = mat.get("fds")
        self.fds = fds
        units = getattr(fds, "varunits", None)
        self.labels = [str(u).strip().strip("()").strip() for u in np.atleast_1d(units)] if units is not None else []

    def has(self, name: str) -> bool:
        col = COLUMNS[name][0]
        return self.fdata.shape[1] >= col and bool(np.any(self.fdata[:, col - 1] != 0))

    def raw(self, name: str, fdatao: bool = False) -> np.ndarray:
        col, _, signal = COLUMNS[name]
        data = self.fdatao if fdatao else self.fdata
        if data.shape[1] < col:
            raise ImportDataError(self.path, f"variable 'fdata' has {data.shape[1]} columns; column {col} "
                                  f"({signal}) is needed", column=f"fdata:{col}")
        return data[:, col - 1]

    def unit(self, name: str) -> str:
        col, standard, _ = COLUMNS[name]
        label = self.labels[col - 1] if len(self.labels) >= col else ""
        return label or standard

    def require(self, name: str) -> np.ndarray:
        col, _, signal = COLUMNS[name]
        x = self.raw(name)
        if not np.any(x != 0):
            raise ImportDataError(self.path, f"{signal} is all zero (SIDPAC's mark of an unrecorded column); "
                                  "aerosid needs it", column=f"fdata:{col}")
        return x

    def si(self, name: str, to_unit: str) -> np.ndarray:
        col, _, signal = COLUMNS[name]
        try:
            return to_si(self.raw(name), self.unit(name), to_unit)
        except (TypeError, ValueError, AttributeError, AssertionError) as exc:  # pint: unknown label, wrong dimension
            raise ImportDataError(self.path, f"{signal}: unit {self.unit(name)!r} does not convert to {to_unit} "
                                  f"({exc})", column=f"fdata:{col}") from None

    def conv(self, column: str, name: str):
        col, _, signal = COLUMNS[name]
        try:
            return conversion(column, self.unit(name), source=f"fdata column {col} ({signal})", where=self.src)
        except UnitError as exc:
            raise ImportDataError(self.path, str(exc), column=f"fdata:{col}") from None

    def scalar(self, var: str, name: str, to_unit: str) -> float:
        """A reference scalar (sarea, bspan, cbar) in SI, else fdata's column for it."""
        value = self.mat.get(var)
        if value is not None and np.size(value) == 1 and float(value) > 0:
            return float(to_si(float(value), COLUMNS[name][1], to_unit))
        if self.fdata.shape[1] >= COLUMNS[name][0] and self.has(name):
            return float(np.nanmean(self.si(name, to_unit)))
        raise ImportDataError(self.path, f"missing .mat variable {var!r} and fdata column {COLUMNS[name][0]} "
                              f"({COLUMNS[name][2]}) is zero: the {COLUMNS[name][2]} is needed for the vehicle file")


def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "aircraft"


def _text(fds, key: str) -> str:
    value = getattr(fds, key, "") if fds is not None else ""
    return str(value).strip() if isinstance(value, str) else ""


def import_sidpac(path: str | Path) -> ImportedFlight:
    """Read a SIDPAC .mat file; return the telemetry in aerosid's raw contract and the
    vehicle file (class "aircraft", vanes), with every conversion recorded."""
    path = Path(path)
    if not path.is_file():
        raise ImportDataError(path, "no such file")
    f = _SidpacFile(path)
    for name in REQUIRED:
        f.require(name)
    n = f.fdata.shape[0]
    notes: list[str] = []
    convs = []
    data: dict[str, np.ndarray] = {}

    def put(column: str, name: str):
        c = f.conv(column, name)
        convs.append(c)
        data[column] = c.apply(f.raw(name))
        return c

    t_raw = f.raw("time")
    check_time(t_raw, f.src, "fdata:1")
    t0 = float(t_raw[0])
    c = replace(f.conv("t_s", "time"), offset=-t0, source="fdata column 1 (time) minus its first value")
    convs.append(c)
    data["t_s"] = c.apply(t_raw)

    # accelerations: at the sensor when the file fixes where the sensor is
    deg_s = {k: f.si(k, "rad/s") for k in ("p", "q", "r")}
    have_meas = all(f.has(k) for k in ("ax_meas", "ay_meas", "az_meas"))
    if all(f.has(k) for k in ("p_dot", "q_dot", "r_dot")):
        ang_acc = [f.si(k, "rad/s^2") for k in ("p_dot", "q_dot", "r_dot")]
    else:
        ang_acc = [np.gradient(deg_s[k], data["t_s"]) for k in ("p", "q", "r")]
        notes.append("angular accelerations for the accelerometer fit: numerical derivatives of p, q, r "
                     "(fdata columns 42-44 are zero)")
    a_cg = np.column_stack([f.si(k, "m/s^2") for k in ("ax_cg", "ay_cg", "az_cg")])
    fit = None
    if have_meas:
        a_meas = np.column_stack([f.si(k, "m/s^2") for k in ("ax_meas", "ay_meas", "az_meas")])
        fit = recover_accel_offset(deg_s["p"], deg_s["q"], deg_s["r"], *ang_acc, a_meas, a_cg)
    if fit is not None and fit.trusted:
        offset = fit.offset_m
        for axis, (column, name) in enumerate((("ax_m_s2", "ax_meas"), ("ay_m_s2", "ay_meas"),
                                               ("az_m_s2", "az_meas"))):
            base = f.conv(column, name)
            # a bias below 1e-4 m/s^2 (1e-5 g, a tenth of the file's resolution) is the fit's rounding, not a bias
            bias = fit.bias_m_s2[axis] if abs(fit.bias_m_s2[axis]) > 1e-4 else 0.0
            c = replace(base, offset=base.offset - bias,
                        source=f"{base.source} minus the bias SIDPAC's compatibility check removed ({bias:.6g} m/s^2)")
            convs.append(c)
            data[column] = c.apply(f.raw(name))
        notes.append("accelerations at the sensor (fdata 53-55) less SIDPAC's biases; aerosid's filter models the "
                     f"lever arm from [sensors] accel_offset_m. {fit.summary()}")
    else:
        offset = (0.0, 0.0, 0.0)
        for column, name in (("ax_m_s2", "ax_cg"), ("ay_m_s2", "ay_cg"), ("az_m_s2", "az_cg")):
            put(column, name)
        why = fit.summary() if fit is not None else "fdata columns 53-55 (measured accelerations) are zero"
        notes.append(f"accelerations at the CG (fdata 11-13), accelerometer offset 0: {why}")
    put("p_rad_s", "p")
    put("q_rad_s", "q")
    put("r_rad_s", "r")
    # d1..d4 = elevator, left aileron, right aileron, rudder (positive trailing edge down; rudder
    # trailing edge left).  SIDPAC's one aileron channel rolls the left wing down when positive
    # (vehicle comments): left aileron = -aileron, right aileron = +aileron.
    put("d1_rad", "elevator")
    c = replace(f.conv("d2_rad", "aileron"), sign=-1.0,
                source="fdata column 15 (aileron), sign flipped: left aileron = -aileron")
    convs.append(c)
    data["d2_rad"] = c.apply(f.raw("aileron"))
    c = replace(f.conv("d3_rad", "aileron"), source="fdata column 15 (aileron): right aileron = +aileron")
    convs.append(c)
    data["d3_rad"] = c.apply(f.raw("aileron"))
    put("d4_rad", "rudder")
    put("V_m_s", "V")
    put("h_m", "alt")
    put("alpha_vane_rad", "alpha")
    put("beta_vane_rad", "beta")
    for column, name in OPTIONAL.items():
        if f.has(name):
            put(column, name)
    telemetry = pd.DataFrame({k: np.asarray(v, dtype=float) for k, v in data.items()})
    assert len(telemetry) == n

    vehicle = _vehicle(f, telemetry, offset, fit)
    meta = {"aerosid.time_origin_s": repr(t0), "aerosid.accel_offset_m": repr(list(offset))}
    for key in ("aircraft", "maneuver", "test_date"):
        if _text(f.fds, key):
            meta[f"aerosid.sidpac_{key}"] = _text(f.fds, key)
    notes.append("alpha, beta: SIDPAC's corrected angles (fdata 3, 4) as the vane columns (bias 0: already "
                 "corrected)")
    return ImportedFlight(importer="sidpac", source=str(path), telemetry=telemetry, vehicle_toml=vehicle.to_toml(),
                          vehicle_name=vehicle.name, conversions=tuple(convs), notes=tuple(notes),
                          extra_metadata=meta)


def _vehicle(f: _SidpacFile, tel: pd.DataFrame, offset, fit) -> AircraftVehicle:
    from aerosid.vehicles.atmosphere import speed_of_sound_m_s

    aircraft = _text(f.fds, "aircraft") or f.path.stem
    manoeuvre = _text(f.fds, "maneuver") or f.path.stem
    date = _text(f.fds, "test_date")
    mass = f.si("mass", "kg")
    inertia = {k: float(np.nanmean(f.si(k, "kg*m^2"))) for k in ("Ixx", "Iyy", "Izz", "Ixz")}
    cg = tuple(float(np.nanmean(f.si(k, "m"))) if f.has(k) else 0.0 for k in ("x_cg", "y_cg", "z_cg"))
    V, h = float(np.nanmean(tel["V_m_s"])), float(np.nanmean(tel["h_m"]))
    if f.has("mach"):
        mach = float(np.nanmean(f.raw("mach")))
        mach_note = [f"mean Mach of the manoeuvre, fdata column 28 ({f.path.name})"]
    else:
        a = float(speed_of_sound_m_s(h))
        mach = V / a
        mach_note = [f"mean V / speed of sound of US-1976 at the mean altitude: {V:.2f} / {a:.2f} m/s at "
                     f"{h:.0f} m ({f.path.name} records no Mach number)",
                     "it only centres the Mach window of the regression (aerosid run --mach-half-width)"]
    noise = float(np.sqrt(np.mean([noise_sigma(tel["alpha_vane_rad"]) ** 2, noise_sigma(tel["beta_vane_rad"]) ** 2])))
    src = f.path.name
    accel_note = ([f"recovered from {src}: sensor (fdata 53-55) minus CG (11-13) accelerations regressed on the",
                   "lever-arm terms omega_dot x r + omega x (omega x r) (plus a bias per axis):",
                   f"sigma {max(fit.sigma_m):.1e} m, residual RMS {fit.residual_rms_m_s2:.1e} m/s^2 over "
                   f"{fit.n_samples} samples; the telemetry holds the sensor's accelerations"]
                  if fit is not None and fit.trusted else
                  ["the telemetry holds the CG accelerations (fdata 11-13): offset 0",
                   (fit.summary() if fit is not None else "the file has no measured accelerations (fdata 53-55)")])
    return AircraftVehicle(
        name=_slug(aircraft),
        description=f"{aircraft}, manoeuvre {manoeuvre}{f' of {date}' if date else ''}, imported from {src} (SIDPAC)",
        header=[f"{aircraft}: vehicle file written by `aerosid import sidpac {src}` (aerosid/vehicles/sidpac.py).",
                "Every number comes from the file (SIDPAC's fdata columns, 1-based; units converted to SI by pint);",
                "the comments say which.  Edit freely: aerosid run reads it as any vehicle file (docs/vehicles.md)."],
        mass_kg=float(np.nanmean(mass)),
        mass_note=[f"fdata 48 (slug), mean over the manoeuvre ({np.nanmin(mass):.1f}..{np.nanmax(mass):.1f} kg: fuel "
                   "burnt); fdata 49-52 (slug ft^2)",
                   "SIDPAC's moment equations use L = Ixx pdot - Ixz rdot + ..., as aerosid does: Ixz keeps its sign"],
        **{f"{k}_kg_m2": v for k, v in inertia.items()},
        S_m2=f.scalar("sarea", "S", "m^2"), chord_m=f.scalar("cbar", "cbar", "m"), span_m=f.scalar("bspan", "b", "m"),
        reference_note=["sarea, cbar, bspan of the file (ft^2, ft)"],
        cg_m=cg,
        cg_note=["CG position, fdata 45-47 (in), in the aircraft's own reference frame as SIDPAC records it",
                 "(not stated in the file); the pipeline uses only accel_offset_m, which is relative to the CG"],
        accel_offset_m=tuple(float(v) for v in offset), accel_note=accel_note,
        mach_reference=float(mach), mach_note=mach_note,
        vane_noise_rad=noise,
        air_data_note=[f"alpha and beta: SIDPAC's angles after its data-compatibility corrections (fdata 4, 3):",
                       "no calibration bias left to remove.  noise_rad: their white-noise level, std of the",
                       f"4th difference / sqrt(70), from {src} (errors-in-variables check).  No cutoff_hz: at",
                       "this noise the vanes need no low-pass; alpha_dot_hat uses the window below."],
        controls_note=["d1..d4 = elevator, left aileron, right aileron, rudder: positive trailing edge down for the",
                       "elevator and each aileron, trailing edge left for the rudder (c172x's conventions).",
                       "d1 = fdata 14 (elevator, SIDPAC positive trailing edge down: its Cm_de is negative).",
                       "SIDPAC records ONE aileron channel (fdata 15), positive rolling the left wing down (on",
                       "lon_020213f1_018 a regression of SIDPAC's Cl on beta, p_hat, r_hat, aileron, rudder gives",
                       "Cl_aileron = -0.138, t = -14): d2 = -aileron, d3 = +aileron, so delta_r = (d2 - d3)/2",
                       "= -aileron (positive right wing down) and Cl_delta_r > 0 as on c172x.  Antisymmetric",
                       "ailerons assumed (one channel cannot say otherwise).",
                       "d4 = fdata 16 (rudder), taken as recorded (SIDPAC's convention, trailing edge left positive);",
                       "an elevator manoeuvre moves it too little to check the sign from the data."],
    )
