"""A validation flight flown by JSBSim, an independent flight dynamics engine.

``simulate_jsbsim("c172x", "3211", seed)`` trims JSBSim's c172x in a steady glide
(simulation.toml), flies two mirrored elevator 3-2-1-1s, an aileron doublet and a rudder
doublet at 100 Hz, and returns a :class:`~aerosid.simulation.SimulatedFlight` with

- ``telemetry``: aerosid's raw schema (``RAW_COLUMNS``) plus the air-data vanes
  ``alpha_vane_rad``, ``beta_vane_rad``, with noise and faults;
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

from aerosid.vehicles.rigid_body import lever_arm_acceleration
from aerosid.simulation import SimulatedFlight
from aerosid.simulation.case import FaultSpec
from aerosid.simulation.jsbsim_tables import AeroTables, body_coefficients
from aerosid.simulation.sensors import IMU_COLUMNS, RAW_COLUMNS, apply_faults
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
VANE_COLUMNS = ["alpha_vane_rad", "beta_vane_rad"]
TELEMETRY_COLUMNS = RAW_COLUMNS + VANE_COLUMNS

# unit conversions (exact definitions)
FT = 0.3048                    # m
INCH = 0.0254                  # m
LBF = 4.4482216152605          # N
SLUG = LBF / FT                # kg (14.5939...)
SLUG_FT2 = SLUG * FT * FT      # kg m^2
PSF = LBF / (FT * FT)          # Pa
SLUG_FT3 = SLUG / FT**3        # kg/m^3
DEG = math.pi / 180.0


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
    fdm = jsbsim.FGFDMExec(jsbsim.get_default_root_dir())
    fdm.set_debug_level(0)
    if not fdm.load_model(sim_cfg["jsbsim"]["model"]):
        raise RuntimeError(f"JSBSim could not load {sim_cfg['jsbsim']['model']!r}")
    if throttle is not None:
        fdm.disable_output()  # the trim initialises JSBSim many times (c172x's output file, one error each)
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


def _fly(fdm, t: np.ndarray, inputs: dict[str, np.ndarray], record: list[str] = _RECORD,
         progress=None) -> dict[str, np.ndarray]:
    """Fly the input increments on top of the current (trimmed) commands; the properties
    `record` at every sample.  progress: optional callback progress("fly", fraction)."""
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
    if np.max(np.abs(rec["simulation/sim-time-sec"] - rec["simulation/sim-time-sec"][0] - t)) > 1e-6:
        raise RuntimeError("JSBSim time does not follow the sample grid")
    return rec


# --------------------------------------------------------------------------------------
# truth
# --------------------------------------------------------------------------------------

_LINEAR_VARS = ["alpha", "beta", "delta_p", "delta_r", "delta_y", "p_hat", "q_hat", "r_hat", "alpha_dot_hat"]


def _linearise(tables: AeroTables, point: dict, arm_ft, cbar_ft, span_ft) -> dict[str, dict[str, float]]:
    """Derivatives of CA, CY, CN and the moment coefficients (about the CG and the
    AERORP) at the trim point by central differences of c172x's own tables."""

    def evaluate(x):
        c = tables.coefficients(x["alpha"], x["beta"], x["delta_p"], x["delta_r"], x["delta_y"],
                                x["p_hat"], x["q_hat"], x["r_hat"], x["alpha_dot_hat"])
        return {k: float(v) for k, v in body_coefficients(c, x["alpha"], x["beta"], arm_ft, cbar_ft, span_ft).items()}

    base = evaluate(point)
    steps = {"alpha": 1e-4, "beta": 1e-4, "delta_p": 1e-4, "delta_r": 1e-4, "delta_y": 1e-4,
             "p_hat": 1e-4, "q_hat": 1e-4, "r_hat": 1e-4, "alpha_dot_hat": 1e-4}
    deriv = {}
    for v in _LINEAR_VARS:
        hi, lo = dict(point), dict(point)
        hi[v] += steps[v]
        lo[v] -= steps[v]
        ch, cl = evaluate(hi), evaluate(lo)
        deriv[v] = {k: (ch[k] - cl[k]) / (2 * steps[v]) for k in base}
    return {"value": base, "d": deriv}


