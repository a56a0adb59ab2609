"""JSBSim aerodynamic models re-evaluated from their XML: a small vectorised evaluator
of JSBSim functions and tables (the truth of aerosid.simulation.jsbsim_flight and
aerosid.simulation.jsbsim_aircraft), and the wind-to-body and AERORP-to-CG transfer
JSBSim applies.

``AeroTables(xml).axis_sums(env)`` evaluates every function of the six axes of any
aircraft whose <aerodynamics> uses the LIFT/DRAG/SIDE + ROLL/PITCH/YAW axis system,
with the properties the functions read taken from ``env`` (a mapping from property
name to a number or an array; ``leaf_properties()`` lists the names it needs):
the forces [lbf] and moments about the aerodynamic reference point [lbf ft], exactly
as JSBSim sums them.  The functions' names are whatever the XML calls them (c172x's
``aero/coefficient/Cm_alpha``, f16's ``aero/coefficient/Cma_M``, ...).
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

DEG = math.pi / 180.0
AXES = ("DRAG", "SIDE", "LIFT", "ROLL", "PITCH", "YAW")


# --------------------------------------------------------------------------------------

def _bracket(breakpoints: np.ndarray, x):
    """Index of the lower breakpoint and the fraction, clamped at the ends (JSBSim's
    table lookup holds the end values outside the table)."""
    x = np.asarray(x, dtype=float)
    n = len(breakpoints)
    if n == 1:
        return np.zeros(x.shape, dtype=int), np.zeros(x.shape)
    i = np.clip(np.searchsorted(breakpoints, x, side="right") - 1, 0, n - 2)
    f = np.clip((x - breakpoints[i]) / (breakpoints[i + 1] - breakpoints[i]), 0.0, 1.0)
    return i, f


class _Table:
    """A JSBSim <table> (1-D, 2-D or 3-D), linear interpolation, ends held."""

    def __init__(self, el: ET.Element):
        lookups = {"row": None, "column": None, "table": None}
        for iv in el.findall("independentVar"):
            lookups[iv.get("lookup", "row")] = iv.text.strip()
        self.row_var, self.col_var, self.table_var = lookups["row"], lookups["column"], lookups["table"]
        datas = el.findall("tableData")
        self.breakpoints = np.array([float(d.get("breakPoint", "0")) for d in datas])
        self.tables = [self._parse(d.text) for d in datas]

    def _parse(self, text: str):
        rows = [[float(v) for v in line.split()] for line in text.strip().splitlines() if line.strip()]
        if self.col_var is None:  # 1-D: "x y" lines
            arr = np.array(rows)
            return arr[:, 0], None, arr[:, 1]
        cols = np.array(rows[0])
        body = np.array(rows[1:])
        return body[:, 0], cols, body[:, 1:]

    def _lookup2(self, table, xr, xc):
        rbp, cbp, vals = table
        ir, fr = _bracket(rbp, xr)
        if cbp is None:
            if len(rbp) == 1:
                return np.full(np.shape(xr), vals[0])
            return vals[ir] * (1 - fr) + vals[ir + 1] * fr
        ic, fc = _bracket(cbp, xc)
        ir1 = np.minimum(ir + 1, len(rbp) - 1)
        ic1 = np.minimum(ic + 1, len(cbp) - 1)
        return ((1 - fr) * (1 - fc) * vals[ir, ic] + fr * (1 - fc) * vals[ir1, ic]
                + (1 - fr) * fc * vals[ir, ic1] + fr * fc * vals[ir1, ic1])

    def __call__(self, env):
        xr = env(self.row_var)
        xc = env(self.col_var) if self.col_var else None
        if self.table_var is None:
            return self._lookup2(self.tables[0], xr, xc)
        xt = np.asarray(env(self.table_var), float)
        shape = np.broadcast(np.asarray(xr, float), np.asarray(xc if xc is not None else 0.0, float), xt).shape
        it, ft = _bracket(self.breakpoints, np.broadcast_to(xt, shape))
        values = np.stack([np.broadcast_to(self._lookup2(tab, xr, xc), shape) for tab in self.tables])
        it1 = np.minimum(it + 1, len(self.tables) - 1)
        if values.ndim == 1:
            return values[it] * (1 - ft) + values[it1] * ft
        idx = np.indices(shape)
        return values[(it, *idx)] * (1 - ft) + values[(it1, *idx)] * ft


def _truth(x) -> np.ndarray:
    return np.asarray(x, float) != 0.0


# element -> (minimum number of arguments, numpy implementation on the evaluated arguments)
_ELEMENTS: dict[str, Callable] = {
    "sum": lambda a: sum(a[1:], a[0]),
    "difference": lambda a: a[0] - sum(a[1:], 0.0),
    "quotient": lambda a: np.divide(a[0], a[1]),
    "pow": lambda a: np.power(a[0], a[1]),
    "sqrt": lambda a: np.sqrt(a[0]),
    "abs": lambda a: np.abs(a[0]),
    "sin": lambda a: np.sin(a[0]),
    "cos": lambda a: np.cos(a[0]),
    "tan": lambda a: np.tan(a[0]),
    "asin": lambda a: np.arcsin(a[0]),
    "acos": lambda a: np.arccos(a[0]),
    "atan": lambda a: np.arctan(a[0]),
    "atan2": lambda a: np.arctan2(a[0], a[1]),
    "exp": lambda a: np.exp(a[0]),
    "ln": lambda a: np.log(a[0]),
    "log2": lambda a: np.log2(a[0]),
    "log10": lambda a: np.log10(a[0]),
    "min": lambda a: np.minimum.reduce(np.broadcast_arrays(*a)),
    "max": lambda a: np.maximum.reduce(np.broadcast_arrays(*a)),
    "avg": lambda a: sum(a[1:], a[0]) / len(a),
    "sign": lambda a: np.where(np.asarray(a[0]) < 0.0, -1.0, 1.0),
    "floor": lambda a: np.floor(a[0]),
    "ceil": lambda a: np.ceil(a[0]),
    "integer": lambda a: np.trunc(a[0]),
    "fraction": lambda a: np.asarray(a[0], float) - np.trunc(a[0]),
    "mod": lambda a: np.fmod(a[0], a[1]),
    "toradians": lambda a: np.asarray(a[0], float) * DEG,
    "todegrees": lambda a: np.asarray(a[0], float) / DEG,
    "lt": lambda a: (np.asarray(a[0]) < a[1]) * 1.0,
    "le": lambda a: (np.asarray(a[0]) <= a[1]) * 1.0,
    "gt": lambda a: (np.asarray(a[0]) > a[1]) * 1.0,
    "ge": lambda a: (np.asarray(a[0]) >= a[1]) * 1.0,
    "eq": lambda a: (np.asarray(a[0]) == a[1]) * 1.0,
    "nq": lambda a: (np.asarray(a[0]) != a[1]) * 1.0,
    "and": lambda a: np.logical_and.reduce([_truth(x) for x in np.broadcast_arrays(*a)]) * 1.0,
    "or": lambda a: np.logical_or.reduce([_truth(x) for x in np.broadcast_arrays(*a)]) * 1.0,
    "not": lambda a: (~_truth(a[0])) * 1.0,
    "ifthen": lambda a: np.where(_truth(a[0]), a[1], a[2]),
}


class AeroTables:
    """The aerodynamic model of a JSBSim aircraft XML, evaluated in numpy.

    ``axis_sums(env)`` sums every function of each <axis> as JSBSim does (wind-axis
    DRAG, SIDE, LIFT forces and body-axis ROLL, PITCH, YAW moments about the
    aerodynamic reference point); ``rp_shift(env)`` is the <aero_ref_pt_shift_x>
    function (a shift of the AERORP, in chords, positive aft) or None.

    ``coefficients(**state)`` is c172x's form: C_D, C_Y(side), C_L and the moment
    coefficients about the AERORP with q̄S = 1, b = c̄ = 1 and the rates given already
    non-dimensional.
    """

    def __init__(self, xml_path: str | Path):
        self.path = Path(xml_path)
        root = ET.parse(self.path).getroot()
        aero = root.find("aerodynamics")
        if aero is None or aero.get("file"):
            raise ValueError(f"{self.path}: no inline <aerodynamics> section")
        self.root = root
        # every named function of the section (top level, in an axis or nested): another
        # function may read any of them by name
        self.named = {f.get("name"): f for f in aero.iter("function") if f.get("name")}
        self.axes = {ax.get("name"): ax.findall("function") for ax in aero.findall("axis")}
        if not set(AXES) <= set(self.axes):
            raise ValueError(f"{self.path}: only the LIFT/DRAG/SIDE + ROLL/PITCH/YAW axis system is supported "
                             f"(this model has {', '.join(self.axes) or 'no'} axes)")
        shift = aero.find("aero_ref_pt_shift_x")
        self.rp_shift_el = shift.find("function") if shift is not None else None
        self._tables: dict[int, _Table] = {}
        self._check_elements(aero)

    def _check_elements(self, aero: ET.Element) -> None:
        known = set(_ELEMENTS) | {"function", "product", "table", "property", "p", "value", "v", "independentVar",
                                  "tableData", "description", "documentation", "axis", "aerodynamics",
                                  "aero_ref_pt_shift_x", "alphalimits", "hysteresis_limits", "limit"}
        bad = sorted({el.tag for el in aero.iter() if el.tag not in known and not callable(el.tag)})
        if bad:
            raise NotImplementedError(f"{self.path}: JSBSim function element(s) <{'>, <'.join(bad)}> "
                                      "are not supported by the evaluator")

    def function_names(self, axis: str) -> list[str]:
        return [f.get("name") for f in self.axes[axis]]

    def leaf_properties(self) -> list[str]:
        """The properties the model reads that it does not define itself."""
        out = set()
        for el in self.root.find("aerodynamics").iter():
            if el.tag in ("property", "p", "independentVar") and el.text:
                name = el.text.strip().lstrip("-")
                if name not in self.named:
                    out.add(name)
        return sorted(out)

    def _eval(self, el: ET.Element, env):
        tag = el.tag
        if tag in ("property", "p"):
            name = el.text.strip()
            if name.startswith("-"):
                return -env(name[1:])
            return env(name)
        if tag in ("value", "v"):
            return float(el.text)
        if tag == "table":
            table = self._tables.get(id(el))
            if table is None:
                table = self._tables[id(el)] = _Table(el)
            return table(env)
        kids = [k for k in el if k.tag not in ("description", "documentation") and not callable(k.tag)]
        if tag == "function":
            (body,) = kids
            return self._eval(body, env)
        if tag == "product":
            out = 1.0
            for k in kids:
                out = out * self._eval(k, env)
            return out
        if tag in _ELEMENTS:
            return _ELEMENTS[tag]([self._eval(k, env) for k in kids])
        raise NotImplementedError(f"{self.path}: JSBSim function element <{tag}> is not supported")

    def _environment(self, values: Mapping[str, object]):
        cache: dict[str, object] = {}

        def env(name):
            if name in values:
                return values[name]
            if name in cache:
                return cache[name]
            if name in self.named:
                cache[name] = self._eval(self.named[name], env)
                return cache[name]
            raise KeyError(f"{self.path}: the aerodynamic model reads {name!r}, which the evaluator was not given")

        return env

    def axis_sums(self, values: Mapping[str, object]) -> dict[str, np.ndarray]:
        """The six axis sums with the leaf properties taken from `values`."""
        env = self._environment(values)
        shape = np.broadcast(*[np.asarray(v, float) for v in values.values()]).shape
        out = {}
        for axis in AXES:
            total = np.zeros(shape)
            for f in self.axes[axis]:
                name = f.get("name")
                total = total + (env(name) if name else self._eval(f, env))
            out[axis] = total
        return out

    def rp_shift(self, values: Mapping[str, object]):
        """The AERORP shift [chords, along the structural x axis] or None."""
        if self.rp_shift_el is None:
            return None
        return self._eval(self.rp_shift_el, self._environment(values))

    def coefficients(self, alpha, beta, delta_e, delta_a, delta_r, p_hat, q_hat, r_hat, alpha_dot_hat,
                     flaps_deg=0.0, h_over_b=1e3, stall_hyst=0.0) -> dict[str, np.ndarray]:
        """c172x: delta_e = fcs/elevator-pos-rad, delta_a = fcs/effective-aileron-pos,
        delta_r = fcs/rudder-pos-rad [rad]; rates non-dimensional (q̂ = q c̄/2V,
        p̂ = p b/2V, r̂ = r b/2V, α̇̂ = α̇ c̄/2V)."""
        alpha, beta = np.asarray(alpha, float), np.asarray(beta, float)
        base = {
            "aero/alpha-rad": alpha, "aero/alpha-deg": alpha / DEG,
            "aero/beta-rad": beta, "aero/beta-deg": beta / DEG, "aero/mag-beta-rad": np.abs(beta),
            "fcs/elevator-pos-rad": np.asarray(delta_e, float), "fcs/mag-elevator-pos-rad": np.abs(delta_e),
            "fcs/effective-aileron-pos": np.asarray(delta_a, float),
            "fcs/rudder-pos-rad": np.asarray(delta_r, float),
            "velocities/p-aero-rad_sec": np.asarray(p_hat, float),
            "velocities/q-aero-rad_sec": np.asarray(q_hat, float),
            "velocities/r-aero-rad_sec": np.asarray(r_hat, float),
            "aero/alphadot-rad_sec": np.asarray(alpha_dot_hat, float),
            "aero/qbar-area": 1.0, "metrics/bw-ft": 1.0, "metrics/cbarw-ft": 1.0,
            "aero/ci2vel": 1.0, "aero/bi2vel": 1.0,
            "fcs/flap-pos-deg": flaps_deg, "aero/h_b-mac-ft": h_over_b, "aero/stall-hyst-norm": stall_hyst,
        }
        s = self.axis_sums(base)
        return {"CD": s["DRAG"], "CS": s["SIDE"], "CL": s["LIFT"],
                "Cl_rp": s["ROLL"], "Cm_rp": s["PITCH"], "Cn_rp": s["YAW"]}


def body_coefficients(c: dict, alpha, beta, arm_ft, cbar_ft: float, span_ft: float) -> dict[str, np.ndarray]:
    """Wind-axis (C_D, C_S, C_L) to body axes as JSBSim does (F_b = T_w2b (-D, S, -L)),
    and the moments transferred from the AERORP to the CG: M_cg = M_rp + r x F with
    r = AERORP - CG in body axes [ft] (JSBSim's FGAerodynamics)."""
    ca, sa, cb, sb = np.cos(alpha), np.sin(alpha), np.cos(beta), np.sin(beta)
    fw = (-c["CD"], c["CS"], -c["CL"])
    cx = ca * cb * fw[0] - ca * sb * fw[1] - sa * fw[2]
    cy = sb * fw[0] + cb * fw[1]
    cz = sa * cb * fw[0] - sa * sb * fw[1] + ca * fw[2]
    dx, dy, dz = arm_ft
    return {
        "CA": -cx, "CY": cy, "CN": -cz,
        "Cl": c["Cl_rp"] + (dy * cz - dz * cy) / span_ft,
        "Cm": c["Cm_rp"] + (dz * cx - dx * cz) / cbar_ft,
        "Cn": c["Cn_rp"] + (dx * cy - dy * cx) / span_ft,
        "Cl_rp": c["Cl_rp"], "Cm_rp": c["Cm_rp"], "Cn_rp": c["Cn_rp"],
        "CL": c["CL"], "CD": c["CD"], "CS": c["CS"],
    }
