"""The linear truth of a JSBSim aircraft at its trim point: the aerodynamic model's
inputs at a state (alpha, beta, the three deflections, the non-dimensional rates),
the model's body-axis coefficients about the CG (JSBSim's wind-to-body rotation and
AERORP-to-CG transfer, with <aero_ref_pt_shift_x>), and their central differences."""
from __future__ import annotations

from dataclasses import dataclass

from aerosid.simulation.jsbsim_tables import DEG, AeroTables, body_coefficients


@dataclass(frozen=True)
class Controls:
    """The properties the aerodynamic model reads as the three control deflections
    [rad], the same surfaces in other units it also reads (``siblings``: e.g.
    Concorde's drag reads fcs/elevator-pos-norm; linear in the deflection, the slope
    probed through the FCS), and the physical left/right aileron positions when the
    FCS has them."""

    pitch: str
    roll: str
    yaw: str
    left_aileron: str | None
    right_aileron: str | None
    siblings: tuple[tuple[str, str], ...] = ()   # (property, the control it follows)



GEOMETRY = ["aero/qbar-psf", "metrics/Sw-sqft", "metrics/cbarw-ft", "metrics/bw-ft", "aero/ci2vel", "aero/bi2vel",
            "metrics/aero-rp-x-in", "metrics/aero-rp-y-in", "metrics/aero-rp-z-in",
            "inertia/cg-x-in", "inertia/cg-y-in", "inertia/cg-z-in", "inertia/mass-slugs",
            "inertia/ixx-slugs_ft2", "inertia/iyy-slugs_ft2", "inertia/izz-slugs_ft2", "inertia/ixz-slugs_ft2",
            "inertia/ixy-slugs_ft2", "inertia/iyz-slugs_ft2", "velocities/vt-fps", "velocities/mach",
            "atmosphere/rho-slugs_ft3", "position/h-sl-ft", "aero/alpha-rad", "aero/beta-rad",
            "flight-path/gamma-rad", "attitude/theta-rad", "attitude/phi-rad"]


def snapshot(fdm, tables: AeroTables, controls: Controls) -> dict[str, float]:
    names = set(tables.leaf_properties()) | set(GEOMETRY) | {controls.pitch, controls.roll, controls.yaw}
    names |= {p for p in (controls.left_aileron, controls.right_aileron) if p}
    return {p: float(fdm[p]) for p in sorted(names)}


def state_values(base: dict, controls: Controls, x: dict, slopes: dict | None = None) -> dict:
    """The model's leaf properties at the state x (alpha, beta, delta_p, delta_r,
    delta_y [rad], p_hat, q_hat, r_hat, alpha_dot_hat), everything else as in `base`."""
    v = dict(base)
    a, b = x["alpha"], x["beta"]

    def put(name, value):
        if name in v:
            v[name] = value

    put("aero/alpha-wing-rad", a + base.get("aero/alpha-wing-rad", 0.0) - base["aero/alpha-rad"])
    put("aero/alpha-rad", a)
    put("aero/alpha-deg", a / DEG)
    put("aero/beta-rad", b)
    put("aero/beta-deg", b / DEG)
    put("aero/mag-beta-rad", abs(b))
    put("aero/mag-beta-deg", abs(b) / DEG)
    v[controls.pitch], v[controls.roll], v[controls.yaw] = x["delta_p"], x["delta_r"], x["delta_y"]
    for sib, ctrl in controls.siblings:
        v[sib] = base[sib] + slopes[sib] * (v[ctrl] - base[ctrl])
    if controls.pitch == "fcs/elevator-pos-rad":
        put("fcs/mag-elevator-pos-rad", abs(x["delta_p"]))
    for axis, hat, scale in (("p", "p_hat", "aero/bi2vel"), ("q", "q_hat", "aero/ci2vel"), ("r", "r_hat", "aero/bi2vel")):
        put(f"velocities/{axis}-aero-rad_sec", x[hat] / base[scale])
        put(f"velocities/{axis}-rad_sec", x[hat] / base[scale])
    put("aero/alphadot-rad_sec", x["alpha_dot_hat"] / base["aero/ci2vel"])
    return v


def arm_ft(tables: AeroTables, values: dict, cg_in) -> tuple:
    """AERORP (with JSBSim's <aero_ref_pt_shift_x>, in chords) minus the CG, body axes [ft]."""
    shift = tables.rp_shift(values)
    rp_x = values["metrics/aero-rp-x-in"] + (0.0 if shift is None else shift * values["metrics/cbarw-ft"] * 12.0)
    return ((cg_in[0] - rp_x) / 12.0, (values["metrics/aero-rp-y-in"] - cg_in[1]) / 12.0,
            (cg_in[2] - values["metrics/aero-rp-z-in"]) / 12.0)


