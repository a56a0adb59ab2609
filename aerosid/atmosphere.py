"""US Standard Atmosphere 1976 (via the maintained ``ambiance`` package).

``air_data`` is the vectorised entry point used by the pipeline (method.md §7).
``FastAtmosphere`` is a tabulation of the same model on a 10 m grid for the
simulator's inner loop, where per-call overhead matters (its error against
ambiance is below 1e-5 relative; a test pins it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from ambiance import Atmosphere

H_MIN_M, H_MAX_M = -5000.0, 81000.0


def _check_altitude(h_m: np.ndarray) -> None:
    bad = ~((h_m >= H_MIN_M) & (h_m <= H_MAX_M))
    if np.any(bad):
        rows = np.flatnonzero(bad)[:10].tolist()
        raise ValueError(f"altitude outside the US-1976 model's {H_MIN_M:g}..{H_MAX_M:g} m at rows {rows}")


def density_kg_m3(h_m):
    """Air density [kg/m^3] at geometric altitude h_m [m]."""
    h = np.asarray(h_m, dtype=float)
    _check_altitude(h)
    return Atmosphere(h).density.reshape(h.shape)


def speed_of_sound_m_s(h_m):
    """Speed of sound [m/s] at geometric altitude h_m [m]."""
    h = np.asarray(h_m, dtype=float)
    _check_altitude(h)
    return Atmosphere(h).speed_of_sound.reshape(h.shape)


def gravity_m_s2(h_m):
    """Gravitational acceleration [m/s^2] at altitude h_m [m] (ambiance's model)."""
    h = np.asarray(h_m, dtype=float)
    return Atmosphere(np.clip(h, H_MIN_M, H_MAX_M)).grav_accel.reshape(h.shape)


@dataclass(frozen=True)
class AirData:
    """Air data per sample: rho [kg/m^3], a [m/s], mach [-], qbar [Pa]."""

    rho_kg_m3: np.ndarray
    a_m_s: np.ndarray
    mach: np.ndarray
    qbar_pa: np.ndarray


def air_data(V_m_s, h_m) -> AirData:
    """Air data from navigation speed V [m/s] and altitude h [m] (method.md §7)."""
    V = np.asarray(V_m_s, dtype=float)
    h = np.asarray(h_m, dtype=float)
    _check_altitude(h)
    atm = Atmosphere(h)
    rho = atm.density.reshape(h.shape)
    a = atm.speed_of_sound.reshape(h.shape)
    return AirData(rho, a, V / a, 0.5 * rho * V * V)


class FastAtmosphere:
    """Scalar (rho, a, g) lookups on a 10 m table, for the simulator's inner loop."""

    STEP_M = 10.0

    def __init__(self) -> None:
        self.h = np.arange(H_MIN_M, H_MAX_M + self.STEP_M, self.STEP_M)
        atm = Atmosphere(self.h)
        self._log_rho = np.log(atm.density).tolist()
        self._a = atm.speed_of_sound.tolist()
        self._g = atm.grav_accel.tolist()
        self._n = len(self.h)

    def __call__(self, h_m: float) -> tuple[float, float, float]:
        x = (h_m - H_MIN_M) / self.STEP_M
        i = int(x)
        if i < 0 or i >= self._n - 1:
            raise ValueError(f"altitude {h_m:.1f} m outside the US-1976 model's {H_MIN_M:g}..{H_MAX_M:g} m")
        w = x - i
        rho = math.exp(self._log_rho[i] + w * (self._log_rho[i + 1] - self._log_rho[i]))
        a = self._a[i] + w * (self._a[i + 1] - self._a[i])
        g = self._g[i] + w * (self._g[i + 1] - self._g[i])
        return rho, a, g
