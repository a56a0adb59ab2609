"""Where the accelerometer sits: recovered from accelerations at the sensor and at the CG.

A flight-test file that holds both the accelerations as measured and the same
accelerations moved to the CG (SIDPAC's data-compatibility output does) fixes the
sensor's position r relative to the CG: their difference is the lever-arm term
omega_dot x r + omega x (omega x r) (aerosid.vehicles.rigid_body.lever_arm_acceleration),
linear in r, plus a constant per axis when the CG values also had a bias removed.
A least-squares fit of the difference on those terms returns r, the biases and the
residual; a residual at the recording resolution means the file's own correction
used exactly this r.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aerosid.vehicles.rigid_body import lever_arm_acceleration

#: The fit is trusted when its residual RMS is below this [m/s^2] (1e-3 g; SIDPAC's
#: Twin Otter files give ~1.6e-5 m/s^2) and every offset component's sigma below
#: MAX_OFFSET_SIGMA_M.
MAX_RESIDUAL_M_S2 = 9.80665e-3
MAX_OFFSET_SIGMA_M = 0.02


@dataclass(frozen=True)
class AccelOffsetFit:
    """Least-squares accelerometer position relative to the CG (body axes x fwd, y right, z down)."""

    offset_m: tuple[float, float, float]
    sigma_m: tuple[float, float, float]  # 1-sigma of each component (OLS, from the residual)
    bias_m_s2: tuple[float, float, float]  # constant (sensor - CG - lever arm) per axis
    residual_rms_m_s2: float
    n_samples: int
    trusted: bool  # residual and sigmas within MAX_RESIDUAL_M_S2, MAX_OFFSET_SIGMA_M
    reason: str = ""  # why not trusted

    def summary(self) -> str:
        x, y, z = self.offset_m
        bx, by, bz = self.bias_m_s2
        head = (f"accelerometer at ({x:.3f}, {y:.3f}, {z:.3f}) m from the CG "
                f"(sigma {max(self.sigma_m):.1e} m), bias ({bx:.4f}, {by:.4f}, {bz:.4f}) m/s^2, "
                f"residual RMS {self.residual_rms_m_s2:.2e} m/s^2 over {self.n_samples} samples")
        return head + ("" if self.trusted else f"; NOT used: {self.reason}")


def recover_accel_offset(p, q, r, p_dot, q_dot, r_dot, a_sensor, a_cg) -> AccelOffsetFit:
    """Fit a_sensor - a_cg = lever_arm(r) + bias (per axis) over all finite samples.

    Rates [rad/s], angular accelerations [rad/s^2], accelerations (n, 3) [m/s^2].
    """
    a_sensor = np.asarray(a_sensor, dtype=float)
    a_cg = np.asarray(a_cg, dtype=float)
    rates = [np.asarray(v, dtype=float) for v in (p, q, r, p_dot, q_dot, r_dot)]
    ok = np.isfinite(a_sensor).all(axis=1) & np.isfinite(a_cg).all(axis=1)
    for v in rates:
        ok &= np.isfinite(v)
    n = int(ok.sum())
    if n < 10:
        return AccelOffsetFit((0.0, 0.0, 0.0), (np.inf,) * 3, (0.0, 0.0, 0.0), np.inf, n, False,
                              f"only {n} samples with every signal finite")
    rates = [v[ok] for v in rates]
    # one column per offset component: the lever-arm acceleration of a unit offset
    cols = [np.concatenate(lever_arm_acceleration(*rates, e)) for e in np.eye(3)]
    for axis in range(3):  # a constant per axis
        cols.append(np.concatenate([np.full(n, float(axis == k)) for k in range(3)]))
    A = np.column_stack(cols)
    y = (a_sensor[ok] - a_cg[ok]).T.reshape(-1)
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    resid = y - A @ coef
    dof = max(len(y) - A.shape[1], 1)
    s2 = float(resid @ resid) / dof
    try:
        cov = s2 * np.linalg.inv(A.T @ A)
        sigma = tuple(float(np.sqrt(max(cov[i, i], 0.0))) for i in range(3))
    except np.linalg.LinAlgError:
        sigma = (np.inf,) * 3
    rms = float(np.sqrt(np.mean(resid**2)))
    reasons = []
    if rms > MAX_RESIDUAL_M_S2:
        reasons.append(f"residual RMS {rms:.3g} m/s^2 > {MAX_RESIDUAL_M_S2:g}: the CG values are not the sensor's "
                       "moved by a fixed lever arm")
    if not max(sigma) <= MAX_OFFSET_SIGMA_M:
        reasons.append(f"offset sigma {max(sigma):.3g} m > {MAX_OFFSET_SIGMA_M:g} m: the manoeuvre's rotation does "
                       "not determine it")
    return AccelOffsetFit(tuple(float(v) for v in coef[:3]), sigma, tuple(float(v) for v in coef[3:]), rms, n,
                          not reasons, "; ".join(reasons))