def model_coefficients(tables: AeroTables, values: dict, alpha, beta, cg_in, cl_squared_from_lift: bool = False):
    """The XML model's body-axis coefficients about the CG (and the AERORP moments).
    cl_squared_from_lift: aero/cl-squared = the model's own C_L^2 (a steady state;
    JSBSim uses the previous frame's)."""
    qS = values["aero/qbar-psf"] * values["metrics/Sw-sqft"]
    b_ft, c_ft = values["metrics/bw-ft"], values["metrics/cbarw-ft"]
    s = tables.axis_sums(values)
    if cl_squared_from_lift and "aero/cl-squared" in values:
        values = dict(values)
        values["aero/cl-squared"] = (s["LIFT"] / qS) ** 2
        s = tables.axis_sums(values)
    c = {"CD": s["DRAG"] / qS, "CS": s["SIDE"] / qS, "CL": s["LIFT"] / qS,
         "Cl_rp": s["ROLL"] / (qS * b_ft), "Cm_rp": s["PITCH"] / (qS * c_ft), "Cn_rp": s["YAW"] / (qS * b_ft)}
    return body_coefficients(c, alpha, beta, arm_ft(tables, values, cg_in), c_ft, b_ft)


def linear_truth(tables: AeroTables, base: dict, controls: Controls, slopes: dict | None = None) -> tuple[dict, dict, dict]:
    """Central differences of the model at the trim point: (about the CG, about the
    AERORP, the value and derivative table) in jsbsim_flight's names."""
    from aerosid.simulation.jsbsim_truth import _coefficient_table, central_differences

    cg = (base["inertia/cg-x-in"], base["inertia/cg-y-in"], base["inertia/cg-z-in"])
    point = {"alpha": base["aero/alpha-rad"], "beta": base["aero/beta-rad"], "delta_p": base[controls.pitch],
             "delta_r": base[controls.roll], "delta_y": base[controls.yaw],
             "p_hat": 0.0, "q_hat": 0.0, "r_hat": 0.0, "alpha_dot_hat": 0.0}

    def evaluate(x):
        c = model_coefficients(tables, state_values(base, controls, x, slopes), x["alpha"], x["beta"], cg,
                               cl_squared_from_lift=True)
        return {k: float(v) for k, v in c.items()}

    lin = central_differences(evaluate, point)
    return _coefficient_table(lin, point, "cg"), _coefficient_table(lin, point, "rp"), lin


def mach_slopes(tables: AeroTables, base: dict, controls: Controls, slopes: dict | None = None) -> dict:
    """d C / d Mach at the trim point (0 when the model does not read velocities/mach)."""
    if "velocities/mach" not in base:
        return {k: 0.0 for k in ("CN", "CA", "Cm", "CY", "Cl", "Cn")}
    cg = (base["inertia/cg-x-in"], base["inertia/cg-y-in"], base["inertia/cg-z-in"])
    x = {"alpha": base["aero/alpha-rad"], "beta": base["aero/beta-rad"], "delta_p": base[controls.pitch],
         "delta_r": base[controls.roll], "delta_y": base[controls.yaw],
         "p_hat": 0.0, "q_hat": 0.0, "r_hat": 0.0, "alpha_dot_hat": 0.0}
    out = []
    for dm in (1e-3, -1e-3):
        v = state_values(base, controls, x, slopes)
        v["velocities/mach"] = base["velocities/mach"] + dm
        out.append(model_coefficients(tables, v, x["alpha"], x["beta"], cg, True))
    return {k: float((out[0][k] - out[1][k]) / 2e-3) for k in ("CN", "CA", "Cm", "CY", "Cl", "Cn")}


def abs_beta_slope(tables: AeroTables, base: dict, controls: Controls, beta_rad: float,
                   slopes: dict | None = None) -> float:
    """d C_m / d |beta| about the CG at `beta_rad` (the even part of C_m in sideslip)."""
    cg = (base["inertia/cg-x-in"], base["inertia/cg-y-in"], base["inertia/cg-z-in"])
    x = {"alpha": base["aero/alpha-rad"], "beta": 0.0, "delta_p": base[controls.pitch],
         "delta_r": base[controls.roll], "delta_y": base[controls.yaw],
         "p_hat": 0.0, "q_hat": 0.0, "r_hat": 0.0, "alpha_dot_hat": 0.0}
    cm = {}
    for b in (-beta_rad, 0.0, beta_rad):
        x["beta"] = b
        cm[b] = float(model_coefficients(tables, state_values(base, controls, x, slopes), x["alpha"], b, cg, True)["Cm"])
    return (cm[beta_rad] + cm[-beta_rad] - 2 * cm[0.0]) / (2 * beta_rad)