_LINEAR_MODEL = {  # the regressors of each coefficient's linear model
    "CN": ["alpha", "q_hat", "delta_p", "alpha_dot_hat"],
    "CA": ["alpha", "delta_p"],
    "Cm": ["alpha", "q_hat", "delta_p", "alpha_dot_hat"],
    "CY": ["beta", "p_hat", "r_hat", "delta_r", "delta_y"],
    "Cl": ["beta", "p_hat", "r_hat", "delta_r", "delta_y"],
    "Cn": ["beta", "p_hat", "r_hat", "delta_r", "delta_y"],
}
_VAR_SUFFIX = {"alpha": "alpha", "beta": "beta", "delta_p": "delta_p", "delta_r": "delta_r", "delta_y": "delta_y",
               "p_hat": "p", "q_hat": "q", "r_hat": "r", "alpha_dot_hat": "alpha_dot"}


def _coefficient_table(lin: dict, point: dict, moment: str = "cg") -> dict[str, float]:
    """The linear truth: derivatives and intercepts (so that the linear model passes
    through the trim point).  moment="rp": the moments about the AERORP instead."""
    out = {}
    for coef, regs in _LINEAR_MODEL.items():
        key = coef if (moment == "cg" or coef in ("CN", "CA", "CY")) else f"{coef}_rp"
        intercept = lin["value"][key]
        for r in regs:
            d = lin["d"][r][key]
            out[f"{coef}_{_VAR_SUFFIX[r]}"] = d
            intercept -= d * point[r]
        out[f"{coef}_0"] = intercept
    out["Cm_q_plus_alpha_dot"] = out["Cm_q"] + out["Cm_alpha_dot"]
    return out


def _regressors(truth: pd.DataFrame, names: list[str]) -> np.ndarray:
    cols = {"alpha": "alpha_rad", "beta": "beta_rad", "delta_p": "delta_p_rad", "delta_r": "delta_r_rad",
            "delta_y": "delta_y_rad", "p_hat": "p_hat", "q_hat": "q_hat", "r_hat": "r_hat",
            "alpha_dot_hat": "alpha_dot_hat"}
    return np.column_stack([np.ones(len(truth))] + [truth[cols[n]].to_numpy() for n in names])


def linear_prediction(truth: pd.DataFrame, coefficients: dict, coef: str) -> np.ndarray:
    """A coefficient (CN, CA, Cm, CY, Cl, Cn) of the truth frame predicted by the linear truth."""
    regs = _LINEAR_MODEL[coef]
    X = _regressors(truth, regs)
    beta = np.array([coefficients[f"{coef}_0"]] + [coefficients[f"{coef}_{_VAR_SUFFIX[r]}"] for r in regs])
    return X @ beta


def _fit(truth: pd.DataFrame, table: dict, coef: str, regs: list[str], mask: np.ndarray,
         extra: dict[str, np.ndarray] | None = None) -> dict:
    X = _regressors(truth, regs)[mask]
    names = [f"{coef}_0"] + [f"{coef}_{_VAR_SUFFIX[r]}" for r in regs]
    for k, v in (extra or {}).items():
        X = np.column_stack([X, v[mask]])
        names.append(k)
    y = truth[coef].to_numpy()[mask]
    sol, *_ = np.linalg.lstsq(X, y, rcond=None)
    resid = y - X @ sol
    return {
        "regressors": ["1"] + regs + list(extra or {}),
        "n_samples": int(mask.sum()),
        "fit": {n: float(v) for n, v in zip(names, sol)},
        "table": {n: float(table[n]) for n in names if n in table},
        "rel_diff": {n: float((v - table[n]) / table[n]) for n, v in zip(names, sol)
                     if n in table and not n.endswith("_0") and table[n] != 0},
        "rms_residual": float(np.sqrt(np.mean(resid ** 2))),
        "std_signal": float(np.std(y)),
    }


def _truth_check(truth: pd.DataFrame, table: dict, t_lateral_s: float) -> dict:
    """Least-squares fits of the noise-free truth coefficients (about the CG) next to
    the transferred table values: Cm on [1, α, q̂, δp, α̇̂] and CN on [1, α, q̂, δp]
    over the longitudinal part of the flight (before the first lateral manoeuvre),
    over the whole flight, and over the whole flight with |β| as an extra regressor
    (c172x's drag grows with |β| and the AERORP sits 0.59 m above the CG, so the
    lateral manoeuvres move Cm about the CG by ~0.067 |β|); Cl and Cn on
    [1, β, p̂, r̂, δr, δy] over the whole flight."""
    t = truth["t_s"].to_numpy()
    lon = t < t_lateral_s
    every = np.ones(len(t), dtype=bool)
    abs_beta = {"Cm_abs_beta": np.abs(truth["beta_rad"].to_numpy())}
    m_regs = ["alpha", "q_hat", "delta_p", "alpha_dot_hat"]
    n_regs = ["alpha", "q_hat", "delta_p"]
    lat = ["beta", "p_hat", "r_hat", "delta_r", "delta_y"]
    return {
        "longitudinal_window_s": [float(t[0]), float(t_lateral_s)],
        "Cm": _fit(truth, table, "Cm", m_regs, lon),
        "CN": _fit(truth, table, "CN", n_regs, lon),
        "Cm_whole_flight": _fit(truth, table, "Cm", m_regs, every),
        "Cm_whole_flight_abs_beta": _fit(truth, table, "Cm", m_regs, every, abs_beta),
        "CN_whole_flight": _fit(truth, table, "CN", n_regs, every),
        "Cl": _fit(truth, table, "Cl", lat, every),
        "Cn": _fit(truth, table, "Cn", lat, every),
    }



