"""The flight control system of a JSBSim aircraft seen statically at its trim point, for the
flight design (`jsbsim_design`): the surfaces' gains and travel per pilot command, what the FCS
feeds back from the rates and angles (a yaw damper, a sideslip feedback), and the derivatives
the manoeuvre's steady responses meet with that feedback."""
from __future__ import annotations

import math

import numpy as np

from aerosid.simulation.jsbsim_linear import Controls
from aerosid.simulation.jsbsim_trim import TrimPoint, initialise


def _probe(fdm, point: TrimPoint, commands, props) -> dict[str, float]:
    """Surface properties with the FCS static at `point` and these commands (None: trim)."""
    initialise(fdm, point, commands)
    return {p: fdm[p] for p in props}


def fcs_statics(fdm, point: TrimPoint, controls: Controls) -> tuple[dict, dict]:
    """Static gains d(surface)/d(command) at trim and surface travel over the full
    command range, with the FCS in trim mode (no actuator lag, zero rates)."""
    trim_cmd = np.array([point.elevator_cmd, point.aileron_cmd, point.rudder_cmd])
    surfaces = {"pitch": [controls.pitch], "roll": [controls.roll], "yaw": [controls.yaw]}
    if controls.left_aileron and controls.right_aileron:
        surfaces["roll"] += [controls.left_aileron, controls.right_aileron]
    gains, limits = {}, {}
    eps = 0.02
    for k, axis in enumerate(("pitch", "roll", "yaw")):
        main = surfaces[axis][0]
        sib = [s for s, c in controls.siblings if c == main]
        props = list(dict.fromkeys(surfaces[axis] + sib))
        hi, lo = trim_cmd.copy(), trim_cmd.copy()
        hi[k] += eps
        lo[k] -= eps
        a, b = _probe(fdm, point, hi, props), _probe(fdm, point, lo, props)
        gains[axis] = (a[main] - b[main]) / (2 * eps)
        for s in sib:  # d(sibling)/d(deflection)
            gains[s] = (a[s] - b[s]) / (a[main] - b[main])
        ends = []
        for end in (-1.0, 1.0):
            c = trim_cmd.copy()
            c[k] = end
            ends.append(_probe(fdm, point, c, props))
        for p in props:
            limits[p] = (min(e[p] for e in ends), max(e[p] for e in ends))
    initialise(fdm, point)
    return gains, limits


def state_feedback(fdm, point: TrimPoint, controls: Controls, rate: float = 0.05,
                   angle_deg: float = 0.5) -> dict[str, dict[str, float]]:
    """What the FCS feeds back at trim, commands held: d(surface)/d(body rate) [rad per
    rad/s] under "p", "q", "r" and d(surface)/d(angle) [rad per rad] under "alpha" (about
    the trim's) and "beta" (central differences): a stability augmentation, a yaw damper
    (r), a sideslip feedback (beta: A320's rudder) or a fly-by-wire law."""
    props = {"pitch": controls.pitch, "roll": controls.roll, "yaw": controls.yaw}
    base = _probe(fdm, point, None, props.values())
    out = {}
    for k, axis in enumerate("pqr"):
        rates = [0.0, 0.0, 0.0]
        rates[k] = rate
        initialise(fdm, point, None, tuple(rates))
        out[axis] = {name: (fdm[prop] - base[prop]) / rate for name, prop in props.items()}
    h = math.radians(angle_deg)
    for angle, key in (("alpha", "alpha_offset_deg"), ("beta", "beta_deg")):
        ends = []
        for sign in (1.0, -1.0):
            initialise(fdm, point, None, **{key: sign * angle_deg})
            ends.append({name: fdm[prop] for name, prop in props.items()})
        out[angle] = {name: (ends[0][name] - ends[1][name]) / (2 * h) for name in props}
    initialise(fdm, point)
    return out


#: The derivatives whose steady responses size the manoeuvre, and that an FCS's static feedback changes.
CLOSED_LOOP = ("Cm_alpha", "Cl_p", "Cn_beta")


def closed_loop_derivatives(d: dict, feedback: dict, V_m_s: float, span_m: float) -> dict[str, float]:
    """The derivatives the manoeuvre's steady responses see with the FCS's static feedback
    on the surface of the same axis: C_m_alpha + C_m_delta_p d(elevator)/d(alpha),
    C_l_p + C_l_delta_r d(aileron)/d(p) 2V/b, C_n_beta + C_n_delta_y d(rudder)/d(beta).
    Without feedback they are the open-loop ones."""
    return {"Cm_alpha": d["Cm_alpha"] + d["Cm_delta_p"] * feedback.get("alpha", {}).get("pitch", 0.0),
            "Cl_p": d["Cl_p"] + d["Cl_delta_r"] * feedback.get("p", {}).get("roll", 0.0) * 2.0 * V_m_s / span_m,
            "Cn_beta": d["Cn_beta"] + d["Cn_delta_y"] * feedback.get("beta", {}).get("yaw", 0.0)}
