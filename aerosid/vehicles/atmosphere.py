"""Air data: the US Standard Atmosphere 1976 (via the maintained ``ambiance`` package)
or, when the telemetry carries them, measured density, dynamic pressure, static
pressure and total temperature.

``air_data`` is the vectorised entry point used by the pipeline (method.md §7); its
``sources`` say where each quantity came from (``air_data_sources`` gives the same
from the list of measured columns alone).
``FastAtmosphere`` is a tabulation of the same model on a 10 m grid for the
simulator's inner loop, where per-call overhead matters (its error against
ambiance is below 1e-5 relative; a test pins it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Iterable

import numpy as np
from ambiance import Atmosphere

H_MIN_M, H_MAX_M = -5000.0, 81000.0
#: Ratio of specific heats and specific gas constant of air [J/(kg K)]: US-1976's (and
#: ambiance's) values, so that the gas law on US-1976 pressure and temperature gives
#: US-1976 density.
GAMMA_AIR = 1.4
R_AIR_J_KG_K = 287.05287
#: Specific heat at constant pressure [J/(kg K)], gamma R / (gamma - 1).
CP_AIR_J_KG_K = GAMMA_AIR * R_AIR_J_KG_K / (GAMMA_AIR - 1.0)

#: The optional measured air-data columns (schemas.telemetry.MEASURED_AIR_DATA_CHANNELS).
MEASURED = ("rho_kg_m3", "qbar_pa", "p_static_pa", "T_total_K")
US1976 = "US-1976 atmosphere at h_m"


def _check_altitude(h_m: np.ndarray) -> None:
    bad = ~((h_m >= H_MIN_M) & (h_m <= H_MAX_M))
    if np.any(bad):
        rows = np.flatnonzero(bad)[:10].tolist()
        raise ValueError(f"altitude outside the US-1976 model's {H_MIN_M:g}..{H_MAX_M:g} m at rows {rows}")


def _us1976(h_m, quantity: str) -> np.ndarray:
    """One US-1976 quantity (ambiance's attribute name) at geometric altitudes h_m [m], shaped as h_m."""
    h = np.asarray(h_m, dtype=float)
    _check_altitude(h)
    return getattr(Atmosphere(h), quantity).reshape(h.shape)


def density_kg_m3(h_m):
    """Air density [kg/m^3] at geometric altitude h_m [m]."""
    return _us1976(h_m, "density")


def pressure_pa(h_m):
    """Static pressure [Pa] at geometric altitude h_m [m]."""
    return _us1976(h_m, "pressure")


def temperature_K(h_m):
    """Static temperature [K] at geometric altitude h_m [m]."""
    return _us1976(h_m, "temperature")


def speed_of_sound_m_s(h_m):
    """Speed of sound [m/s] at geometric altitude h_m [m]."""
    return _us1976(h_m, "speed_of_sound")


def gravity_m_s2(h_m):
    """Gravitational acceleration [m/s^2] at altitude h_m [m] (ambiance's model)."""
    h = np.asarray(h_m, dtype=float)
    return Atmosphere(np.clip(h, H_MIN_M, H_MAX_M)).grav_accel.reshape(h.shape)


class AirDataError(ValueError):
    """A measured air-data value that cannot be used: names the column and the sample
    positions (of the arrays given to ``air_data``)."""

    def __init__(self, column: str, positions: np.ndarray, message: str):
        self.column, self.positions = column, np.asarray(positions)
        super().__init__(f"column {column!r}: {message} at {self.positions.size} sample(s)")


def air_data_sources(measured: Iterable[str] = ()) -> dict[str, str]:
    """Where ``air_data`` takes each quantity from, given the names of the measured
    columns available (any of ``MEASURED``): keys ``rho_kg_m3``, ``T_static_K``,
    ``mach``, ``qbar_pa``.  With none, everything is the US-1976 atmosphere's."""
    have = set(measured)
    temp = ("T_total_K and V_m_s: T = T_total_K - V^2/(2 c_p)" if "T_total_K" in have else US1976)
    if "rho_kg_m3" in have:
        rho = "measured: rho_kg_m3"
    elif "p_static_pa" in have:
        rho = "gas law: p_static_pa / (R T), T from " + ("T_total_K" if "T_total_K" in have else US1976)
    else:
        rho = US1976
    return {
        "rho_kg_m3": rho,
        "T_static_K": temp,
        "mach": "V_m_s / sqrt(gamma R T), T from T_total_K" if "T_total_K" in have else f"V_m_s / a, a from {US1976}",
        "qbar_pa": "measured: qbar_pa" if "qbar_pa" in have else "0.5 rho V_m_s^2",
    }


@dataclass(frozen=True)
class AirData:
    """Air data per sample: rho [kg/m^3], a [m/s], mach [-], qbar [Pa]; ``sources``:
    where each came from (``air_data_sources``)."""

    rho_kg_m3: np.ndarray
    a_m_s: np.ndarray
    mach: np.ndarray
    qbar_pa: np.ndarray
    sources: dict = field(default_factory=air_data_sources)


def _positive(column: str, x: np.ndarray) -> np.ndarray:
    bad = ~(x > 0)
    if bad.any():
        raise AirDataError(column, np.flatnonzero(bad), f"non-positive or NaN value(s) {x[bad][:3].tolist()}")
    return x


def air_data(V_m_s, h_m, *, rho_kg_m3=None, qbar_pa=None, p_static_pa=None, T_total_K=None) -> AirData:
    """Air data from navigation speed V [m/s] and altitude h [m] (method.md §7), with
    measured values where given (arrays like V; None = not measured).

    The US-1976 atmosphere at h is the default for every quantity.  Measured data
    replace it as follows (V is taken as the airspeed, as everywhere in the pipeline):

    * static temperature: from the total temperature T_t [K] and the speed,
      T = T_t - V^2 / (2 c_p).  This is T_t = T (1 + (gamma-1)/2 M^2) solved for T with
      M = V / sqrt(gamma R T): (gamma-1)/2 * V^2/(gamma R T) * T = V^2/(2 c_p), so no
      iteration on Mach is needed.  A probe recovery factor below 1 is not modelled
      (give the corrected total temperature).
    * speed of sound and Mach: a = sqrt(gamma R T) at that temperature, M = V / a
      (without T_t: US-1976 at h).
    * density: rho_kg_m3 when measured; else the gas law rho = p / (R T) from the
      static pressure p [Pa] and the static temperature above (US-1976's at h when no
      total temperature is measured); else US-1976 at h.
    * dynamic pressure: qbar_pa when measured, else 0.5 rho V^2 with the density above.

    gamma = 1.4 and R = 287.05287 J/(kg K) are US-1976's, so US-1976 pressure and
    temperature in give US-1976 density and Mach out.  Raises ``AirDataError`` for a
    non-positive measured value or static temperature.
    """
    V = np.asarray(V_m_s, dtype=float)
    h = np.asarray(h_m, dtype=float)
    given = {k: np.asarray(v, dtype=float) for k, v in (("rho_kg_m3", rho_kg_m3), ("qbar_pa", qbar_pa),
                                                         ("p_static_pa", p_static_pa), ("T_total_K", T_total_K))
             if v is not None}
    for k, v in given.items():
        if v.shape != V.shape:
            raise ValueError(f"column {k!r}: {v.shape} values for {V.shape} speeds")
        _positive(k, v)
    sources = air_data_sources(given)
    if not given:  # the standard atmosphere alone (kept bit for bit as it always was)
        _check_altitude(h)
        atm = Atmosphere(h)
        rho = atm.density.reshape(h.shape)
        a = atm.speed_of_sound.reshape(h.shape)
        return AirData(rho, a, V / a, 0.5 * rho * V * V, sources)
    atm = None
    if "T_total_K" not in given or not {"rho_kg_m3", "p_static_pa"} & set(given):
        _check_altitude(h)
        atm = Atmosphere(h)
    if "T_total_K" in given:
        T = given["T_total_K"] - V * V / (2.0 * CP_AIR_J_KG_K)
        if not (T > 0).all():
            raise AirDataError("T_total_K", np.flatnonzero(~(T > 0)), "static temperature T_total_K - V^2/(2 c_p) "
                               "is not positive (total temperature too low for the speed: units?)")
        a = np.sqrt(GAMMA_AIR * R_AIR_J_KG_K * T)
    else:
        T = atm.temperature.reshape(h.shape)
        a = atm.speed_of_sound.reshape(h.shape)
    if "rho_kg_m3" in given:
        rho = given["rho_kg_m3"]
    elif "p_static_pa" in given:
        rho = given["p_static_pa"] / (R_AIR_J_KG_K * T)
    else:
        rho = atm.density.reshape(h.shape)
    qbar = given["qbar_pa"] if "qbar_pa" in given else 0.5 * rho * V * V
    return AirData(rho, a, V / a, qbar, sources)


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