def sensor_sigma(sens: dict) -> dict[str, float]:
    """1-sigma noise per telemetry channel from a [sensors] table (simulation.toml)."""
    sigma = dict(zip(IMU_COLUMNS, (*sens["accel_noise_m_s2"], *(g * DEG for g in sens["gyro_noise_deg_s"]))))
    sigma.update({f"d{i}_rad": sens["surface_noise_deg"] * DEG for i in range(1, 5)})
    sigma.update({"V_m_s": sens["V_noise_m_s"], "h_m": sens["h_noise_m"],
                  "alpha_vane_rad": sens["vane_noise_deg"] * DEG, "beta_vane_rad": sens["vane_noise_deg"] * DEG})
    return sigma


def make_telemetry(clean: dict[str, np.ndarray], truth: pd.DataFrame, sens: dict, fcfg: dict, seed: int,
                   faults: bool):
    """Noise ([sensors]) and faults ([faults]) on the clean signals: each channel's noise
    from its own child of SeedSequence(seed).  Adds the fault masks (fault_*) and the
    noise actually added (noise_*) to `truth`.  Returns (telemetry, masks, FaultSpec, sigma)."""
    t = clean["t_s"]
    n = len(t)
    sigma = sensor_sigma(sens)
    channels = TELEMETRY_COLUMNS[1:]
    children = np.random.SeedSequence(seed).spawn(2 + len(channels))
    rng_drop, rng_out = np.random.default_rng(children[0]), np.random.default_rng(children[1])
    noisy = {"t_s": t.copy()}
    for child, col in zip(children[2:], channels):
        noisy[col] = clean[col] + sigma[col] * np.random.default_rng(child).standard_normal(n)
    spec = FaultSpec(
        dropout_rate_per_s=fcfg["dropout_rate_per_s"], dropout_length_s=tuple(fcfg["dropout_length_s"]),
        dropout_nan_fraction=fcfg["dropout_nan_fraction"], outlier_probability=fcfg["outlier_probability"],
        outlier_size_sigma=tuple(fcfg["outlier_size_sigma"]), sync_gap_at=fcfg["sync_gap_at"],
        sync_gap_s=fcfg["sync_gap_s"])
    if not faults:
        spec = spec.without_faults()
    sigma_imu = np.array([sigma[c] for c in IMU_COLUMNS])
    telemetry, masks = apply_faults({c: noisy[c] for c in RAW_COLUMNS}, sigma_imu, spec, rng_drop, rng_out)
    keep = ~masks["dropout_missing_row"].to_numpy()
    nan_rows = masks["dropout_nan"].to_numpy()
    for col in VANE_COLUMNS:
        v = noisy[col].copy()
        v[nan_rows] = np.nan
        telemetry[col] = v[keep]
    telemetry = telemetry[TELEMETRY_COLUMNS]
    for col in masks.columns[1:]:
        truth[f"fault_{col}"] = masks[col].to_numpy()
    for col in channels:
        truth[f"noise_{col}"] = noisy[col] - clean[col]
    return telemetry, masks, spec, sigma


def rates_at_the_moments(x: np.ndarray, x_dot: np.ndarray, dt: float) -> np.ndarray:
    """Body rates re-timed to the instant of the sample's moments.

    JSBSim integrates the body rates with rectangular Euler (its default
    simulation/integrator/rate/rotational = 1): x[k+1] = x[k] + dt x_dot[k], where
    x_dot[k] comes from the moments of sample k.  Those moments therefore act at
    t_k + dt/2 as far as the rates are concerned: the logged rates run half a step late
    relative to the logged moments and accelerations (a derivative of the logged q is
    (q_dot[k-1] + q_dot[k])/2, not q_dot[k]; docs/jsbsim.md).  The rate at t_k + dt/2 is
    exactly x[k] + dt/2 x_dot[k] (x is linear over the step); as the gyros' reading at
    sample k, its derivative matches the moment of sample k."""
    return x + 0.5 * dt * x_dot

