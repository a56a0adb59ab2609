"""Flying a designed input (aerosid design, ``simulate --jsbsim AIRCRAFT --input FILE``).

The file's ``elevator_cmd_rad``, ``aileron_cmd_rad``, ``rudder_cmd_rad`` are increments of
the surface *command* [rad of deflection, JSBSim's signs] about trim; they become
increments of JSBSim's normalised pilot commands through the aircraft's control scaling:
for c172x the XML's ``aerosurface_scale`` (piecewise linear, a different travel on each
side of zero: the elevator 23 deg up the positive side, 28 deg the negative), inverted
about the trimmed command; for the generated designs the static gain at trim
(jsbsim_design.fcs_statics).  Missing columns: no input on that axis.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pandas as pd

AXES = (("elevator", "elevator_cmd_rad"), ("aileron", "aileron_cmd_rad"), ("rudder", "rudder_cmd_rad"))


def input_time(table: pd.DataFrame, dt: float) -> np.ndarray:
    """The flight's sample grid: 0 .. the file's last time."""
    n = int(round(float(table["t_s"].iloc[-1]) / dt)) + 1
    return np.arange(n) * dt


def _scale(xml_root: ET.Element, name: str):
    """(rad per unit command on the positive side, on the negative side, input property)."""
    fcs = xml_root.find("flight_control")
    for sc in fcs.iter("aerosurface_scale"):
        if sc.get("name") == name:
            gain = float(sc.findtext("gain") or 1.0)
            rng = sc.find("range")
            lo, hi = float(rng.findtext("min")), float(rng.findtext("max"))
            sign = -1.0 if sc.findtext("input").strip().startswith("-") else 1.0
            return hi * gain, -lo * gain, sign
    raise KeyError(name)


def _to_norm(delta_rad: np.ndarray, s0: float, pos: float, neg: float) -> np.ndarray:
    """Command increment that moves the scale's output by delta_rad from its value at s0."""
    def f(s):
        return np.where(s >= 0, s * pos, s * neg)

    def finv(y):
        return np.where(y >= 0, y / pos, y / neg)

    return finv(f(np.asarray(s0, float)) + delta_rad) - s0


def c172x_inputs(table: pd.DataFrame, t: np.ndarray, xml_root: ET.Element, trim: dict) -> dict[str, np.ndarray]:
    """Normalised command increments for c172x from a designed-input table."""
    spec = {"elevator": ("fcs/elevator-control", trim["fcs/pitch-trim-sum"]),
            "aileron": ("fcs/left-aileron-control", trim["fcs/roll-trim-sum"]),
            "rudder": ("fcs/rudder-control", 0.0)}
    out = {}
    for axis, col in AXES:
        if col not in table.columns:
            out[axis] = np.zeros_like(t)
            continue
        x = np.interp(t, table["t_s"].to_numpy(float), table[col].to_numpy(float), left=0.0, right=0.0)
        pos, neg, sign = _scale(xml_root, spec[axis][0])
        out[axis] = sign * _to_norm(sign * x, sign * spec[axis][1], pos, neg)
    return out


def gain_inputs(table: pd.DataFrame, t: np.ndarray, gains: dict) -> dict[str, np.ndarray]:
    """Normalised command increments from static gains [rad per unit command] per axis."""
    out = {}
    for (axis, col), g in zip(AXES, (gains["pitch"], gains["roll"], gains["yaw"])):
        if col not in table.columns or abs(g) < 1e-9:
            out[axis] = np.zeros_like(t)
            continue
        x = np.interp(t, table["t_s"].to_numpy(float), table[col].to_numpy(float), left=0.0, right=0.0)
        out[axis] = x / g
    return out
