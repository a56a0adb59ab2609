"""A validation flight flown by JSBSim, an independent flight dynamics engine.

``simulate_jsbsim("c172x", "3211", seed)`` trims JSBSim's c172x in a steady glide
(simulation.toml), flies two mirrored elevator 3-2-1-1s, an aileron doublet and a rudder
doublet at 100 Hz, and returns a :class:`~aerosid.simulation.SimulatedFlight` with

- ``telemetry``: aerosid's raw schema (``RAW_COLUMNS``) plus the air-data vanes
  ``alpha_vane_rad``, ``beta_vane_rad`` and the INS attitude ``phi_rad``, ``theta_rad``,
  with noise and faults;
- ``truth``: the noise-free per-sample state, the surface positions and the
  aerodynamic force and moment coefficients about the CG in body axes, taken
  from JSBSim's own aerodynamic forces and moments;
- ``coefficients``: the linear truth, linearised at the trim point from c172x's
  own aerodynamic tables (read from its XML) and transferred from JSBSim's
  aerodynamic reference point (AERORP) to the CG.

Everything about the flight (trim condition, loading, manoeuvre timing and
amplitudes, noise, faults) is in ``aerosid/data/<aircraft>/simulation.toml``;
the accelerometer position is in ``vehicle.toml``.  See docs/jsbsim.md.

jsbsim is an optional dependency (``pip install "aerosid[jsbsim]"``); it is
imported only when a flight is simulated.
"""
from __future__ import annotations

import math
import os
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd

from aerosid.simulation import SimulatedFlight
from aerosid.simulation.jsbsim_columns import (DEG, FT, INCH, INTEGRATOR_KEY, LBF, PSF, SLUG, SLUG_FT2, SLUG_FT3,
                                               TELEMETRY_COLUMNS,
                                               coefficient_columns, make_telemetry, state_columns)
from aerosid.simulation.jsbsim_tables import AeroTables, body_coefficients
from aerosid.simulation.jsbsim_truth import _coefficient_table, _linearise, _truth_check, flight_statistics
from aerosid.simulation.jsbsim_turbulence import checked_turbulence, start_turbulence
from aerosid.vehicles.vehicle import DATA_DIR

__all__ = ["JSBSimUnavailable", "simulate_jsbsim", "SUPPORTED_AIRCRAFT", "GENERATED_AIRCRAFT", "MANOEUVRES", "AeroTables",
           "TELEMETRY_COLUMNS"]

# aircraft with a hand-written flight (aerosid/data/<aircraft>/simulation.toml); any other
# aircraft of the jsbsim package is flown with a generated design and vehicle file
# (aerosid.simulation.jsbsim_aircraft), when it trims; GENERATED_AIRCRAFT are the ones
# checked (tests, bench/bench_generalisation.py, docs/jsbsim.md)
SUPPORTED_AIRCRAFT = ("c172x",)
GENERATED_AIRCRAFT = ("pa28", "OV10", "T37", "F4N")
MANOEUVRES = ("3211",)


class JSBSimUnavailable(ImportError):
    """The optional jsbsim package is not installed."""


def _import_jsbsim():
    os.environ["JSBSIM_DEBUG"] = "0"
    try:
        import jsbsim
    except ImportError as exc:
        raise JSBSimUnavailable('jsbsim is not installed: pip install "aerosid[jsbsim]"') from exc
    return jsbsim


# --------------------------------------------------------------------------------------
# configuration
# --------------------------------------------------------------------------------------

def _check_names(aircraft: str, manoeuvre: str) -> None:
    if aircraft not in SUPPORTED_AIRCRAFT:
        raise ValueError(f"JSBSim aircraft {aircraft!r} is not supported; supported: {', '.join(SUPPORTED_AIRCRAFT)}")
    if manoeuvre not in MANOEUVRES:
        raise ValueError(f"unknown manoeuvre {manoeuvre!r}; choices: {', '.join(MANOEUVRES)}")


def load_jsbsim_config(aircraft: str = "c172x") -> tuple[dict, dict]:
    """(simulation.toml, vehicle.toml) of a supported aircraft as dicts."""
    _check_names(aircraft, MANOEUVRES[0])
    folder = DATA_DIR / aircraft
    sim = tomllib.loads((folder / "simulation.toml").read_text())
    veh = tomllib.loads((folder / "vehicle.toml").read_text())
    return sim, veh