def state_columns(rec: dict, t: np.ndarray, dt: float, accel_offset_m) -> tuple[dict, np.ndarray]:
    """The truth columns every JSBSim flight shares, from its record: air data, attitude, the
    gyros' rates at the instant of the sample's moments (JSBSim's Euler step logs them half a
    step late, :func:`rates_at_the_moments`; the state JSBSim's aerodynamics used stays in
    p/q/r_state_rad_s), angular accelerations, the specific force at the CG (all external
    non-gravitational forces / mass: JSBSim's forces/fb*-total are aero + propulsion + ground +
    external) and at the accelerometer (offset [m], body axes), alpha, beta, alpha-dot.
    Returns (columns in the truth frame's order, mass [kg] per sample)."""
    mass_kg = rec["inertia/mass-slugs"] * SLUG
    xdot = [rec[f"accelerations/{a}dot-rad_sec2"] for a in "pqr"]
    state = [rec[f"velocities/{a}-rad_sec"] for a in "pqr"]
    p, q, r = (rates_at_the_moments(x, xd, dt) for x, xd in zip(state, xdot))
    f_cg = [rec[f"forces/fb{a}-total-lbs"] * LBF / mass_kg for a in "xyz"]
    f_sensor = [f + lv for f, lv in zip(f_cg, lever_arm_acceleration(p, q, r, *xdot, accel_offset_m))]
    cols = {
        "t_s": t,
        "h_m": rec["position/h-sl-ft"] * FT, "V_m_s": rec["velocities/vt-fps"] * FT, "mach": rec["velocities/mach"],
        "qbar_pa": rec["aero/qbar-psf"] * PSF,
        "rho_kg_m3": rec["atmosphere/rho-slugs_ft3"] * SLUG_FT3, "g_m_s2": rec["accelerations/gravity-ft_sec2"] * FT,
        "phi_rad": rec["attitude/phi-rad"], "theta_rad": rec["attitude/theta-rad"], "psi_rad": rec["attitude/psi-rad"],
        "p_rad_s": p, "q_rad_s": q, "r_rad_s": r,
        "p_state_rad_s": state[0], "q_state_rad_s": state[1], "r_state_rad_s": state[2],
        "p_dot_rad_s2": xdot[0], "q_dot_rad_s2": xdot[1], "r_dot_rad_s2": xdot[2],
        "ax_cg_m_s2": f_cg[0], "ay_cg_m_s2": f_cg[1], "az_cg_m_s2": f_cg[2],
        "ax_sensor_m_s2": f_sensor[0], "ay_sensor_m_s2": f_sensor[1], "az_sensor_m_s2": f_sensor[2],
        "alpha_rad": rec["aero/alpha-rad"], "beta_rad": rec["aero/beta-rad"],
        "alpha_dot_rad_s": rec["aero/alphadot-rad_sec"],
    }
    return cols, mass_kg


def coefficient_columns(rec: dict, S_ft2: float, cbar_ft: float, b_ft: float) -> dict:
    """The aerodynamic force and moment coefficients (moments about the CG) and the
    propulsive ones, non-dimensionalised alike (the accelerometers and gyros feel both)."""
    qS_lbs = rec["aero/qbar-psf"] * S_ft2
    return {
        "CA": -rec["forces/fbx-aero-lbs"] / qS_lbs, "CY": rec["forces/fby-aero-lbs"] / qS_lbs,
        "CN": -rec["forces/fbz-aero-lbs"] / qS_lbs,
        "Cl": rec["moments/l-aero-lbsft"] / (qS_lbs * b_ft), "Cm": rec["moments/m-aero-lbsft"] / (qS_lbs * cbar_ft),
        "Cn": rec["moments/n-aero-lbsft"] / (qS_lbs * b_ft),
        "CX_prop": rec["forces/fbx-prop-lbs"] / qS_lbs, "CZ_prop": rec["forces/fbz-prop-lbs"] / qS_lbs,
        "Cl_prop": rec["moments/l-prop-lbsft"] / (qS_lbs * b_ft),
        "Cm_prop": rec["moments/m-prop-lbsft"] / (qS_lbs * cbar_ft),
        "Cn_prop": rec["moments/n-prop-lbsft"] / (qS_lbs * b_ft),
    }


# --------------------------------------------------------------------------------------
# the flight
# --------------------------------------------------------------------------------------

