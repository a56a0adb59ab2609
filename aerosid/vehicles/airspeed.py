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

from aerosid.vehicles.atmosphere import CP_AIR_J_KG_K, GAMMA_AIR, R_AIR_J_KG_K, pressure_pa, temperature_K

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


def calibrated_share(V_m_s, h_m) -> float:
    """The median share of the true airspeed a calibrated airspeed is, for an airspeed column V_m_s
    [m/s] at altitudes h_m [m] read as calibrated (US-1976): what V_m_s / true airspeed would be if
    the column held a calibrated airspeed (0.93 at 1400 m, 0.74 at 6 km)."""
    V = np.asarray(V_m_s, dtype=float)
    return float(np.median(V / true_airspeed_m_s(V, h_m, "calibrated")))


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
    if kind == "equivalent":
        if rho_kg_m3 is not None:
            return V * np.sqrt(RHO0_KG_M3 / np.asarray(rho_kg_m3, dtype=float))
        if T_total_K is None:
            T = temperature_K(h)
        else:  # T = T_t - V_true^2 / (2 c_p) as in atmosphere.air_data, V_true^2 = V^2 rho_0 R T / p: solved for T
            heating = V**2 * RHO0_KG_M3 * R_AIR_J_KG_K / (2.0 * CP_AIR_J_KG_K * p)
            T = np.asarray(T_total_K, dtype=float) / (1.0 + heating)
        return V * np.sqrt(RHO0_KG_M3 * R_AIR_J_KG_K * T / p)
    qc = P0_PA * _qc_over_p(V / A0_M_S)
    mach = _mach_from_qc_over_p(qc / p)
    if T_total_K is not None:
        T = np.asarray(T_total_K, dtype=float) / (1.0 + 0.2 * mach**2)
    elif rho_kg_m3 is not None:
        T = p / (R_AIR_J_KG_K * np.asarray(rho_kg_m3, dtype=float))
    else:
        T = temperature_K(h)
    return mach * np.sqrt(GAMMA_AIR * R_AIR_J_KG_K * T)


#: Measured air-data columns the conversion reads when the telemetry has them (true_airspeed_m_s).
MEASURED_FOR_AIRSPEED = ("p_static_pa", "T_total_K", "rho_kg_m3")


def true_airspeed_where_known(V_m_s, h_m, kind: str, measured: dict) -> tuple[np.ndarray, int]:
    """(true airspeed [m/s], rows emptied): true_airspeed_m_s on the rows whose V_m_s, h_m and
    measured columns (a dict of MEASURED_FOR_AIRSPEED arrays) are finite and positive (h within
    the US-1976 model); an airspeed whose row lacks the others becomes NaN (a dropout the
    preprocessing fills), a missing or non-positive airspeed or a sentinel value (which the
    preprocessing flags) stays as recorded."""
    from aerosid.vehicles.atmosphere import H_MAX_M, H_MIN_M
    from schemas.telemetry import sentinel_mask

    V, h = np.asarray(V_m_s, dtype=float), np.asarray(h_m, dtype=float)
    have_V = np.isfinite(V) & (V > 0) & ~sentinel_mask(V)
    ok = have_V & np.isfinite(h) & (h >= H_MIN_M) & (h <= H_MAX_M)
    for x in measured.values():
        ok &= np.isfinite(x) & (np.asarray(x, dtype=float) > 0)
    out = V.copy()
    out[ok] = true_airspeed_m_s(V[ok], h[ok], kind, **{c: np.asarray(x, dtype=float)[ok] for c, x in measured.items()})
    out[have_V & ~ok] = np.nan
    return out, int((have_V & ~ok).sum())


def columns_to_true_airspeed(columns, kind: str, said: str) -> tuple[np.ndarray, str]:
    """(true airspeed [m/s], the note to record): the V_m_s of `columns` (a frame or a dict of
    arrays with V_m_s, h_m and any MEASURED_FOR_AIRSPEED) read as an airspeed of `kind`
    (true_airspeed_where_known); said: where the kind was stated, for the note."""
    measured = {c: np.asarray(columns[c], dtype=float) for c in MEASURED_FOR_AIRSPEED if c in columns}
    V, kept = true_airspeed_where_known(np.asarray(columns["V_m_s"], dtype=float),
                                        np.asarray(columns["h_m"], dtype=float), kind, measured)
    with_what = ", ".join(["h_m" + ("" if measured else " (US-1976)"), *measured])
    return V, (f"V_m_s: {said} converted to the true airspeed with {with_what} (aerosid.vehicles.airspeed); "
               f"{kept} row(s) without them left empty")


def as_true_airspeed(frame, kind: str):
    """(frame, note): a raw telemetry frame whose V_m_s holds an airspeed of `kind` (the vehicle
    file's [air_data] airspeed) with V_m_s converted to the true airspeed (a copy; the frame itself
    when kind is "true", with an empty note)."""
    if kind == "true" or "V_m_s" not in frame.columns or "h_m" not in frame.columns:
        return frame, ""
    V, note = columns_to_true_airspeed(frame, kind, f"the vehicle file's [air_data] airspeed = \"{kind}\"")
    out = frame.copy()
    out["V_m_s"] = V
    return out, note


def dynamic_from_impact_pressure_pa(qc_pa, p_static_pa) -> np.ndarray:
    """The dynamic pressure 0.5 rho V^2 = (gamma / 2) p M^2 [Pa] of an impact pressure q_c = p_t - p
    [Pa] (what a pitot-static system measures) at static pressure p_static_pa [Pa]: the Mach number
    from q_c / p (isentropic below Mach 1, Rayleigh's pitot formula above).  q_c exceeds the dynamic
    pressure by about 1 + M^2/4: 1.17 at Mach 0.8, 1.28 at Mach 1."""
    p = np.asarray(p_static_pa, dtype=float)
    mach = _mach_from_qc_over_p(np.asarray(qc_pa, dtype=float) / p)
    return 0.5 * GAMMA_AIR * p * mach**2
