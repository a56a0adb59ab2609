"""Synthetic 21-state truth and measurements for tests and benchmarks.

The angular accelerations (L, M, N hat) and the CG accelerations are sums of
sines below ``f_max_hz`` (their chain derivatives are analytic); the body rates
are integrated from the Euler equations with scipy's DOP853 (tight tolerances,
independent of the filter's RK4); the measurements are h(x_true) (method.md §5)
plus white Gaussian noise of the given sigmas.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from .model import IX_ACC, IX_ANG, N_STATE, PlantModel, measure, rate_rhs

#: noise sigmas of the seed's Table 2: ax, ay, az [m/s^2], p, q, r [rad/s]
SEED_NOISE_SIGMA = (0.8, 1.0, 2.0, np.deg2rad(4.0), np.deg2rad(2.0), np.deg2rad(1.0))
#: an RLV-like inertia (Ixx, Iyy, Izz, Ixz) [kg m^2]
RLV_INERTIA = (150.0, 2500.0, 2550.0, 12.0)
#: accelerometer position relative to the CG [m]
RLV_OFFSET = (1.0, 0.03, -0.05)


@dataclass(frozen=True)
class SyntheticFlight:
    """t_s (N,) [s]; x_true (N,21) (STATE_NAMES units); z_clean, z (N,6) (MEAS_NAMES units);
    noise_sigma (6,); model: the PlantModel used."""

    t_s: np.ndarray
    x_true: np.ndarray
    z_clean: np.ndarray
    z: np.ndarray
    noise_sigma: np.ndarray
    model: PlantModel

    def summary(self) -> str:
        return (f"synthetic flight: {self.t_s.size} samples at {1.0 / self.model.dt_s:g} Hz, "
                f"noise sigma {np.array2string(np.asarray(self.noise_sigma), precision=4)}")


def _sines(rng, n, f_lo, f_hi, amp):
    f = rng.uniform(f_lo, f_hi, n)
    a = amp * rng.uniform(0.3, 1.0, n) / np.sqrt(n)
    ph = rng.uniform(0, 2 * np.pi, n)
    return f, a, ph


def _chain(t, bias, f, a, ph):
    """value, 1st, 2nd derivative of bias + sum a sin(2 pi f t + ph)."""
    w = 2 * np.pi * f
    arg = np.outer(t, w) + ph
    s, c = np.sin(arg), np.cos(arg)
    return (bias + s @ a, c @ (a * w), -(s @ (a * w * w)))


def simulate_flight(duration_s: float = 80.0, rate_hz: float = 100.0, noise_sigma=SEED_NOISE_SIGMA,
                    inertia_kg_m2=RLV_INERTIA, sensor_offset_m=RLV_OFFSET, seed: int = 0,
                    f_max_hz: float = 2.0, n_sines: int = 4, ang_amp_rad_s2: float = 1.5,
                    acc_amp_m_s2: float = 8.0) -> SyntheticFlight:
    """Simulate a flight: see module doc.  Amplitudes: ang_amp_rad_s2 (angular
    accelerations, rad/s^2), acc_amp_m_s2 (CG accelerations, m/s^2) before the
    1/sqrt(n_sines) split."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate_hz
    N = int(round(duration_s * rate_hz))
    t = np.arange(N) * dt
    model = PlantModel(tuple(inertia_kg_m2), tuple(sensor_offset_m), dt)
    prm = model.params
    x = np.zeros((N, N_STATE))
    ang = []
    for i, s in enumerate(IX_ANG):
        f, a, ph = _sines(rng, n_sines, 0.1, f_max_hz, ang_amp_rad_s2)
        bias = rng.normal(0, 0.05)
        ang.append((bias, f, a, ph))
        x[:, s], x[:, s + 1], x[:, s + 2] = _chain(t, bias, f, a, ph)
    for i, s in enumerate(IX_ACC):
        f, a, ph = _sines(rng, n_sines, 0.1, f_max_hz, acc_amp_m_s2)
        bias = (0.5, -0.3, -9.0)[i]
        x[:, s], x[:, s + 1], x[:, s + 2] = _chain(t, bias, f, a, ph)

    def u_of(tt):
        return np.array([_chain(np.atleast_1d(tt), *ang[i])[0][0] for i in range(3)])

    def rhs(tt, w):
        return rate_rhs(w, u_of(tt), prm)

    w0 = rng.normal(0, 0.05, 3)
    sol = solve_ivp(rhs, (0.0, t[-1]), w0, method="DOP853", t_eval=t, rtol=1e-11, atol=1e-12)
    x[:, 0:3] = sol.y.T
    zc = np.array([measure(x[k], model) for k in range(N)])
    sig = np.asarray(noise_sigma, dtype=float)
    z = zc + rng.standard_normal((N, 6)) * sig
    return SyntheticFlight(t, x, zc, z, sig, model)
