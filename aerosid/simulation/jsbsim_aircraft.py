"""A validation flight of any JSBSim aircraft that trims, with its vehicle file generated.

``simulate_aircraft("pa28", seed)`` designs a flight for the aircraft from its own
XML and JSBSim (aerosid.simulation.jsbsim_design: trim point, surfaces, manoeuvre),
flies two mirrored elevator 3-2-1-1s and aileron and rudder doublets at 100 Hz, and
returns a :class:`~aerosid.simulation.SimulatedFlight` whose

- ``telemetry`` is aerosid's raw schema plus the vanes and the INS attitude (noise and faults as
  aerosid/data/jsbsim/instrumentation.toml);
- ``truth`` holds JSBSim's own aerodynamic coefficients about the CG at every sample,
  next to the aircraft's XML model re-evaluated independently at every sample
  (``*_xml``; the flight is refused if they differ by more than XML_TOLERANCE);
- ``coefficients`` is the linear truth at the trim point (central differences of the
  XML model moved to the CG);
- ``files["vehicle.toml"]`` is the generated vehicle file (mass, inertia, geometry,
  CG, controls and their mixing, surface limits, sensors, mach_reference and the
  aircraft-class [models]), written beside the telemetry and named in its metadata.

docs/jsbsim.md ("Any aircraft") describes the rules and what was measured.
"""
from __future__ import annotations

import math
import tomllib
import xml.etree.ElementTree as ET

import numpy as np
import pandas as pd

from aerosid.simulation import SimulatedFlight
from aerosid.simulation.jsbsim_design import (DT_S, FT, INCH, LBF, PSF, SLUG, SLUG_FT2, FlightDesign, in_catalogue,
                                              UnsupportedAircraft, flight_design, loaded_fdm)
from aerosid.simulation.jsbsim_linear import abs_beta_slope, mach_slopes, model_coefficients
from aerosid.simulation.jsbsim_flight import COMMON_PROPERTIES, _fly, _import_jsbsim, _schedule, _takeup_steps
from aerosid.simulation.jsbsim_turbulence import checked_turbulence, start_turbulence
from aerosid.simulation.jsbsim_columns import coefficient_columns, make_telemetry, state_columns
from aerosid.simulation.jsbsim_truth import flight_statistics, _truth_check
from aerosid.simulation.jsbsim_tables import DEG, AeroTables
from aerosid.simulation.jsbsim_trim import initialise
from aerosid.simulation.jsbsim_truth_avg import generated_flight_average
from aerosid.simulation.jsbsim_vehicle import powered_level, vehicle_toml
from aerosid.vehicles.vehicle import DATA_DIR

__all__ = ["simulate_aircraft", "XML_TOLERANCE", "RESERVED"]

XML_TOLERANCE = 1e-6   # largest |coefficient from the XML - JSBSim's| accepted at any sample
# kept out of aerosid's development: an independent check flies them (issue 16)
RESERVED = ("737", "787-8")

_STANDARD = [
    *COMMON_PROPERTIES,
    "aero/alpha-rad", "aero/beta-rad", "aero/alphadot-rad_sec", "aero/ci2vel", "aero/bi2vel",
    "fcs/elevator-cmd-norm", "fcs/aileron-cmd-norm", "fcs/rudder-cmd-norm",
    "accelerations/gravity-ft_sec2", "metrics/Sw-sqft", "metrics/cbarw-ft", "metrics/bw-ft",
    "metrics/aero-rp-x-in", "metrics/aero-rp-y-in", "metrics/aero-rp-z-in",
]


def instrumentation() -> dict:
    return tomllib.loads((DATA_DIR / "jsbsim" / "instrumentation.toml").read_text())


def _record_list(design: FlightDesign, tables: AeroTables, catalogue: set[str], n_eng: int) -> list[str]:
    c = design.controls
    names = _STANDARD + tables.leaf_properties() + [c.pitch, c.roll, c.yaw]
    names += [p for p in (c.left_aileron, c.right_aileron) if p] + [s for s, _ in c.siblings]
    names += [f"propulsion/engine[{i}]/thrust-lbs" for i in range(n_eng)]
    return [p for p in dict.fromkeys(names) if in_catalogue(p, catalogue)]