def _takeup_steps(xml_root: ET.Element, outputs: list[str], trim_sum: float) -> list[float]:
    """Hysteresis take-up command steps [normalised, in the direction of the return]
    for the surfaces driven by one pilot command.

    Each actuator's hysteresis (width w) leaves its surface w/2 short of the trim
    position when the command returns to trim.  Overshooting the trim command by
    w/2 / gain (gain [rad per unit command] of the surface's aerosurface_scale on
    the side the trim sits on) and returning puts the surface back exactly.  Two
    surfaces on one command with different gains (c172x's ailerons: 20 deg on one
    side, 15 deg on the other) need two steps: the larger overshoot first (the
    low-gain surface lands exactly, the other goes past), then a step back by the
    smaller one (the high-gain surface returns exactly; the other one's input
    moves by less than w/2 and it stays put)."""
    fcs = xml_root.find("flight_control")
    needed = []
    for output in outputs:
        act = next((a for a in fcs.iter("actuator") if (a.findtext("output") or "").strip() == output), None)
        if act is None or not act.findtext("hysteresis_width"):
            continue
        width = float(act.findtext("hysteresis_width"))
        src = act.findtext("input").strip()
        scale = next(sc for sc in fcs.iter("aerosurface_scale") if sc.get("name") == src)
        sign = -1.0 if scale.findtext("input").strip().startswith("-") else 1.0
        gain = float(scale.findtext("gain") or 1.0)
        rng = scale.find("range")
        side = sign * trim_sum
        g = (float(rng.findtext("max")) if side >= 0 else -float(rng.findtext("min"))) * gain
        needed.append(0.5 * width / g)
    if not needed:
        return []
    hi, lo = max(needed), min(needed)
    return [hi] if math.isclose(hi, lo, rel_tol=1e-9) else [hi, -lo]


def _schedule(t: np.ndarray, m: dict, takeup: dict) -> tuple[dict[str, np.ndarray], dict]:
    """Command increments on top of the trimmed commands [normalised], per input."""
    elev = np.zeros_like(t)
    ail = np.zeros_like(t)
    rud = np.zeros_like(t)
    windows = {}
    # elevator 3-2-1-1 sequences (each start with the sign of its pattern)
    takeups = []
    for k, (start, sign) in enumerate(zip(m["elevator_starts_s"], m["elevator_signs"])):
        s = float(start)
        for units, amp in zip(m["elevator_units"], m["elevator_amplitudes_norm"]):
            end = s + units * float(m["elevator_unit_s"])
            elev[(t >= s - 1e-9) & (t < end - 1e-9)] = sign * amp
            s = end
        windows[f"elevator_3211_{k + 1}"] = [float(start), round(s, 9)]
        takeups.append(("elevator", elev, s, sign * m["elevator_amplitudes_norm"][-1]))
    # aileron and rudder doublets
    for name, arr in (("aileron", ail), ("rudder", rud)):
        a0, half, amp = float(m[f"{name}_start_s"]), float(m[f"{name}_half_s"]), float(m[f"{name}_amplitude_norm"])
        arr[(t >= a0 - 1e-9) & (t < a0 + half - 1e-9)] = amp
        arr[(t >= a0 + half - 1e-9) & (t < a0 + 2 * half - 1e-9)] = -amp
        windows[f"{name}_doublet"] = [a0, a0 + 2 * half]
        takeups.append((name, arr, a0 + 2 * half, -amp))
    # finite input rise time (simulation.toml elevator_rise_s, ...): every step of the
    # manoeuvre's command becomes a linear ramp of that duration starting at the step
    # time (a causal moving average over the rise time: a pilot or an input box does
    # not step the stick instantly, and a ramp keeps the pitch acceleration free of
    # jumps).  The hysteresis take-up below starts when the last ramp has ended.
    dt = float(t[1] - t[0]) if len(t) > 1 else 1.0
    rise = {}
    for name, arr in (("elevator", elev), ("aileron", ail), ("rudder", rud)):
        k = int(round(float(m.get(f"{name}_rise_s", 0.0)) / dt))
        rise[name] = k * dt if k > 1 else 0.0
        if k > 1:
            arr[:] = np.convolve(arr, np.full(k, 1.0 / k))[:len(arr)]
    takeups = [(name, arr, end + rise[name], amp) for name, arr, end, amp in takeups]
    # hysteresis take-up after each manoeuvre (see simulation.toml, _takeup_steps)
    dur = float(m["hysteresis_takeup_s"])
    for name, arr, end, amp in takeups:
        for j, step in enumerate(takeup.get(name, []) if dur > 0.0 else []):
            t0 = end + j * dur
            arr[(t >= t0 - 1e-9) & (t < t0 + dur - 1e-9)] = -math.copysign(1.0, amp) * step
        if takeup.get(name) and dur > 0.0:
            windows[f"{name}_hysteresis_takeup_{len([w for w in windows if w.startswith(name + '_hyst')]) + 1}"] = \
                [round(end, 9), round(end + len(takeup[name]) * dur, 9)]
    return {"elevator": elev, "aileron": ail, "rudder": rud}, windows


