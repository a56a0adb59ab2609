"""The vehicle's flight-test limits a designed manoeuvre must respect (vehicle file).

Surface deflections: ``[controls] fin_limit_rad`` (or ``surface_limit_rad`` and the
per-surface ``surface_limits_rad``); the rest from the ``[limits]`` table:
``surface_rate_limit_rad_s``, ``alpha_rad = [lo, hi]``, ``load_factor = [lo, hi]``,
``duration_max_s`` and ``surface_margin`` (share of each deflection limit kept in
reserve, default 0.02).  A missing key is reported in :attr:`Limits.assumed`.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field

import numpy as np

from aerosid.vehicles.vehicle import resolve_vehicle_path


@dataclass(frozen=True)
class Limits:
    surface_rad: tuple[tuple[float, float], ...]  # per surface d1..d4 (lo, hi)
    surface_rate_rad_s: float
    alpha_rad: tuple[float, float]
    load_factor: tuple[float, float]
    duration_max_s: float
    margin: float = 0.02
    assumed: tuple[str, ...] = field(default=())

    def check(self, surfaces: np.ndarray, alpha: np.ndarray, n_z: np.ndarray, dt: float) -> dict:
        """Use of each limit by a flown manoeuvre: max share (1 = at the limit) and the worst value."""
        s = np.asarray(surfaces, float)
        used = []
        for i, (lo, hi) in enumerate(self.surface_rad):
            x = s[:, i]
            used.append(max(float(np.max(x)) / hi if hi > 0 else 0.0, float(np.min(x)) / lo if lo < 0 else 0.0))
        rate = float(np.max(np.abs(np.diff(s, axis=0)))) / dt if len(s) > 1 else 0.0
        a_lo, a_hi = self.alpha_rad
        n_lo, n_hi = self.load_factor
        return {
            "surface": max(used) / (1.0 - self.margin),
            "surface_max_abs_rad": float(np.max(np.abs(s))),
            "surface_rate": rate / self.surface_rate_rad_s,
            "surface_rate_max_rad_s": rate,
            "alpha": max(float(np.max(alpha)) / a_hi, float(np.min(alpha)) / a_lo),
            "alpha_range_rad": [float(np.min(alpha)), float(np.max(alpha))],
            "load_factor": max(float(np.max(n_z)) / n_hi, float(np.min(n_z)) / n_lo),
            "load_factor_range": [float(np.min(n_z)), float(np.max(n_z))],
        }

    def to_dict(self) -> dict:
        return {"surface_rad": [list(x) for x in self.surface_rad], "surface_rate_rad_s": self.surface_rate_rad_s,
                "alpha_rad": list(self.alpha_rad), "load_factor": list(self.load_factor),
                "duration_max_s": self.duration_max_s, "surface_margin": self.margin, "assumed": list(self.assumed)}


def read_limits(vehicle_name_or_path: str) -> Limits:
    path = resolve_vehicle_path(vehicle_name_or_path)
    doc = tomllib.loads(path.read_text())
    ctl = doc.get("controls", {})
    lim = doc.get("limits", {})
    assumed = []
    if "surface_limits_rad" in ctl:
        surf = tuple((float(a), float(b)) for a, b in ctl["surface_limits_rad"])
    else:
        x = float(ctl.get("fin_limit_rad", ctl.get("surface_limit_rad", math.radians(20.0))))
        surf = tuple((-x, x) for _ in range(4))
    if "surface_rate_limit_rad_s" not in lim:
        assumed.append("surface_rate_limit_rad_s = 1.0 (not in the vehicle file)")
    if "alpha_rad" not in lim:
        assumed.append("alpha_rad = [-0.2, 0.2] (not in the vehicle file)")
    if "load_factor" not in lim:
        assumed.append("load_factor = [-1, 3] (not in the vehicle file)")
    if "duration_max_s" not in lim:
        assumed.append("duration_max_s = 120 (not in the vehicle file)")
    return Limits(surf, float(lim.get("surface_rate_limit_rad_s", 1.0)),
                  tuple(float(v) for v in lim.get("alpha_rad", (-0.2, 0.2))),
                  tuple(float(v) for v in lim.get("load_factor", (-1.0, 3.0))),
                  float(lim.get("duration_max_s", 120.0)), float(lim.get("surface_margin", 0.02)), tuple(assumed))