def simulate_jsbsim(aircraft: str = "c172x", manoeuvre: str = "3211", seed: int = 0, *,
                    faults: bool = True, progress=None, input_table: pd.DataFrame | None = None) -> SimulatedFlight:
    """Fly JSBSim's `aircraft` through `manoeuvre`; noise and faults from `seed`.

    c172x flies its hand-written simulation.toml; any other aircraft of the jsbsim
    package a generated design, with its vehicle file in ``flight.files`` (raises
    aerosid.simulation.jsbsim_design.UnsupportedAircraft, a ValueError, when it cannot).
    progress: an optional callback progress(stage, fraction) (the CLI's display)."""
    if manoeuvre not in MANOEUVRES:
        raise ValueError(f"unknown manoeuvre {manoeuvre!r}; choices: {', '.join(MANOEUVRES)}")
    if aircraft not in SUPPORTED_AIRCRAFT:
        from aerosid.simulation.jsbsim_aircraft import simulate_aircraft

        return simulate_aircraft(aircraft, seed, faults=faults, progress=progress, input_table=input_table)
    _check_names(aircraft, manoeuvre)
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
    deg = 1.0 / DEG
    check = _truth_check(truth, table_cg, float(m["aileron_start_s"]))
    trim_alpha = trim["aero/alpha-rad"]
    info = {
        "simulator": f"JSBSim {jsbsim.__version__}", "aircraft": model, "manoeuvre": manoeuvre,
        "aircraft_xml": str(xml_path),
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
                        "h_m": sens["h_noise_m"], "vane_rad": sens["vane_noise_deg"] * DEG},
        "vane_bias_rad": {"alpha": air["alpha_bias_deg"] * DEG, "beta": air["beta_bias_deg"] * DEG},
        "manoeuvre_windows_s": windows,
        "manoeuvre_settings": dict(m),
        "hysteresis_takeup_norm": takeup,
        "linearisation": ("linear truth = central differences of c172x's own aerodynamic tables at the trim point "
                          "(alpha, beta, surface positions of the trim; zero rates), forces to body axes as JSBSim "
                          "does, moments transferred from the AERORP to the CG; *_0 are the intercepts"),
        "coefficients_aerorp": {k: float(v) for k, v in table_rp.items()},
        "coefficients_extra_note": "CN_q, CN_alpha_dot, CA_*, CY_p, CY_r, CY_delta_r: also in c172x's model",
        "surfaces": {"d1": "fcs/elevator-pos-rad", "d2": "fcs/left-aileron-pos-rad",
                     "d3": "fcs/right-aileron-pos-rad", "d4": "fcs/rudder-pos-rad",
                     "delta_r": "fcs/effective-aileron-pos = (d2 - d3)/2"},
        "truth_check": check,
    }
    return SimulatedFlight(case=aircraft, seed=int(seed), effects=(), telemetry=telemetry, truth=truth,
                           coefficients=coefficients, info=info)


def flight_statistics(truth, telemetry, masks, spec, sigma, t, dt, qbar_pa, alpha, beta, V) -> dict:
    """The part of a JSBSim flight's info every flight shares: sizes, faults, ranges of the
    flight condition and the pitch-plane signal-to-noise ratios."""
    deg = 1.0 / DEG
    return {
        "n_samples": int(len(t)), "sample_rate_hz": 1.0 / dt, "duration_s": float(t[-1]),
        "n_telemetry_rows": int(len(telemetry)),
        "n_dropout": int(masks["dropout"].sum()),
        "n_outliers": int(sum(masks[f"outlier_{c}"].sum() for c in IMU_COLUMNS)),
        "sync_gap_s": float(spec.sync_gap_s),
        "mach_min": float(truth["mach"].min()), "mach_max": float(truth["mach"].max()),
        "h_min_m": float(truth["h_m"].min()), "h_max_m": float(truth["h_m"].max()),
        "qbar_min_pa": float(np.min(qbar_pa)), "qbar_max_pa": float(np.max(qbar_pa)),
        "alpha_min_deg": float(np.min(alpha) * deg), "alpha_max_deg": float(np.max(alpha) * deg),
        "beta_min_deg": float(np.min(beta) * deg), "beta_max_deg": float(np.max(beta) * deg),
        "phi_min_deg": float(truth["phi_rad"].min() * deg), "phi_max_deg": float(truth["phi_rad"].max() * deg),
        "V_min_m_s": float(np.min(V)), "V_max_m_s": float(np.max(V)),
        "snr": {
            "az": float(truth["az_sensor_m_s2"].std() / sigma["az_m_s2"]),
            "q": float(truth["q_rad_s"].std() / sigma["q_rad_s"]),
            "ax": float(truth["ax_sensor_m_s2"].std() / sigma["ax_m_s2"]),
        },
    }
