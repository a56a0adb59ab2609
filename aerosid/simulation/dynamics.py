"""6-DOF rigid-body flight over a flat Earth with centrifugal relief.

State (13): north, east, down position [m]; NED velocity [m/s]; attitude
quaternion body->NED (scalar first); body rates p, q, r [rad/s].  Forces are
aerodynamic only (an unpowered descent); gravity from the US-1976 model; the
centrifugal term (v_n^2 + v_e^2)/(R_E + h) relieves it (a flat-Earth stand-in
for the curvature of a hypersonic trajectory).  Fixed-step RK4 at the telemetry
rate (at most 10 ms), fins held constant over a step (a digital autopilot
running at the telemetry rate).
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from aerosid.modelling.aeromodel import AeroModel
from aerosid.vehicles.atmosphere import FastAtmosphere
from aerosid.vehicles.rigid_body import body_rate_derivatives
from aerosid.vehicles.vehicle import Vehicle

R_EARTH_M = 6_371_000.0


def smooth_pulse(t: float, start: float, duration: float, ramp: float) -> float:
    """1 inside [start, start+duration] with raised-cosine edges of `ramp` s, else 0."""
    if t < start - ramp or t > start + duration + ramp:
        return 0.0
    if t < start:
        return 0.5 * (1.0 - math.cos(math.pi * (t - start + ramp) / ramp))
    if t > start + duration:
        return 0.5 * (1.0 + math.cos(math.pi * (t - start - duration) / ramp))
    return 1.0


def schedule(t: float, plan, period: float, ramp: float) -> float:
    """Sum of smooth pulses (start, duration, amplitude), the plan repeating every period."""
    tc = t % period if period > 0 else t
    return sum(a * smooth_pulse(tc, s, d, ramp) for s, d, a in plan)


def quat_to_dcm(q0, q1, q2, q3):
    """Body->NED direction cosine matrix (array inputs broadcast)."""
    return np.array(
        [
            [1 - 2 * (q2 * q2 + q3 * q3), 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q3 + q0 * q2)],
            [2 * (q1 * q2 + q0 * q3), 1 - 2 * (q1 * q1 + q3 * q3), 2 * (q2 * q3 - q0 * q1)],
            [2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), 1 - 2 * (q1 * q1 + q2 * q2)],
        ]
    )


def euler_from_quat(q0, q1, q2, q3):
    """(roll phi, pitch theta, yaw psi) [rad] from the body->NED quaternion."""
    phi = np.arctan2(2 * (q0 * q1 + q2 * q3), 1 - 2 * (q1 * q1 + q2 * q2))
    theta = np.arcsin(np.clip(2 * (q0 * q2 - q3 * q1), -1.0, 1.0))
    psi = np.arctan2(2 * (q0 * q3 + q1 * q2), 1 - 2 * (q2 * q2 + q3 * q3))
    return phi, theta, psi


def quat_from_euler(phi, theta, psi):
    cr, sr = math.cos(phi / 2), math.sin(phi / 2)
    cp, sp = math.cos(theta / 2), math.sin(theta / 2)
    cy, sy = math.cos(psi / 2), math.sin(psi / 2)
    return (cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy)


def aero_angles(u, v, w):
    """Total angle of attack alpha_r and aero roll angle phi_r [rad] from body velocity."""
    V = np.sqrt(u * u + v * v + w * w)
    alpha_r = np.arctan2(np.sqrt(v * v + w * w), u)
    phi_r = np.arctan2(v, w)
    return V, alpha_r, phi_r


class Plant:
    """Right-hand side of the equations of motion for one vehicle and aero model."""

    def __init__(self, vehicle: Vehicle, model: AeroModel):
        self.vehicle = vehicle
        self.model = model
        self.inertia = vehicle.inertia
        self.atmosphere = FastAtmosphere()

    def forces_moments(self, state, controls):
        """Specific force [m/s^2] and (L/Ixx, M/Iyy, N/Izz) [rad/s^2] in body axes, plus air data."""
        veh = self.vehicle
        q0, q1, q2, q3 = state[6:10]
        p, q, r = state[10:13]
        C = quat_to_dcm(q0, q1, q2, q3)
        u, v, w = C.T @ state[3:6]
        V, alpha_r, phi_r = aero_angles(u, v, w)
        rho, a, g = self.atmosphere(-state[2])
        qbar = 0.5 * rho * V * V
        mach = V / a
        dp, dy, dr = controls[:3]
        # entries past the three fins (time, lagged fin) feed uncatalogued effects (simulation.hidden)
        c = self.model.coefficients(alpha_r, phi_r, mach, dp, dy, dr, p, q, r, V, qbar, *controls[3:])
        qs = qbar * veh.S_m2
        qsd = qs * veh.d_m
        f = (-c["CA"] * qs / veh.mass_kg, c["CY"] * qs / veh.mass_kg, -c["CN"] * qs / veh.mass_kg)
        mom = (c["Cl"] * qsd / veh.Ixx_kg_m2, c["Cm"] * qsd / veh.Iyy_kg_m2, c["Cn"] * qsd / veh.Izz_kg_m2)
        return C, f, mom, g

    def derivative(self, state, controls):
        C, f, mom, g = self.forces_moments(state, controls)
        vn, ve, vd = state[3:6]
        q0, q1, q2, q3 = state[6:10]
        p, q, r = state[10:13]
        h = -state[2]
        acc = C @ np.asarray(f)
        acc[2] += g - (vn * vn + ve * ve) / (R_EARTH_M + h)
        pd, qd, rd = body_rate_derivatives(p, q, r, mom[0], mom[1], mom[2], self.inertia)
        norm_err = 1.0 - (q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        k = 1.0  # pulls |quat| back to 1 (drift correction)
        return np.array([
            vn, ve, vd, acc[0], acc[1], acc[2],
            0.5 * (-q1 * p - q2 * q - q3 * r) + k * norm_err * q0,
            0.5 * (q0 * p + q2 * r - q3 * q) + k * norm_err * q1,
            0.5 * (q0 * q - q1 * r + q3 * p) + k * norm_err * q2,
            0.5 * (q0 * r + q1 * q - q2 * p) + k * norm_err * q3,
            pd, qd, rd,
        ])


def integrate(plant: Plant, x0: np.ndarray, t: np.ndarray, controller,
              progress: Callable[[str, float], None] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """RK4 over the sample grid t [s]; controller(t, state) -> (delta_p, delta_y, delta_r)
    held over each step (a controller may return extra entries after the three fins, which the
    plant passes on to the aero model).  Returns states (N,13) and controls (N,3+) at the samples.
    progress: called as progress("integrate", fraction done) about 200 times."""
    n = len(t)
    every = max(1, n // 200)
    states = np.empty((n, 13))
    controls = None
    x = np.asarray(x0, dtype=float)
    for k in range(n):
        states[k] = x
        u = controller(t[k], x)
        if controls is None:  # 3 fins, or more entries for uncatalogued effects (simulation.hidden)
            controls = np.empty((n, len(u)))
        controls[k] = u
        if k == n - 1:
            break
        if progress is not None and k % every == 0:
            progress("integrate", k / (n - 1))
        dt_total = t[k + 1] - t[k]
        sub = max(1, int(math.ceil(dt_total / 0.01 - 1e-9)))
        h = dt_total / sub
        for _ in range(sub):
            k1 = plant.derivative(x, u)
            k2 = plant.derivative(x + 0.5 * h * k1, u)
            k3 = plant.derivative(x + 0.5 * h * k2, u)
            k4 = plant.derivative(x + h * k3, u)
            x = x + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
        if not np.all(np.isfinite(x)) or -x[2] < 0:
            raise RuntimeError(f"simulation left the envelope at t = {t[k + 1]:.2f} s (h = {-x[2]:.0f} m): "
                               "the unpowered glide has run out of energy; shorten --duration")
    return states, controls