# --------------------------------------------------------------------------------------
# flying JSBSim
# --------------------------------------------------------------------------------------

#: Properties every JSBSim flight records (the hand-written c172x one and the generated ones).
COMMON_PROPERTIES = [
    "simulation/sim-time-sec",
    "position/h-sl-ft", "velocities/vt-fps", "velocities/mach", "aero/qbar-psf", "atmosphere/rho-slugs_ft3",
    "attitude/phi-rad", "attitude/theta-rad", "attitude/psi-rad",
    "velocities/p-rad_sec", "velocities/q-rad_sec", "velocities/r-rad_sec",
    "velocities/p-aero-rad_sec", "velocities/q-aero-rad_sec", "velocities/r-aero-rad_sec",
    "accelerations/pdot-rad_sec2", "accelerations/qdot-rad_sec2", "accelerations/rdot-rad_sec2",
    "forces/fbx-total-lbs", "forces/fby-total-lbs", "forces/fbz-total-lbs",
    "forces/fbx-aero-lbs", "forces/fby-aero-lbs", "forces/fbz-aero-lbs",
    "forces/fbx-prop-lbs", "forces/fby-prop-lbs", "forces/fbz-prop-lbs",
    "moments/l-aero-lbsft", "moments/m-aero-lbsft", "moments/n-aero-lbsft",
    "moments/l-prop-lbsft", "moments/m-prop-lbsft", "moments/n-prop-lbsft",
    "inertia/mass-slugs", "inertia/cg-x-in", "inertia/cg-y-in", "inertia/cg-z-in",
]

_RECORD = [
    *COMMON_PROPERTIES,
    "aero/alpha-rad", "aero/beta-rad", "aero/alphadot-rad_sec",
    "fcs/elevator-pos-rad", "fcs/left-aileron-pos-rad", "fcs/right-aileron-pos-rad", "fcs/rudder-pos-rad",
    "fcs/effective-aileron-pos", "fcs/elevator-control",
    "fcs/elevator-cmd-norm", "fcs/aileron-cmd-norm", "fcs/rudder-cmd-norm",
    "accelerations/gravity-ft_sec2", "aero/stall-hyst-norm", "aero/h_b-mac-ft", "fcs/flap-pos-deg",
    "propulsion/engine/thrust-lbs",
]


def _trimmed_fdm(jsbsim, sim_cfg: dict, throttle: float | None = None):
    """JSBSim's c172x trimmed as simulation.toml says (JSBSim's own trim: the throttle holds
    the speed on the configured glide path), or, with `throttle` [0..1, 0 = idle], a steady
    glide at that fixed throttle: the flight-path angle is then solved for
    (aerosid.simulation.jsbsim_trim.trim, mode "glide"), the speed and height stay."""
    from aerosid.simulation.jsbsim_trim import new_fdm
    fdm = new_fdm(jsbsim)
    if not fdm.load_model(sim_cfg["jsbsim"]["model"]):
        raise RuntimeError(f"JSBSim could not load {sim_cfg['jsbsim']['model']!r}")
    fdm.disable_output()  # the output files c172x's XML asks for are not the flight's record
    for i, w in enumerate(sim_cfg["loading"]["pointmass_weights_lbs"]):
        fdm[f"inertia/pointmass-weight-lbs[{i}]"] = float(w)
    fdm.set_dt(float(sim_cfg["jsbsim"]["dt_s"]))
    tr = sim_cfg["trim"]
    fdm["ic/h-sl-ft"] = tr["h_m"] / FT
    fdm["ic/vt-fps"] = tr["V_m_s"] / FT
    fdm["ic/gamma-deg"] = tr["gamma_deg"]
    fdm["ic/psi-true-deg"] = tr["heading_deg"]
    fdm["ic/lat-geod-deg"] = tr["latitude_deg"]
    fdm["ic/long-gc-deg"] = tr["longitude_deg"]
    fdm["fcs/flap-cmd-norm"] = 0.0
    fdm["propulsion/set-running"] = -1
    fdm.run_ic()
    if throttle is None:
        fdm["simulation/do_simple_trim"] = 1
        return fdm
    from aerosid.simulation.jsbsim_trim import TrimError, trim as fixed_throttle_trim

    fdm["propulsion/set-running"] = -1  # a piston engine set running before the first run_ic stays off
    try:
        fixed_throttle_trim(fdm, tr["h_m"], tr["V_m_s"], "glide", throttle=float(throttle))
    except TrimError as exc:  # a ValueError: the CLI reports it as a bad parameter, no traceback
        raise ValueError(f"the designed input's throttle_cmd_norm {throttle:g}: {exc}") from exc
    return fdm


