"""Flight force and moment coefficients from smoothed states (method.md §7–§9).

    C_N = -m Z1/(qbar S)   C_Y = m Y1/(qbar S)   C_A = -m X1/(qbar S)
    C_l = Ixx L_hat/(qbar S b)   C_m = Iyy M_hat/(qbar S c)   C_n = Izz N_hat/(qbar S b)

with c and b the vehicle's pitch and lateral reference lengths (both d for the
finned class; chord and span for an aircraft).

X1, Y1, Z1 are the CG specific forces [m/s^2] and L_hat, M_hat, N_hat the
aerodynamic angular accelerations (moment / inertia) [rad/s^2], i.e. the
smoother's X1, Y1, Z1, L1, M1, N1 states.  The moments come out about the CG.
C_N is the normal force, positive up (C_N = -C_z): the sign chain of seed eq. 5
(positive pitch fin -> positive q -> positive alpha -> positive C_N -> negative a_z).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aerosid.vehicles.atmosphere import AirData, air_data
from aerosid.vehicles.vehicle import Vehicle


@dataclass(frozen=True)
class FlightCoefficients:
    """Per-sample coefficients [-] with their 1-sigma from the smoother's sigma."""

    CA: np.ndarray
    CY: np.ndarray
    CN: np.ndarray
    Cl: np.ndarray
    Cm: np.ndarray
    Cn: np.ndarray
    sigma: dict  # name -> (N,) 1-sigma [-] (propagated from state sigma; q-bar taken as exact)
    air: AirData


def flight_coefficients(vehicle: Vehicle, V_m_s, h_m, accel_cg_m_s2, ang_accel_hat_rad_s2,
                        accel_sigma=None, ang_sigma=None, air: AirData | None = None) -> FlightCoefficients:
    """accel_cg_m_s2: (N,3) X1, Y1, Z1; ang_accel_hat_rad_s2: (N,3) L_hat, M_hat, N_hat.
    Optional (N,3) sigmas of each give the coefficients' sigma.  ``air``: the air data
    per sample (``aerosid.vehicles.atmosphere.air_data``, e.g. with measured density); default
    the US-1976 atmosphere at h_m."""
    air = air_data(V_m_s, h_m) if air is None else air
    qs = air.qbar_pa * vehicle.S_m2
    lengths = np.array([vehicle.length_lateral_m, vehicle.length_pitch_m, vehicle.length_lateral_m])
    a = np.asarray(accel_cg_m_s2, dtype=float)
    w = np.asarray(ang_accel_hat_rad_s2, dtype=float)
    m = vehicle.mass_kg
    inertia = np.array([vehicle.Ixx_kg_m2, vehicle.Iyy_kg_m2, vehicle.Izz_kg_m2])
    force_scale = m / qs
    moment_scale = inertia[None, :] / (qs[:, None] * lengths[None, :])
    sigma = {}
    if accel_sigma is not None:
        s = np.asarray(accel_sigma) * force_scale[:, None]
        sigma.update(CA=s[:, 0], CY=s[:, 1], CN=s[:, 2])
    if ang_sigma is not None:
        s = np.asarray(ang_sigma) * moment_scale
        sigma.update(Cl=s[:, 0], Cm=s[:, 1], Cn=s[:, 2])
    return FlightCoefficients(
        CA=-a[:, 0] * force_scale,
        CY=a[:, 1] * force_scale,
        CN=-a[:, 2] * force_scale,
        Cl=w[:, 0] * moment_scale[:, 0],
        Cm=w[:, 1] * moment_scale[:, 1],
        Cn=w[:, 2] * moment_scale[:, 2],
        sigma=sigma,
        air=air,
    )
