"""Rigid-body rotational dynamics shared by the simulator and the estimator.

Convention (written down once, used everywhere): the *aerodynamic angular
accelerations* are the aerodynamic moments divided by the matching principal
inertia,

    L_hat = L / Ixx,   M_hat = M / Iyy,   N_hat = N / Izz        [rad/s^2]

as the seed does (method.md §5, §8: C_l = Ixx L_hat / (qbar S d)).  With the
inertia constants c1..c9 of method.md §5 (Gamma = Ixx Izz - Ixz^2):

    p_dot = (c1 r + c2 p) q + c3 Ixx L_hat + c4 Izz N_hat
    q_dot = c5 p r - c6 (p^2 - r^2) + M_hat                 (c7 Iyy = 1)
    r_dot = (c8 p - c2 r) q + c4 Ixx L_hat + c9 Izz N_hat
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np


class InertiaConstants(NamedTuple):
    """c1..c9 of method.md §5 and the inertias they came from [kg m^2]."""

    c1: float
    c2: float
    c3: float
    c4: float
    c5: float
    c6: float
    c7: float
    c8: float
    c9: float
    Ixx: float
    Iyy: float
    Izz: float
    Ixz: float


def inertia_constants(Ixx: float, Iyy: float, Izz: float, Ixz: float) -> InertiaConstants:
    """Inertia constants c1..c9 [1/(kg m^2) or dimensionless] from inertias [kg m^2].

    Raises ValueError when the inertia tensor is not physical (a non-positive
    principal inertia or Gamma = Ixx Izz - Ixz^2 <= 0).
    """
    if min(Ixx, Iyy, Izz) <= 0.0:
        raise ValueError(f"inertias must be positive, got Ixx={Ixx}, Iyy={Iyy}, Izz={Izz} kg m^2")
    gamma = Ixx * Izz - Ixz**2
    if gamma <= 0.0:
        raise ValueError(f"Gamma = Ixx*Izz - Ixz^2 = {gamma:g} <= 0: Ixz={Ixz} kg m^2 is not physical")
    return InertiaConstants(
        c1=((Iyy - Izz) * Izz - Ixz**2) / gamma,
        c2=(Ixx - Iyy + Izz) * Ixz / gamma,
        c3=Izz / gamma,
        c4=Ixz / gamma,
        c5=(Izz - Ixx) / Iyy,
        c6=Ixz / Iyy,
        c7=1.0 / Iyy,
        c8=((Ixx - Iyy) * Ixx + Ixz**2) / gamma,
        c9=Ixx / gamma,
        Ixx=Ixx,
        Iyy=Iyy,
        Izz=Izz,
        Ixz=Ixz,
    )


def body_rate_derivatives(p, q, r, L_hat, M_hat, N_hat, c: InertiaConstants):
    """Angular accelerations (p_dot, q_dot, r_dot) [rad/s^2].

    p, q, r: body rates [rad/s]; L_hat, M_hat, N_hat: moments divided by
    Ixx, Iyy, Izz [rad/s^2].  Works on scalars and on numpy arrays alike.
    """
    p_dot = (c.c1 * r + c.c2 * p) * q + c.c3 * c.Ixx * L_hat + c.c4 * c.Izz * N_hat
    q_dot = c.c5 * p * r - c.c6 * (p * p - r * r) + M_hat
    r_dot = (c.c8 * p - c.c2 * r) * q + c.c4 * c.Ixx * L_hat + c.c9 * c.Izz * N_hat
    return p_dot, q_dot, r_dot


def lever_arm_acceleration(p, q, r, p_dot, q_dot, r_dot, offset_m):
    """Extra specific force seen by an accelerometer at offset_m=(x, y, z) [m] from
    the CG in body axes: omega_dot x r + omega x (omega x r) [m/s^2] (method.md §5)."""
    x, y, z = offset_m
    ax = -(q * q + r * r) * x + (p * q - r_dot) * y + (p * r + q_dot) * z
    ay = (p * q + r_dot) * x - (p * p + r * r) * y + (q * r - p_dot) * z
    az = (p * r - q_dot) * x + (q * r + p_dot) * y - (p * p + q * q) * z
    return ax, ay, az


def angular_momentum(p, q, r, c: InertiaConstants) -> np.ndarray:
    """Body-axis angular momentum I omega [kg m^2/s] (Ixz is the product of inertia
    with the usual aircraft sign: I = [[Ixx,0,-Ixz],[0,Iyy,0],[-Ixz,0,Izz]])."""
    return np.array([c.Ixx * p - c.Ixz * r, c.Iyy * q, c.Izz * r - c.Ixz * p])


def rotational_energy(p, q, r, c: InertiaConstants) -> float:
    """Rotational kinetic energy 0.5 omega^T I omega [J]."""
    return 0.5 * (c.Ixx * p * p + c.Iyy * q * q + c.Izz * r * r - 2.0 * c.Ixz * p * r)