#: JSBSim's integrator of the body rates during the flight: 3 = Adams-Bashforth 2 (JSBSim's
#: default, 1 = rectangular Euler, leaves a logged rate and the sample's moment half a step
#: apart: re-timing the rates to the moments then put the gyros dt/2 = 5 ms off the state the
#: aerodynamics used, which inflated F4N's C_m_delta and damping by ~2.5 %,
#: bench/results/attribution.md).  With AB2 the central difference of the logged rates is
#: centred on the sample's moment (to second order) and the rates are the aerodynamics' own.
ROTATIONAL_INTEGRATOR = 3


def _fly(fdm, t: np.ndarray, inputs: dict[str, np.ndarray], record: list[str] = _RECORD,
         progress=None, integrator: int = ROTATIONAL_INTEGRATOR) -> dict[str, np.ndarray]:
    """Fly the input increments on top of the current (trimmed) commands; the properties
    `record` at every sample, the body rates integrated with `integrator` (JSBSim's
    simulation/integrator/rate/rotational, see ROTATIONAL_INTEGRATOR).  progress: optional
    callback progress("fly", fraction)."""
    fdm[INTEGRATOR_KEY] = int(integrator)
    every = max(1, len(t) // 200)
    trim_cmd = {"elevator": fdm["fcs/elevator-cmd-norm"], "aileron": fdm["fcs/aileron-cmd-norm"],
                "rudder": fdm["fcs/rudder-cmd-norm"]}
    out = np.empty((len(t), len(record)))
    get = fdm.get_property_value
    for k in range(len(t)):
        if progress is not None and k % every == 0:
            progress("fly", k / max(len(t) - 1, 1))
        if k > 0:
            # the command for t_k; the FCS, the aerodynamics and the forces of the
            # frame that ends at t_k see it (JSBSim propagates first, then runs the
            # models at the new state: recorded state, positions and forces are
            # all at the same instant)
            for name, prop in (("elevator", "fcs/elevator-cmd-norm"), ("aileron", "fcs/aileron-cmd-norm"),
                               ("rudder", "fcs/rudder-cmd-norm")):
                fdm[prop] = trim_cmd[name] + inputs[name][k]
            fdm.run()
        out[k] = [get(p) for p in record]
    rec = {p: out[:, j] for j, p in enumerate(record)}
    rec[INTEGRATOR_KEY] = np.full(len(t), float(fdm[INTEGRATOR_KEY]))
    if np.max(np.abs(rec["simulation/sim-time-sec"] - rec["simulation/sim-time-sec"][0] - t)) > 1e-6:
        raise RuntimeError("JSBSim time does not follow the sample grid")
    return rec


# --------------------------------------------------------------------------------------
# the flight
# --------------------------------------------------------------------------------------

def simulate_jsbsim(aircraft: str = "c172x", manoeuvre: str = "3211", seed: int = 0, *,
                    faults: bool = True, progress=None, input_table: pd.DataFrame | None = None,
                    turbulence: str = "none") -> SimulatedFlight:
    """Fly JSBSim's `aircraft` through `manoeuvre`; noise, faults and the turbulence (a
    jsbsim_turbulence.TURBULENCE_SEVERITY level; "none": calm air) from `seed`.

    c172x flies its hand-written simulation.toml; any other aircraft of the jsbsim
    package a generated design, with its vehicle file in ``flight.files`` (raises
    aerosid.simulation.jsbsim_design.UnsupportedAircraft, a ValueError, when it cannot).
    progress: an optional callback progress(stage, fraction) (the CLI's display)."""
    if manoeuvre not in MANOEUVRES:
        raise ValueError(f"unknown manoeuvre {manoeuvre!r}; choices: {', '.join(MANOEUVRES)}")
    if aircraft not in SUPPORTED_AIRCRAFT:
        from aerosid.simulation.jsbsim_aircraft import simulate_aircraft

        return simulate_aircraft(aircraft, seed, faults=faults, progress=progress, input_table=input_table,
                                 turbulence=turbulence)
    _check_names(aircraft, manoeuvre)
    checked_turbulence(turbulence)
    jsbsim = _import_jsbsim()
    sim_cfg, veh_cfg = load_jsbsim_config(aircraft)
    model = sim_cfg["jsbsim"]["model"]
    xml_path = Path(jsbsim.get_default_root_dir()) / "aircraft" / model / f"{model}.xml"
    xml_root = ET.parse(xml_path).getroot()
    tables = AeroTables(xml_path)

    # a designed input may fix the throttle (throttle_cmd_norm, e.g. 0 = idle: a power-off glide)
    throttle = None
    if input_table is not None and "throttle_cmd_norm" in input_table.columns:
        throttle = float(input_table["throttle_cmd_norm"].iloc[0])
    fdm = _trimmed_fdm(jsbsim, sim_cfg, throttle)
    dt = float(sim_cfg["jsbsim"]["dt_s"])
    n = int(round(float(sim_cfg["flight"]["duration_s"]) / dt)) + 1
    t = np.arange(n) * dt
    if input_table is not None:  # a designed input (aerosid.simulation.jsbsim_input) sets the duration
        from aerosid.simulation.jsbsim_input import input_time

        t = input_time(input_table, dt)

    # trim state
    trim = {p: fdm[p] for p in _RECORD}
    trim.update({p: fdm[p] for p in ("fcs/pitch-trim-cmd-norm", "fcs/throttle-cmd-norm", "fcs/pitch-trim-sum",
                                     "fcs/roll-trim-sum", "metrics/Sw-sqft", "metrics/cbarw-ft", "metrics/bw-ft",
                                     "metrics/aero-rp-x-in", "metrics/aero-rp-y-in", "metrics/aero-rp-z-in",
                                     "inertia/ixx-slugs_ft2", "inertia/iyy-slugs_ft2", "inertia/izz-slugs_ft2",
                                     "inertia/ixz-slugs_ft2", "inertia/ixy-slugs_ft2", "inertia/iyz-slugs_ft2",
                                     "velocities/u-fps", "velocities/w-fps", "flight-path/gamma-rad")})

    # hysteresis take-up overshoots [normalised command]
    m = sim_cfg["manoeuvres"][manoeuvre]
    takeup = {
        "elevator": _takeup_steps(xml_root, ["fcs/elevator-pos-rad"], trim["fcs/pitch-trim-sum"]),
        "aileron": _takeup_steps(xml_root, ["fcs/left-aileron-pos-rad", "fcs/right-aileron-pos-rad"],
                                 trim["fcs/roll-trim-sum"]),
    }
    inputs, windows = _schedule(t, m, takeup)
    if input_table is not None:
        from aerosid.simulation.jsbsim_input import c172x_inputs

        inputs, windows = c172x_inputs(input_table, t, xml_root, trim), {"designed_input": [0.0, float(t[-1])]}

    air = start_turbulence(fdm, turbulence, seed)
    rec = _fly(fdm, t, inputs, progress=progress)

    # ---- geometry and mass (SI) ----
    S_ft2, cbar_ft, b_ft = trim["metrics/Sw-sqft"], trim["metrics/cbarw-ft"], trim["metrics/bw-ft"]
    S, cbar, b = S_ft2 * FT**2, cbar_ft * FT, b_ft * FT
    rp_in = np.array([trim["metrics/aero-rp-x-in"], trim["metrics/aero-rp-y-in"], trim["metrics/aero-rp-z-in"]])
    cg_in = np.column_stack([rec["inertia/cg-x-in"], rec["inertia/cg-y-in"], rec["inertia/cg-z-in"]])
    # AERORP relative to the CG in body axes [ft] (JSBSim's StructuralToBody: x, z flip)
    arm_ft = ((cg_in[:, 0] - rp_in[0]) / 12.0, (rp_in[1] - cg_in[:, 1]) / 12.0, (cg_in[:, 2] - rp_in[2]) / 12.0)
    arm0_ft = tuple(float(a[0]) for a in arm_ft)
    accel_offset = tuple(float(v) for v in veh_cfg["sensors"]["accel_offset_m"])

    # ---- truth ----
    cols, mass_kg = state_columns(rec, t, dt, accel_offset)
    V, qbar_pa, alpha, beta = cols["V_m_s"], cols["qbar_pa"], cols["alpha_rad"], cols["beta_rad"]
    f_sensor = [cols[f"a{a}_sensor_m_s2"] for a in "xyz"]
    delta_p = rec["fcs/elevator-pos-rad"]
    delta_r = 0.5 * (rec["fcs/left-aileron-pos-rad"] - rec["fcs/right-aileron-pos-rad"])
    delta_y = rec["fcs/rudder-pos-rad"]
    V_fps = rec["velocities/vt-fps"]
    ci2vel, bi2vel = cbar_ft / (2 * V_fps), b_ft / (2 * V_fps)
    truth = pd.DataFrame({
        **cols,
        "delta_p_rad": delta_p, "delta_r_rad": delta_r, "delta_y_rad": delta_y,
        "d1_rad": delta_p, "d2_rad": rec["fcs/left-aileron-pos-rad"], "d3_rad": rec["fcs/right-aileron-pos-rad"],
        "d4_rad": delta_y,
        # the elevator deflection the command asks for (fcs/elevator-control, before the
        # actuator's lag, hysteresis and 0.002 rad bias) and the pilot commands
        "elevator_control_rad": rec["fcs/elevator-control"],
        "elevator_cmd_norm": rec["fcs/elevator-cmd-norm"], "aileron_cmd_norm": rec["fcs/aileron-cmd-norm"],
        "rudder_cmd_norm": rec["fcs/rudder-cmd-norm"],
        "p_hat": rec["velocities/p-aero-rad_sec"] * bi2vel, "q_hat": rec["velocities/q-aero-rad_sec"] * ci2vel,
        "r_hat": rec["velocities/r-aero-rad_sec"] * bi2vel, "alpha_dot_hat": rec["aero/alphadot-rad_sec"] * ci2vel,
        **coefficient_columns(rec, S_ft2, cbar_ft, b_ft),
        "thrust_N": rec["propulsion/engine/thrust-lbs"] * LBF, "mass_kg": mass_kg,
        "x_cg_m": cg_in[:, 0] * INCH,
    })

    # the nonlinear model of the XML at every sample (closed-form check of the truth)
    c_rp = tables.coefficients(alpha, beta, delta_p, rec["fcs/effective-aileron-pos"], delta_y,
                               truth["p_hat"].to_numpy(), truth["q_hat"].to_numpy(), truth["r_hat"].to_numpy(),
                               truth["alpha_dot_hat"].to_numpy(),
                               flaps_deg=rec["fcs/flap-pos-deg"], h_over_b=rec["aero/h_b-mac-ft"],
                               stall_hyst=rec["aero/stall-hyst-norm"])
    c_model = body_coefficients(c_rp, alpha, beta, arm_ft, cbar_ft, b_ft)
    for k in ("CA", "CY", "CN", "Cl", "Cm", "Cn"):
        truth[f"{k}_xml"] = c_model[k]
    truth["Cm_rp"] = c_model["Cm_rp"]
    truth["Cl_rp"] = c_model["Cl_rp"]
    truth["Cn_rp"] = c_model["Cn_rp"]
    truth["CL"] = c_model["CL"]
    truth["CD"] = c_model["CD"]

    # ---- the linear truth at the trim point ----
    point = {"alpha": trim["aero/alpha-rad"], "beta": trim["aero/beta-rad"], "delta_p": trim["fcs/elevator-pos-rad"],
             "delta_r": trim["fcs/effective-aileron-pos"], "delta_y": trim["fcs/rudder-pos-rad"],
             "p_hat": 0.0, "q_hat": 0.0, "r_hat": 0.0, "alpha_dot_hat": 0.0}
    lin = _linearise(tables, point, arm0_ft, cbar_ft, b_ft)
    table_cg = _coefficient_table(lin, point, "cg")
    table_rp = _coefficient_table(lin, point, "rp")
    names = ["CN_0", "CN_alpha", "CN_delta_p", "Cm_0", "Cm_alpha", "Cm_delta_p", "Cm_q", "Cm_alpha_dot",
             "Cm_q_plus_alpha_dot", "CY_0", "CY_beta", "CY_delta_y", "Cl_0", "Cl_beta", "Cl_p", "Cl_r",
             "Cl_delta_r", "Cl_delta_y", "Cn_0", "Cn_beta", "Cn_p", "Cn_r", "Cn_delta_r", "Cn_delta_y"]
    extras = ["CN_q", "CN_alpha_dot", "CA_0", "CA_alpha", "CA_delta_p", "CY_p", "CY_r", "CY_delta_r"]
    coefficients = {k: float(table_cg[k]) for k in names + extras}

    # ---- telemetry: noise and faults ----
    sens, air, fcfg = sim_cfg["sensors"], sim_cfg["air_data"], sim_cfg["faults"]
    clean = {
        "t_s": t,
        "ax_m_s2": f_sensor[0], "ay_m_s2": f_sensor[1], "az_m_s2": f_sensor[2],
        "p_rad_s": truth["p_rad_s"].to_numpy(), "q_rad_s": truth["q_rad_s"].to_numpy(),
        "r_rad_s": truth["r_rad_s"].to_numpy(),
        "d1_rad": truth["d1_rad"].to_numpy(), "d2_rad": truth["d2_rad"].to_numpy(),
        "d3_rad": truth["d3_rad"].to_numpy(), "d4_rad": truth["d4_rad"].to_numpy(),
        "V_m_s": V, "h_m": truth["h_m"].to_numpy(),
        "alpha_vane_rad": alpha + air["alpha_bias_deg"] * DEG,
        "beta_vane_rad": beta + air["beta_bias_deg"] * DEG,
    }
    telemetry, masks, spec, sigma = make_telemetry(clean, truth, sens, fcfg, seed, faults)

    # ---- info ----
    from aerosid.simulation.jsbsim_truth_avg import c172x_flight_average

    deg = 1.0 / DEG
    check = _truth_check(truth, table_cg, float(m["aileron_start_s"]))
    trim_alpha = trim["aero/alpha-rad"]
    info = {
        "simulator": f"JSBSim {jsbsim.__version__}", "aircraft": model, "manoeuvre": manoeuvre,
        "aircraft_xml": str(xml_path), "turbulence": air,
        **flight_statistics(truth, telemetry, masks, spec, sigma, t, dt, qbar_pa, alpha, beta, V),
        "trim": {
            "h_m": trim["position/h-sl-ft"] * FT, "V_m_s": trim["velocities/vt-fps"] * FT,
            "mach": trim["velocities/mach"], "qbar_pa": trim["aero/qbar-psf"] * PSF,
            "rho_kg_m3": trim["atmosphere/rho-slugs_ft3"] * SLUG_FT3,
            "alpha_rad": trim_alpha, "alpha_deg": trim_alpha * deg, "theta_deg": trim["attitude/theta-rad"] * deg,
            "beta_deg": trim["aero/beta-rad"] * deg,
            "elevator_pos_rad": trim["fcs/elevator-pos-rad"], "effective_aileron_pos_rad": trim["fcs/effective-aileron-pos"],
            "rudder_pos_rad": trim["fcs/rudder-pos-rad"],
            "pitch_trim_cmd_norm": trim["fcs/pitch-trim-cmd-norm"], "aileron_cmd_norm": trim["fcs/aileron-cmd-norm"],
            "rudder_cmd_norm": trim["fcs/rudder-cmd-norm"], "throttle_cmd_norm": trim["fcs/throttle-cmd-norm"],
            "thrust_N": trim["propulsion/engine/thrust-lbs"] * LBF,
            "gamma_deg": trim["flight-path/gamma-rad"] * deg,
            "power": ("JSBSim trim (throttle holds the speed on the configured glide path)" if throttle is None
                      else f"glide at fixed throttle {throttle:g} (designed input's throttle_cmd_norm)"),
            "Cm_prop": trim["moments/m-prop-lbsft"] / (trim["aero/qbar-psf"] * S_ft2 * cbar_ft),
            "Cl_prop": trim["moments/l-prop-lbsft"] / (trim["aero/qbar-psf"] * S_ft2 * b_ft),
            "Cn_prop": trim["moments/n-prop-lbsft"] / (trim["aero/qbar-psf"] * S_ft2 * b_ft),
            "CX_prop": trim["forces/fbx-prop-lbs"] / (trim["aero/qbar-psf"] * S_ft2),
        },
        "reference": {"S_m2": S, "chord_m": cbar, "span_m": b,
                      "x_cg_m": trim["inertia/cg-x-in"] * INCH, "z_cg_m": trim["inertia/cg-z-in"] * INCH,
                      "x_aerorp_m": rp_in[0] * INCH, "z_aerorp_m": rp_in[2] * INCH,
                      "aerorp_from_cg_body_m": [a * FT for a in arm0_ft],
                      "frame": "JSBSim structural frame: x aft, y right, z up, from the structural origin"},
        "mass": {"mass_kg": trim["inertia/mass-slugs"] * SLUG,
                 "Ixx_kg_m2": trim["inertia/ixx-slugs_ft2"] * SLUG_FT2, "Iyy_kg_m2": trim["inertia/iyy-slugs_ft2"] * SLUG_FT2,
                 "Izz_kg_m2": trim["inertia/izz-slugs_ft2"] * SLUG_FT2,
                 # aerosid's Ixz (L = Ixx pdot - Ixz rdot + ..., Ixz = integral of x z dm) is
                 # minus JSBSim 1.3.3's inertia/ixz-slugs_ft2 (checked against JSBSim's pdot, rdot)
                 "Ixz_kg_m2": -trim["inertia/ixz-slugs_ft2"] * SLUG_FT2,
                 "Ixz_jsbsim_property_kg_m2": trim["inertia/ixz-slugs_ft2"] * SLUG_FT2,
                 "Ixy_kg_m2": trim["inertia/ixy-slugs_ft2"] * SLUG_FT2, "Iyz_kg_m2": trim["inertia/iyz-slugs_ft2"] * SLUG_FT2,
                 "mass_change_kg": float(mass_kg[-1] - mass_kg[0])},
        "accel_offset_m": list(accel_offset),
        "noise_sigma": {"accel_m_s2": list(sens["accel_noise_m_s2"]),
                        "gyro_rad_s": [g * DEG for g in sens["gyro_noise_deg_s"]],
                        "surface_rad": sens["surface_noise_deg"] * DEG, "V_m_s": sens["V_noise_m_s"],
                        "h_m": sens["h_noise_m"], "vane_rad": sens["vane_noise_deg"] * DEG,
                        "attitude_rad": sigma["phi_rad"]},
        "vane_bias_rad": {"alpha": air["alpha_bias_deg"] * DEG, "beta": air["beta_bias_deg"] * DEG},
        "manoeuvre_windows_s": windows,
        "manoeuvre_settings": dict(m),
        "hysteresis_takeup_norm": takeup,
        "linearisation": ("linear truth = central differences of c172x's own aerodynamic tables at the trim point "
                          "(alpha, beta, surface positions of the trim; zero rates), forces to body axes as JSBSim "
                          "does, moments transferred from the AERORP to the CG; *_0 are the intercepts"),
        "coefficients_aerorp": {k: float(v) for k, v in table_rp.items()},
        **c172x_flight_average(tables, rec, truth, arm_ft, cbar_ft, b_ft),  # jsbsim_truth_avg
        "coefficients_extra_note": "CN_q, CN_alpha_dot, CA_*, CY_p, CY_r, CY_delta_r: also in c172x's model",
        "surfaces": {"d1": "fcs/elevator-pos-rad", "d2": "fcs/left-aileron-pos-rad",
                     "d3": "fcs/right-aileron-pos-rad", "d4": "fcs/rudder-pos-rad",
                     "delta_r": "fcs/effective-aileron-pos = (d2 - d3)/2"},
        "truth_check": check,
    }
    return SimulatedFlight(case=aircraft, seed=int(seed), effects=(), telemetry=telemetry, truth=truth,
                           coefficients=coefficients, info=info)
