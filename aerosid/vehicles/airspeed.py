"""Airspeeds as a data system records them, converted to the true airspeed aerosid needs.

A flight-test data system often records the *calibrated* airspeed (CAS: the pitot-static
impact pressure expressed as the speed that gives it at sea level; an *indicated* airspeed is
the same before the position-error correction) or the *equivalent* airspeed (EAS: the speed
that gives the same dynamic pressure at sea-level density).  Every coefficient divides by
0.5 rho V^2 with the *true* airspeed; a CAS taken for it makes q-bar low by about rho / rho_0
(every coefficient x1.16 at 1500 m, x1.86 at 6 km, x3.4 at 12 km).

Conversions (subsonic and supersonic; SI; sea level of the US-1976 atmosphere):

* impact pressure from CAS, q_c = p_0 [(1 + 0.2 (V_c/a_0)^2)^3.5 - 1] (isentropic, V_c <= a_0)
  or Rayleigh's pitot formula above a_0;
* Mach number from q_c / p (the same two formulas with the static pressure p, Rayleigh's
  solved by fixed-point iteration);
* the static temperature from the total one, T = T_t / (1 + 0.2 M^2), when it is measured;
* V = M sqrt(gamma R T);  EAS: V = V_e sqrt(rho_0 / rho).

Static pressure and temperature are the measured ones when given, the US-1976 values at
the altitude otherwise.
"""
from __future__ import annotations

import numpy as np

from aerosid.vehicles.atmosphere import GAMMA_AIR, R_AIR_J_KG_K, density_kg_m3, pressure_pa, temperature_K

#: What an airspeed column may hold (an import map's ``airspeed`` key).
AIRSPEED_KINDS = ("true", "calibrated", "indicated", "equivalent")
P0_PA = 101325.0
T0_K = 288.15
A0_M_S = float(np.sqrt(GAMMA_AIR * R_AIR_J_KG_K * T0_K))
RHO0_KG_M3 = P0_PA / (R_AIR_J_KG_K * T0_K)
#: q_c / p at Mach 1: (1.2)^3.5 - 1, where the isentropic and Rayleigh formulas meet.
QC_OVER_P_SONIC = 1.2**3.5 - 1.0


def _qc_over_p(mach: np.ndarray) -> np.ndarray:
    """Impact pressure over static pressure at Mach `mach` (isentropic below 1, Rayleigh's pitot
    formula, the normal shock ahead of the probe, above)."""
    m = np.asarray(mach, dtype=float)
    sub = (1.0 + 0.2 * m**2) ** 3.5 - 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        sup = 166.92158 * m**7 / np.maximum(7.0 * m**2 - 1.0, 1e-12) ** 2.5 - 1.0
    return np.where(m <= 1.0, sub, sup)


def _mach_from_qc_over_p(ratio: np.ndarray) -> np.ndarray:
    """Inverse of _qc_over_p (ratio >= 0)."""
    r = np.asarray(ratio, dtype=float)
    sub = np.sqrt(5.0 * ((r + 1.0) ** (2.0 / 7.0) - 1.0))
    m = np.maximum(sub, 1.0)
    for _ in range(60):  # Rayleigh: M = 0.8812848 sqrt((r + 1) (1 - 1 / (7 M^2))^2.5), a contraction for M >= 1
        m = np.maximum(1.0, 0.88128485 * np.sqrt((r + 1.0) * (1.0 - 1.0 / (7.0 * m**2)) ** 2.5))
    return np.where(r <= QC_OVER_P_SONIC, sub, m)


def calibrated_from_true_m_s(V_m_s, h_m, p_static_pa=None, T_static_K=None) -> np.ndarray:
    """The calibrated airspeed [m/s] of a true airspeed V_m_s [m/s] at altitude h_m [m]
    (US-1976 static pressure and temperature unless given [Pa], [K]): the simulator's CAS
    channel and the inverse the tests check ``true_airspeed_m_s`` against."""
    V = np.asarray(V_m_s, dtype=float)
    p = pressure_pa(h_m) if p_static_pa is None else np.asarray(p_static_pa, dtype=float)
    T = temperature_K(h_m) if T_static_K is None else np.asarray(T_static_K, dtype=float)
    qc = p * _qc_over_p(V / np.sqrt(GAMMA_AIR * R_AIR_J_KG_K * T))
    return A0_M_S * _mach_from_qc_over_p(qc / P0_PA)


def true_airspeed_m_s(V_m_s, h_m, kind: str = "calibrated", p_static_pa=None, T_total_K=None,
                      rho_kg_m3=None) -> np.ndarray:
    """The true airspeed [m/s] of an airspeed V_m_s [m/s] of `kind` (AIRSPEED_KINDS; indicated
    is taken as calibrated: the position error is the data system's) at geometric altitude h_m
    [m].  p_static_pa [Pa] and T_total_K [K], when measured, replace the US-1976 static pressure
    and temperature (the static temperature then follows from the Mach number); a measured
    density rho_kg_m3 [kg/m^3] gives the static temperature by the gas law where no total
    temperature is measured (and the equivalent airspeed's density directly)."""
    if kind not in AIRSPEED_KINDS:
        raise ValueError(f"airspeed kind {kind!r}: expected one of {', '.join(AIRSPEED_KINDS)}")
    V = np.asarray(V_m_s, dtype=float)
    if kind == "true":
        return V.copy()
    h = np.broadcast_to(np.asarray(h_m, dtype=float), V.shape)
    p = pressure_pa(h) if p_static_pa is None else np.broadcast_to(np.asarray(p_static_pa, dtype=float), V.shape)
    if kind == "equivalent" and rho_kg_m3 is not None:
        return V * np.sqrt(RHO0_KG_M3 / np.asarray(rho_kg_m3, dtype=float))
    if kind == "equivalent":
        if T_total_K is None and p_static_pa is None:
            rho = density_kg_m3(h)
        else:  # the gas law on what is measured; a total temperature is corrected with the Mach number
            T = temperature_K(h)
            for _ in range(3 if T_total_K is not None else 0):
                mach = V * np.sqrt(RHO0_KG_M3 / (p / (R_AIR_J_KG_K * T))) / np.sqrt(GAMMA_AIR * R_AIR_J_KG_K * T)
                T = np.asarray(T_total_K, dtype=float) / (1.0 + 0.2 * mach**2)
            rho = p / (R_AIR_J_KG_K * T)
        return V * np.sqrt(RHO0_KG_M3 / rho)
    qc = P0_PA * _qc_over_p(V / A0_M_S)
    mach = _mach_from_qc_over_p(qc / p)
    if T_total_K is not None:
        T = np.asarray(T_total_K, dtype=float) / (1.0 + 0.2 * mach**2)
    elif rho_kg_m3 is not None:
        T = p / (R_AIR_J_KG_K * np.asarray(rho_kg_m3, dtype=float))
    else:
        T = temperature_K(h)
    return mach * np.sqrt(GAMMA_AIR * R_AIR_J_KG_K * T)
