"""An aircraft-class vehicle file (the layout of aerosid/data/c172x/vehicle.toml), with
every value's origin written beside it as a comment.

:class:`AircraftVehicle` holds the values in SI; :meth:`AircraftVehicle.to_toml`
writes the file.  No ``[estimation]`` table is written: smoother settings are the
run's business, not the vehicle's.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field

#: Default linear models of an imported aircraft: c172x's (aerosid/data/c172x/vehicle.toml),
#: without its Cm_abs_beta, which stands for JSBSim's aerodynamic reference point 0.585 m
#: above the c172x's CG (a property of that model, not of aircraft in general).
#: The default models written for an imported aircraft.  The pitch channel is the
#: flight-test standard for one elevator manoeuvre (SIDPAC's too): a short-period
#: manoeuvre makes alpha-dot follow q, so Cm_q and Cm_alpha_dot are not separable
#: (on Twin Otter 018 together: VIF 96, and Cm_alpha moved 30 % through them); Cm_q
#: then stands for the combined damping.  Add `Cm_alpha_dot = alpha_dot_hat` with a
#: model spec when the flight has manoeuvres that separate them.
DEFAULT_AIRCRAFT_MODELS: dict[str, list[str]] = {
    "CN": ["CN_0 = 1", "CN_alpha = alpha", "CN_delta_p = delta_p"],
    "Cm": ["Cm_0 = 1", "Cm_alpha = alpha", "Cm_delta_p = delta_p", "pitch_damping"],
    "CY": ["CY_0 = 1", "CY_beta = beta", "CY_delta_y = delta_y"],
    "Cl": ["Cl_0 = 1", "Cl_beta = beta", "Cl_p = p_hat", "Cl_r = r_hat", "Cl_delta_r = delta_r", "Cl_delta_y = delta_y"],
    "Cn": ["Cn_0 = 1", "Cn_beta = beta", "Cn_p = p_hat", "Cn_r = r_hat", "Cn_delta_r = delta_r", "Cn_delta_y = delta_y"],
}

#: Conventional aircraft mixing over d1..d4 = elevator, left aileron, right aileron,
#: rudder (positive trailing edge down; rudder trailing edge left): delta_r = (d2 - d3)/2
#: (positive rolls right wing down), delta_p = elevator, delta_y = rudder.
AIRCRAFT_MIXING = ((0.0, 0.5, -0.5, 0.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
AIRCRAFT_SURFACES = ("elevator", "left_aileron", "right_aileron", "rudder")


def num(value: float) -> str:
    """A float as TOML, 7 significant digits (exact values such as 0.3048 ft stay exact)."""
    return repr(float(f"{float(value):.7g}"))


def comment(lines) -> str:
    return "".join(f"# {line}\n" if line else "#\n" for line in lines)


@dataclass(frozen=True)
class AircraftVehicle:
    """An aircraft's vehicle file in SI units, with notes (comment lines) saying where each value came from."""

    name: str
    description: str
    mass_kg: float
    Ixx_kg_m2: float
    Iyy_kg_m2: float
    Izz_kg_m2: float
    Ixz_kg_m2: float
    S_m2: float
    chord_m: float
    span_m: float
    cg_m: tuple[float, float, float]  # as the source gives it (its frame, see cg_note)
    accel_offset_m: tuple[float, float, float]
    mach_reference: float
    vane_noise_rad: float
    header: tuple[str, ...] = ()
    mass_note: tuple[str, ...] = ()
    reference_note: tuple[str, ...] = ()
    cg_note: tuple[str, ...] = ()
    accel_note: tuple[str, ...] = ()
    controls_note: tuple[str, ...] = ()
    air_data_note: tuple[str, ...] = ()
    mach_note: tuple[str, ...] = ()
    surfaces: tuple[str, ...] = AIRCRAFT_SURFACES
    mixing: tuple[tuple[float, ...], ...] = AIRCRAFT_MIXING
    surface_limit_rad: float = 0.35
    alpha_column: str = "alpha_vane_rad"
    beta_column: str = "beta_vane_rad"
    derivative_half_window_s: float = 0.15
    models: dict = field(default_factory=lambda: {k: list(v) for k, v in DEFAULT_AIRCRAFT_MODELS.items()})

    def __post_init__(self):  # notes given as lists are kept as tuples (a frozen value)
        for name in ("header", "mass_note", "reference_note", "cg_note", "accel_note", "controls_note",
                     "air_data_note", "mach_note", "surfaces"):
            object.__setattr__(self, name, tuple(getattr(self, name)))

    def summary(self) -> str:
        x, y, z = self.accel_offset_m
        return (f"vehicle {self.name}: mass {self.mass_kg:.1f} kg; Ixx/Iyy/Izz/Ixz {self.Ixx_kg_m2:.0f} / "
                f"{self.Iyy_kg_m2:.0f} / {self.Izz_kg_m2:.0f} / {self.Ixz_kg_m2:.0f} kg m^2; S {self.S_m2:.2f} m^2, "
                f"chord {self.chord_m:.3f} m, span {self.span_m:.2f} m; accelerometer ({x:.3f}, {y:.3f}, {z:.3f}) m "
                f"from the CG; Mach reference {self.mach_reference:.4f}; d1..d4 = {', '.join(self.surfaces)}")

    def to_toml(self) -> str:
        q = json.dumps  # a TOML basic string is a JSON string for the text written here
        out = [comment(self.header), "\n",
               f"name = {q(self.name)}\n", 'class = "aircraft"\n', f"description = {q(self.description)}\n\n",
               "[mass]\n", comment(self.mass_note),
               f"mass_kg = {num(self.mass_kg)}\n", f"Ixx_kg_m2 = {num(self.Ixx_kg_m2)}\n",
               f"Iyy_kg_m2 = {num(self.Iyy_kg_m2)}\n", f"Izz_kg_m2 = {num(self.Izz_kg_m2)}\n",
               comment(["aerosid's convention: L = Ixx pdot - Ixz rdot + ..., Ixz = integral of x z dm "
                        "(body axes x fwd, z down)"]),
               f"Ixz_kg_m2 = {num(self.Ixz_kg_m2)}\n\n",
               "[reference]\n", comment(self.reference_note),
               f"S_m2 = {num(self.S_m2)}\n",
               f"chord_m = {num(self.chord_m)}             # mean aerodynamic chord: C_m and q c/(2V)\n",
               f"span_m = {num(self.span_m)}              # C_l, C_n and p b/(2V), r b/(2V)\n",
               comment(self.cg_note),
               f"x_cg_m = {num(self.cg_m[0])}\n",
               f"y_cg_m = {num(self.cg_m[1])}              # for reference; not read by the pipeline\n",
               f"z_cg_m = {num(self.cg_m[2])}              # for reference; not read by the pipeline\n\n",
               "[sensors]\n", comment(["accelerometer triad relative to the CG, body axes x fwd, y right, z down [m]"]),
               comment(self.accel_note),
               f"accel_offset_m = [{', '.join(num(v) for v in self.accel_offset_m)}]\n\n",
               "[air_data]\n", comment(self.air_data_note),
               'source = "vanes"                        # alpha, beta from the telemetry columns below\n',
               f"alpha_column = {q(self.alpha_column)}\n", f"beta_column = {q(self.beta_column)}\n",
               "alpha_bias_rad = 0.0\n", "beta_bias_rad = 0.0\n",
               f"noise_rad = {num(self.vane_noise_rad)}\n",
               f"derivative_half_window_s = {num(self.derivative_half_window_s)}\n",
               comment(["the vanes against the IMU (docs/estimation.md, 'Air-data timing'): delay_s, their delay",
                        "behind it [s] (a run that measures one reports it, finding airdata_delay, with the value);",
                        "vane_position_m, their position from the CG, body axes [m] (0: angles already at the CG)"]),
               "delay_s = 0.0\n", "vane_position_m = [0.0, 0.0, 0.0]\n\n",
               "[controls]\n", comment(self.controls_note),
               f"surfaces = [{', '.join(q(s) for s in self.surfaces)}]   # d1..d4\n",
               comment(["rows: delta_r (roll control), delta_p (pitch control = elevator), "
                        "delta_y (yaw control = rudder); columns d1..d4"]),
               "mixing = [" + ", ".join("[" + ", ".join(num(v) for v in row) + "]" for row in self.mixing) + "]\n",
               comment(["largest surface deflection: not in the data; aerosid uses it only to clip simulated "
                        "surfaces"]),
               f"surface_limit_rad = {num(self.surface_limit_rad)}\n\n",
               "[aero]\n", comment(self.mach_note),
               f"mach_reference = {num(self.mach_reference)}\n\n",
               "[models]\n",
               comment(["The default linear models (SI per radian, moments about the CG; q_hat = q c/(2V), "
                        "p_hat = p b/(2V),",
                        "r_hat = r b/(2V); delta_p = elevator, delta_r = (left - right aileron)/2, delta_y = rudder).",
                        "c172x's defaults without its Cm_abs_beta (JSBSim's reference point above the c172x CG).",
                        "pitch_damping is C_m_q q_hat; Cm_q and Cm_alpha_dot are nearly collinear in a short period:",
                        "their sum is what the manoeuvre measures.  Terms the manoeuvre does not excite (the lateral",
                        "channels of an elevator input) are the run's business: aerosid fit --model SPEC changes them."]),
               ]
        for ch, terms in self.models.items():
            out.append(f"{ch} = [{', '.join(q(t) for t in terms)}]\n")
        return "".join(out)
