"""c172x's aerodynamics re-evaluated from its JSBSim XML: a small vectorised evaluator
of JSBSim functions and tables (the truth of aerosid.simulation.jsbsim_flight), and
the wind-to-body and AERORP-to-CG transfer JSBSim applies."""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

DEG = math.pi / 180.0


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
        it, ft = _bracket(self.breakpoints, env(self.table_var))
        values = np.stack([self._lookup2(tab, xr, xc) * np.ones_like(np.asarray(xr, float)) for tab in self.tables])
        it1 = np.minimum(it + 1, len(self.tables) - 1)
        idx = np.arange(values.shape[1]) if values.ndim > 1 else None
        if idx is None:
            return values[it] * (1 - ft) + values[it1] * ft
        return values[it, idx] * (1 - ft) + values[it1, idx] * ft


class AeroTables:
    """The aerodynamic model of a JSBSim aircraft XML, evaluated in numpy.

    ``coefficients(**state)`` returns wind-axis C_D, C_Y(side), C_L and the body-axis
    moment coefficients about the aerodynamic reference point, by evaluating every
    function of the <aerodynamics> axes with q̄S = 1, b = c̄ = 1 and the rates given
    already non-dimensional (ci2vel = bi2vel = 1, q = q̂, ...).  Supports the
    function elements c172x uses (product, sum, difference, quotient, table,
    property, value).
    """

    def __init__(self, xml_path: str | Path):
        self.path = Path(xml_path)
        root = ET.parse(self.path).getroot()
        aero = root.find("aerodynamics")
        self.root = root
        self.named = {f.get("name"): f for f in aero.findall("function")}
        self.axes = {ax.get("name"): ax.findall("function") for ax in aero.findall("axis")}
        if not {"DRAG", "SIDE", "LIFT", "ROLL", "PITCH", "YAW"} <= set(self.axes):
            raise ValueError(f"{self.path}: only the LIFT/DRAG/SIDE + ROLL/PITCH/YAW axis system is supported")
        self._tables: dict[int, _Table] = {}

    def function_names(self, axis: str) -> list[str]:
        return [f.get("name") for f in self.axes[axis]]

    def _eval(self, el: ET.Element, env):
        tag = el.tag
        if tag in ("property", "p"):
            name = el.text.strip()
            if name.startswith("-"):
                return -env(name[1:])
            return env(name)
        if tag in ("value", "v"):
            return float(el.text)
        kids = [k for k in el if k.tag != "description"]
        if tag == "function":
            (body,) = kids
            return self._eval(body, env)
        if tag == "product":
            out = 1.0
            for k in kids:
                out = out * self._eval(k, env)
            return out
        if tag == "sum":
            out = 0.0
            for k in kids:
                out = out + self._eval(k, env)
            return out
        if tag == "difference":
            out = self._eval(kids[0], env)
            for k in kids[1:]:
                out = out - self._eval(k, env)
            return out
        if tag == "quotient":
            return self._eval(kids[0], env) / self._eval(kids[1], env)
        if tag == "table":
            table = self._tables.get(id(el))
            if table is None:
                table = self._tables[id(el)] = _Table(el)
            return table(env)
        raise NotImplementedError(f"{self.path}: JSBSim function element <{tag}> is not supported")

    def coefficients(self, alpha, beta, delta_e, delta_a, delta_r, p_hat, q_hat, r_hat, alpha_dot_hat,
                     flaps_deg=0.0, h_over_b=1e3, stall_hyst=0.0) -> dict[str, np.ndarray]:
        """delta_e = fcs/elevator-pos-rad, delta_a = fcs/effective-aileron-pos,
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
        cache: dict[str, object] = {}

        def env(name):
            if name in base:
                return base[name]
            if name in cache:
                return cache[name]
            if name in self.named:
                cache[name] = self._eval(self.named[name], env)
                return cache[name]
            raise KeyError(f"{self.path}: the aerodynamic model uses {name!r}, which the evaluator does not provide")

        shape = np.broadcast(alpha, beta, np.asarray(delta_e), np.asarray(q_hat)).shape

        def axis_sum(axis):
            out = np.zeros(shape)
            for f in self.axes[axis]:
                out = out + self._eval(f, env)
            return out

        return {"CD": axis_sum("DRAG"), "CS": axis_sum("SIDE"), "CL": axis_sum("LIFT"),
                "Cl_rp": axis_sum("ROLL"), "Cm_rp": axis_sum("PITCH"), "Cn_rp": axis_sum("YAW")}


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