def _surfaces(design: FlightDesign, rec: dict) -> tuple[list[np.ndarray], list[str], list[list[float]], list]:
    """The four recorded surface channels d1..d4, their names, the mixing rows (roll,
    pitch, yaw) and each channel's travel [rad], from how the model uses them."""
    c, lim = design.controls, design.limits_rad
    roll = rec[c.roll]
    L, R = c.left_aileron, c.right_aileron
    zeros = np.zeros_like(roll)
    if L and R and np.max(np.abs(0.5 * (rec[L] - rec[R]) - roll)) <= 1e-9 + 1e-7 * np.max(np.abs(roll)):
        d2, d3, names, row = rec[L], rec[R], ["left aileron", "right aileron"], [0.0, 0.5, -0.5, 0.0]
        lims = [lim[L], lim[R]]
    elif L and c.roll == L:
        d2, d3 = rec[L], (rec[R] if R else zeros)
        names, row = ["left aileron", "right aileron" if R else "unused"], [0.0, 1.0, 0.0, 0.0]
        lims = [lim[L], lim[R] if R else lim[L]]
    else:  # the model's aileron variable is not a physical surface position (e.g. a command)
        d2, d3 = roll, (rec[R] if R else zeros)
        names, row = [f"aileron ({c.roll})", "right aileron" if R else "unused"], [0.0, 1.0, 0.0, 0.0]
        lims = [lim[c.roll], lim[R] if R else lim[c.roll]]
    channels = [rec[c.pitch], d2, d3, rec[c.yaw]]
    mixing = [row, [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
    limits = [lim[c.pitch], *lims, lim[c.yaw]]
    return channels, ["elevator", *names, "rudder"], mixing, limits


def _xml_check(tables: AeroTables, rec: dict, truth: pd.DataFrame) -> dict:
    """The aircraft's XML model at every sample (from the recorded properties) against
    JSBSim's own coefficients about the CG."""
    leaves = tables.leaf_properties()
    values = {p: rec[p] for p in leaves}
    for p in ("aero/qbar-psf", "metrics/Sw-sqft", "metrics/cbarw-ft", "metrics/bw-ft",
              "metrics/aero-rp-x-in", "metrics/aero-rp-y-in", "metrics/aero-rp-z-in"):
        values.setdefault(p, rec[p])
    cg = (rec["inertia/cg-x-in"], rec["inertia/cg-y-in"], rec["inertia/cg-z-in"])
    c = model_coefficients(tables, values, rec["aero/alpha-rad"], rec["aero/beta-rad"], cg)
    out = {}
    for k in ("CA", "CY", "CN", "Cl", "Cm", "Cn"):
        truth[f"{k}_xml"] = c[k]
        out[k] = float(np.max(np.abs(c[k] - truth[k].to_numpy())))
    truth["CL"], truth["CD"] = c["CL"], c["CD"]
    return out


def simulate_aircraft(aircraft: str, seed: int = 0, *, faults: bool = True, progress=None,
                      input_table: pd.DataFrame | None = None, turbulence: str = "none") -> SimulatedFlight:
    """Fly JSBSim's `aircraft` through the generated flight design (or a designed input,
    ``input_table``: aerosid.simulation.jsbsim_input); noise, faults and the turbulence
    (aerosid.simulation.jsbsim_turbulence.TURBULENCE_SEVERITY) from `seed`.
    progress: an optional callback progress(stage, fraction)."""
    checked_turbulence(turbulence)
    if input_table is not None and "throttle_cmd_norm" in input_table.columns:
        raise ValueError(f"{aircraft}: a designed input's throttle_cmd_norm (a fixed-throttle glide) is flown for "
                         "c172x only; the generated flight design trims its own throttle")
    if progress is not None:
        progress("design and trim the flight", 0.0)
    jsbsim = _import_jsbsim()
    design = flight_design(jsbsim, aircraft)
    inst = instrumentation()
    tables = AeroTables(design.xml_path)
    xml_root = ET.parse(design.xml_path).getroot()
    ctl = design.controls

    fdm = loaded_fdm(jsbsim, aircraft, xml_root, design.trim)
    residual = initialise(fdm, design.trim)
    catalogue = {p.split(" ")[0] for p in fdm.get_property_catalog()}
    n_eng = int(fdm.get_propulsion().get_num_engines())
    record = _record_list(design, tables, catalogue, n_eng)
    trim = {p: float(fdm[p]) for p in record}

    dt = DT_S
    n = int(round(design.duration_s / dt)) + 1
    t = np.arange(n) * dt
    if input_table is not None:  # a designed input (aerosid.simulation.jsbsim_input) sets the duration
        from aerosid.simulation.jsbsim_input import input_time

        t = input_time(input_table, dt)
    m = design.manoeuvre
    takeup = {}
    for name, prop, cmd in (("elevator", ctl.pitch, design.trim.elevator_cmd),
                            ("aileron", ctl.roll, design.trim.aileron_cmd)):
        try:
            takeup[name] = _takeup_steps(xml_root, [prop], cmd)
        except (StopIteration, AttributeError, TypeError, ValueError):
            takeup[name] = []  # hysteresis not modelled the way c172x does it: no take-up
    inputs, windows = _schedule(t, m, takeup)
    if input_table is not None:
        from aerosid.simulation.jsbsim_input import gain_inputs

        inputs, windows = gain_inputs(input_table, t, design.gains), {"designed_input": [0.0, float(t[-1])]}
    air = start_turbulence(fdm, turbulence, seed)
    rec = _fly(fdm, t, inputs, record, progress=progress)
    for prop in _STANDARD:  # an aircraft without propulsion (a glider) has no forces/*-prop-* properties
        if prop not in rec and "-prop-" in prop:
            rec[prop] = np.zeros(len(t))

    # ---- geometry and mass ----
    S_ft2, cbar_ft, b_ft = trim["metrics/Sw-sqft"], trim["metrics/cbarw-ft"], trim["metrics/bw-ft"]
    S, cbar, b = S_ft2 * FT**2, cbar_ft * FT, b_ft * FT
    base = design.state
    offset = tuple(float(k) for k in inst["accelerometer"]["offset_m"])

    # ---- truth ----
    cols, mass_kg = state_columns(rec, t, dt, offset)
    V, qbar_pa, alpha, beta = cols["V_m_s"], cols["qbar_pa"], cols["alpha_rad"], cols["beta_rad"]
    p, q, r = cols["p_rad_s"], cols["q_rad_s"], cols["r_rad_s"]
    f_sensor = [cols[f"a{a}_sensor_m_s2"] for a in "xyz"]
    channels, surface_names, mixing, limits = _surfaces(design, rec)
    ci2vel, bi2vel = rec["aero/ci2vel"], rec["aero/bi2vel"]
    prop_thrust = sum(rec.get(f"propulsion/engine[{i}]/thrust-lbs", 0.0) for i in range(n_eng)) * LBF
    truth = pd.DataFrame({
        **cols,
        "delta_p_rad": rec[ctl.pitch], "delta_r_rad": rec[ctl.roll], "delta_y_rad": rec[ctl.yaw],
        "d1_rad": channels[0], "d2_rad": channels[1], "d3_rad": channels[2], "d4_rad": channels[3],
        "elevator_cmd_norm": rec["fcs/elevator-cmd-norm"], "aileron_cmd_norm": rec["fcs/aileron-cmd-norm"],
        "rudder_cmd_norm": rec["fcs/rudder-cmd-norm"],
        "p_hat": rec["velocities/p-aero-rad_sec"] * bi2vel, "q_hat": rec["velocities/q-aero-rad_sec"] * ci2vel,
        "r_hat": rec["velocities/r-aero-rad_sec"] * bi2vel, "alpha_dot_hat": rec["aero/alphadot-rad_sec"] * ci2vel,
        **coefficient_columns(rec, S_ft2, cbar_ft, b_ft),
        "thrust_N": prop_thrust * np.ones(len(t)), "mass_kg": mass_kg, "x_cg_m": rec["inertia/cg-x-in"] * INCH,
    })
    xml_diff = _xml_check(tables, rec, truth)
    worst = max(xml_diff, key=xml_diff.get)
    if xml_diff[worst] > XML_TOLERANCE:
        raise UnsupportedAircraft(
            f"{aircraft}: the aerodynamic model re-evaluated from {design.xml_path.name} differs from JSBSim's own "
            f"coefficients by up to {xml_diff[worst]:.3g} ({worst}; tolerance {XML_TOLERANCE:g}): the truth "
            "cannot be taken from its tables")
    # other inputs of the model that moved (configuration the linear truth holds at trim)
    moved = {}
    for prop in tables.leaf_properties():
        if prop.startswith(("fcs/", "gear/", "systems/", "propulsion/")) and prop not in (
                ctl.pitch, ctl.roll, ctl.yaw, *(s for s, _ in ctl.siblings)) and "mag-" not in prop:
            span = float(np.ptp(rec[prop]))
            if span > 1e-9:
                moved[prop] = span

    coefficients = {k: float(v) for k, v in design.derivatives.items()}
    d_mach = mach_slopes(tables, design.state, ctl, design.gains)
    # the tables' Mach slope; on a powered level flight the model's Cm_mach also takes up the thrust's
    # moment changing with speed (jsbsim_vehicle), which this slope leaves out: named apart there
    coefficients.update({f"{k}_mach" + ("_aero" if powered_level(design) and k == "Cm" else ""): v
                         for k, v in d_mach.items()})
    check = _truth_check(truth, design.derivatives, float(m["aileron_start_s"]))
    check["xml_vs_jsbsim_max_abs"] = xml_diff

    # ---- telemetry ----
    air = inst["air_data"]
    clean = {
        "t_s": t, "ax_m_s2": f_sensor[0], "ay_m_s2": f_sensor[1], "az_m_s2": f_sensor[2],
        "p_rad_s": p, "q_rad_s": q, "r_rad_s": r,
        "d1_rad": channels[0], "d2_rad": channels[1], "d3_rad": channels[2], "d4_rad": channels[3],
        "V_m_s": V, "h_m": truth["h_m"].to_numpy(),
        "alpha_vane_rad": alpha + air["alpha_bias_deg"] * DEG, "beta_vane_rad": beta + air["beta_bias_deg"] * DEG,
    }
    telemetry, masks, spec, sigma = make_telemetry(clean, truth, inst["sensors"], inst["faults"], seed, faults)

    # ---- the vehicle file ----
    cm_abs_beta = abs_beta_slope(tables, base, ctl, 2.0 * DEG, design.gains)
    mass = {"mass_kg": trim["inertia/mass-slugs"] * SLUG,
            "Ixx_kg_m2": base["inertia/ixx-slugs_ft2"] * SLUG_FT2, "Iyy_kg_m2": base["inertia/iyy-slugs_ft2"] * SLUG_FT2,
            "Izz_kg_m2": base["inertia/izz-slugs_ft2"] * SLUG_FT2,
            # aerosid's Ixz (integral of x z dm, L = Ixx pdot - Ixz rdot + ...) is minus JSBSim 1.3.3's
            # inertia/ixz-slugs_ft2 (c172x: checked against JSBSim's pdot, rdot; docs/jsbsim.md)
            "Ixz_kg_m2": -base["inertia/ixz-slugs_ft2"] * SLUG_FT2,
            "Ixz_jsbsim_property_kg_m2": base["inertia/ixz-slugs_ft2"] * SLUG_FT2,
            "mass_change_kg": float(mass_kg[-1] - mass_kg[0])}
    rp_in = (base["metrics/aero-rp-x-in"], base["metrics/aero-rp-y-in"], base["metrics/aero-rp-z-in"])
    reference = {"S_m2": S, "chord_m": cbar, "span_m": b, "x_cg_m": base["inertia/cg-x-in"] * INCH,
                 "z_cg_m": base["inertia/cg-z-in"] * INCH, "x_aerorp_m": rp_in[0] * INCH, "z_aerorp_m": rp_in[2] * INCH,
                 "frame": "JSBSim structural frame: x aft, y right, z up, from the structural origin"}
    f_sp = design.modes["omega_sp_rad_s"] / (2 * math.pi)
    cutoff = round(max(2.0, 2.0 * f_sp), 1)
    text = vehicle_toml(design, jsbsim.__version__, mass, reference, offset, surface_names, mixing, limits,
                        vane_noise_rad=inst["sensors"]["vane_noise_deg"] * DEG, cutoff_hz=cutoff,
                        cm_abs_beta=cm_abs_beta, moved=moved, mach_slopes=d_mach)

    # ---- info ----
    tr = design.trim
    info = {
        "simulator": f"JSBSim {jsbsim.__version__}", "aircraft": aircraft, "manoeuvre": "3211",
        "aircraft_xml": str(design.xml_path), "generated": True, "turbulence": air,
        **flight_statistics(truth, telemetry, masks, spec, sigma, t, dt, qbar_pa, alpha, beta, V),
        "propulsion": design.propulsion, "engines": list(design.engines),
        "trim": {**tr.as_dict(), "condition": design.condition_note, "mach": trim["velocities/mach"],
                 "qbar_pa": trim["aero/qbar-psf"] * PSF, "alpha_rad": trim["aero/alpha-rad"],
                 "residual_at_start": [float(v) for v in residual],
                 "thrust_N": float(prop_thrust[0]) if np.ndim(prop_thrust) else float(prop_thrust),
                 "Cm_prop": float(truth["Cm_prop"].iloc[0]), "CX_prop": float(truth["CX_prop"].iloc[0])},
        "reference": {**reference, "aerorp_from_cg_body_m": [
            (base["inertia/cg-x-in"] - rp_in[0]) * INCH, (rp_in[1] - base["inertia/cg-y-in"]) * INCH,
            (base["inertia/cg-z-in"] - rp_in[2]) * INCH]},
        "mass": mass, "accel_offset_m": list(offset),
        "controls": {"pitch": ctl.pitch, "roll": ctl.roll, "yaw": ctl.yaw, "surfaces": surface_names,
                     "mixing": mixing, "static_gains_rad_per_command": design.gains,
                     "limits_rad": {k: list(v) for k, v in design.limits_rad.items()}},
        "modes": design.modes, "design_notes": list(design.notes),
        "noise_sigma": dict(sigma), "vane_bias_rad": {"alpha": air["alpha_bias_deg"] * DEG,
                                                      "beta": air["beta_bias_deg"] * DEG},
        "manoeuvre_windows_s": windows, "manoeuvre_settings": {k: v for k, v in m.items()},
        "hysteresis_takeup_norm": takeup,
        "linearisation": ("linear truth = central differences of the aircraft's own aerodynamic tables at the trim "
                          "point (alpha, beta, surface positions of the trim; zero rates; every other input of the "
                          "model held at its trim value), forces to body axes as JSBSim does, moments transferred "
                          "from the AERORP to the CG; *_0 are the intercepts"),
        "coefficients_aerorp": {k: float(v) for k, v in design.derivatives_rp.items()},
        **generated_flight_average(tables, rec, ctl, design.gains),  # jsbsim_truth_avg
        "inputs_held_at_trim_that_moved": moved,
        "Cm_abs_beta": cm_abs_beta,
        "truth_check": check,
    }
    return SimulatedFlight(case=aircraft, seed=int(seed), effects=(), telemetry=telemetry, truth=truth,
                           coefficients=coefficients, info=info, files={"vehicle.toml": text})
