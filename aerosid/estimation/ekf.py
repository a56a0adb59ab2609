"""Plain-numpy EKF step and Modified Bryson-Frazier smoother (method.md §6).

These are the readable reference implementations: dense matrices, the vector
Joseph update with a Cholesky-factored innovation covariance, Bierman's MBF
backward recursion in its vector form.  The fast path (:mod:`._fast`, numba)
computes the same numbers with the plant's structure exploited; the tests check
the two agree to rounding, and check these against filterpy.

Partial updates: ``used`` (6,) bool selects the channels folded in at a sample;
all matrices returned for a sample (H, S, K, v) refer to the used channels only,
in channel order.

Innovation gate: channel by channel in the order ax, ay, az, p, q, r, each
channel's innovation is tested *conditionally on the channels of the same
sample already accepted* (the sequential-scalar form of the update: with R
diagonal, the conditional innovation e_j / sqrt(s_j) is the j-th Cholesky-
whitened innovation).  A channel with e_j^2 / s_j > gate_threshold is flagged
and not used; it does not disturb the test of the channels after it.
Under a correct model each statistic is chi-square with 1 dof, so the default
threshold chi2.isf(1e-6, 1) = 23.9 (4.9 sigma) flags about one good channel-sample
in 10^6.  A gate can hold a channel out for a limited number of consecutive samples
(``gate_hold``); the next sample of that channel is taken without the test (see
:class:`aerosid.estimation.pipeline.EBMOptions`, gyro_gate_hold_s, for why).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve, cholesky, solve_triangular

from .model import N_MEAS, N_STATE, PlantModel, measure, measurement_jacobian, propagate


@dataclass(frozen=True)
class EKFUpdate:
    """One EKF measurement update.

    x (21,), P (21,21): posterior state and covariance (SI units of STATE_NAMES).
    used (6,) bool: channels folded in; gated (6,) bool: channels the innovation gate rejected.
    v (m,): innovations z - h(x_prior) of the used channels [m/s^2 or rad/s];
    H (m,21), S (m,m), K (21,m): Jacobian, innovation covariance, gain.
    nis: v' S^-1 v (NaN if m == 0); dof: m.
    """

    x: np.ndarray
    P: np.ndarray
    used: np.ndarray
    gated: np.ndarray
    v: np.ndarray
    H: np.ndarray
    S: np.ndarray
    K: np.ndarray
    nis: float
    dof: int

    def summary(self) -> str:
        lines = [f"EKF update: {self.dof} channels used, NIS = {self.nis:.3f}",
                 f"{'channel':>8} {'used':>5} {'gated':>6}"]
        names = ("ax", "ay", "az", "p", "q", "r")
        for j in range(N_MEAS):
            lines.append(f"{names[j]:>8} {bool(self.used[j])!s:>5} {bool(self.gated[j])!s:>6}")
        return "\n".join(lines)


def ekf_predict(x: np.ndarray, P: np.ndarray, model: PlantModel, Qd: np.ndarray):
    """Time update over model.dt_s [s]: returns (x_pred, P_pred, Phi).

    P_pred = Phi P Phi' + Qd, with Phi the exact Jacobian of the discrete map
    (model.propagate).  P_pred is symmetrised.
    """
    xn, Phi = propagate(x, model)
    Pn = Phi @ P @ Phi.T + Qd
    Pn = 0.5 * (Pn + Pn.T)
    return xn, Pn, Phi


def gate_channels(v: np.ndarray, S: np.ndarray, candidates: np.ndarray, threshold: float):
    """Sequential conditional innovation gate (module doc).

    v (6,), S (6,6) full-vector innovation and covariance; candidates (6,) bool;
    threshold a number or (6,) per channel (inf: that channel is not gated).
    Returns (accepted (6,) bool, gated (6,) bool).
    """
    thr = np.broadcast_to(np.asarray(threshold, dtype=float), (N_MEAS,))
    accepted = np.zeros(N_MEAS, dtype=bool)
    gated = np.zeros(N_MEAS, dtype=bool)
    acc_idx: list[int] = []
    for j in range(N_MEAS):
        if not candidates[j]:
            continue
        idx = acc_idx + [j]
        Lc = cholesky(S[np.ix_(idx, idx)], lower=True)
        e = solve_triangular(Lc, v[idx], lower=True)
        if np.isfinite(thr[j]) and e[-1] ** 2 > thr[j]:
            gated[j] = True
        else:
            accepted[j] = True
            acc_idx.append(j)
    return accepted, gated


def ekf_update(x: np.ndarray, P: np.ndarray, z: np.ndarray, valid: np.ndarray,
               model: PlantModel, R_diag: np.ndarray, gate_threshold=np.inf) -> EKFUpdate:
    """Measurement update with the valid, non-gated channels.

    z (6,): measurements ax, ay, az [m/s^2], p, q, r [rad/s]; valid (6,) bool
    (a NaN measurement counts as invalid); R_diag (6,): noise variances
    [(m/s^2)^2, (rad/s)^2]; gate_threshold: chi-square(1) limit, one for every channel
    or (6,) per channel (np.inf = no gate).  Joseph form, K from a Cholesky solve (never inv(S)).
    """
    z = np.asarray(z, dtype=float)
    cand = np.asarray(valid, dtype=bool) & np.isfinite(z)
    Hf = measurement_jacobian(x, model)
    vf = np.where(cand, z - measure(x, model), 0.0)
    PHt_f = P @ Hf.T
    Sf = Hf @ PHt_f + np.diag(R_diag)
    used, gated = gate_channels(vf, Sf, cand, gate_threshold)
    idx = np.flatnonzero(used)
    m = idx.size
    if m == 0:
        return EKFUpdate(x.copy(), P.copy(), used, gated, np.zeros(0), np.zeros((0, N_STATE)),
                         np.zeros((0, 0)), np.zeros((N_STATE, 0)), float("nan"), 0)
    H = Hf[idx]
    v = vf[idx]
    S = Sf[np.ix_(idx, idx)]
    R = np.diag(np.asarray(R_diag, dtype=float)[idx])
    cf = cho_factor(S, lower=True)
    K = cho_solve(cf, PHt_f[:, idx].T).T
    xn = x + K @ v
    IKH = np.eye(N_STATE) - K @ H
    Pn = IKH @ P @ IKH.T + K @ R @ K.T
    Pn = 0.5 * (Pn + Pn.T)
    nis = float(v @ cho_solve(cf, v))
    return EKFUpdate(xn, Pn, used, gated, v, H, S, K, nis, m)


@dataclass(frozen=True)
class MBFResult:
    """Output of :func:`mbf_smooth` (dense, per sample).

    x_smooth (N,n), P_smooth (N,n,n): smoothed states and covariances.
    lam (N,n), Lam (N,n,n): adjoint lambda~_k and its information Lambda~_k, i.e.
    carried back to sample k before sample k's own measurement is folded in.
    u: list of (m_k,) arrays S^-1 v + K' lambda~ (the smoothed residual is R u);
    D: list of (m_k,m_k) arrays S^-1 + K' Lambda~ K (Cov of u; Cov of the smoothed
    residual is R D R).
    """

    x_smooth: np.ndarray
    P_smooth: np.ndarray
    lam: np.ndarray
    Lam: np.ndarray
    u: list
    D: list

    def summary(self) -> str:
        sig = np.sqrt(np.maximum(np.diagonal(self.P_smooth, axis1=1, axis2=2), 0.0))
        return (f"MBF smoother: {self.x_smooth.shape[0]} samples, {self.x_smooth.shape[1]} states; "
                f"median smoothed sigma per state: " + ", ".join(f"{s:.3g}" for s in np.median(sig, axis=0)))


def mbf_smooth(x_filt, P_filt, Phi, H, v, S, K) -> MBFResult:
    """Bierman's Modified Bryson-Frazier smoother (method.md §6), vector form.

    x_filt (N,n), P_filt (N,n,n): filtered x(k|k), P(k|k).
    Phi: (N,n,n) with Phi[k] the transition from sample k-1 to k (Phi[0] unused).
    H, v, S, K: sequences of length N of the used-channel Jacobian (m_k,n),
    innovation (m_k,), innovation covariance (m_k,m_k) and gain (n,m_k); m_k = 0
    means no update at k (then lambda^_k = lambda~_k).

    Backward, from lambda~_{N-1} = 0, Lambda~_{N-1} = 0, with C = I - K H:
        lambda^_k = -H' S^-1 v + C' lambda~_k,    Lambda^_k = H' S^-1 H + C' Lambda~_k C
        lambda~_{k-1} = Phi_k' lambda^_k,          Lambda~_{k-1} = Phi_k' Lambda^_k Phi_k
        x(k|N) = x(k|k) - P(k|k) lambda~_k,        P(k|N) = P(k|k) - P(k|k) Lambda~_k P(k|k)
    S^-1 is applied by Cholesky solves.
    """
    x_filt = np.asarray(x_filt, dtype=float)
    N, n = x_filt.shape
    xs = np.empty_like(x_filt)
    Ps = np.empty((N, n, n))
    lam_out = np.empty((N, n))
    Lam_out = np.empty((N, n, n))
    u_out: list = [None] * N
    D_out: list = [None] * N
    lam = np.zeros(n)
    Lam = np.zeros((n, n))
    eye = np.eye(n)
    for k in range(N - 1, -1, -1):
        Pk = P_filt[k]
        lam_out[k] = lam
        Lam_out[k] = Lam
        xs[k] = x_filt[k] - Pk @ lam
        Pk_s = Pk - Pk @ Lam @ Pk
        Ps[k] = 0.5 * (Pk_s + Pk_s.T)
        m = 0 if H[k] is None else np.asarray(H[k]).shape[0]
        if m > 0:
            Hk, vk, Kk = np.asarray(H[k]), np.asarray(v[k]), np.asarray(K[k])
            cf = cho_factor(np.asarray(S[k]), lower=True)
            Sinv_v = cho_solve(cf, vk)
            Sinv_H = cho_solve(cf, Hk)
            u_out[k] = Sinv_v + Kk.T @ lam
            D_out[k] = cho_solve(cf, np.eye(m)) + Kk.T @ Lam @ Kk
            C = eye - Kk @ Hk
            lam = -Hk.T @ Sinv_v + C.T @ lam
            Lam = Hk.T @ Sinv_H + C.T @ Lam @ C
            Lam = 0.5 * (Lam + Lam.T)
        else:
            u_out[k] = np.zeros(0)
            D_out[k] = np.zeros((0, 0))
        if k > 0:
            F = Phi[k]
            lam = F.T @ lam
            Lam = F.T @ Lam @ F
    return MBFResult(xs, Ps, lam_out, Lam_out, u_out, D_out)


@dataclass(frozen=True)
class ReferenceRun:
    """Everything the plain-numpy filter + smoother computed (store='full')."""

    x_filter: np.ndarray
    P_filter: np.ndarray
    x_smooth: np.ndarray
    P_smooth: np.ndarray
    nis_filter: np.ndarray
    dof: np.ndarray
    nis_smoother: np.ndarray
    used: np.ndarray
    gated: np.ndarray
    updates: list
    Phi: np.ndarray

    def summary(self) -> str:
        return (f"reference run: {self.x_filter.shape[0]} samples, mean NIS filter "
                f"{np.nanmean(self.nis_filter):.3f}, smoother {np.nanmean(self.nis_smoother):.3f}")


def run_reference(z, valid, x0, P0, model: PlantModel, Qd, R_diag, gate_threshold=np.inf,
                  gate_hold=None) -> ReferenceRun:
    """Filter + MBF smoother over all samples with the numpy functions above.

    x0, P0 are the prior at sample 0 (x(0|-1), P(0|-1)); Qd (21,21), or (N,21,21) for a
    time-varying process noise (Qd[k]: the transition into sample k); gate_threshold a number
    or (N,) per sample (inf: no gate there); gate_hold (6,) int or None: after this many
    consecutive gated samples a channel's next sample is taken without the gate (0: no
    limit; module doc).  Smoother NIS at k is
    sum_j e_j^2 / Var(e_j) with e = z - h(x(k|N)) and Var(e) = diag(R D R)
    (see :class:`aerosid.estimation.pipeline.EBMResult`).
    """
    z = np.asarray(z, dtype=float)
    N = z.shape[0]
    R_diag = np.asarray(R_diag, dtype=float)
    xf = np.empty((N, N_STATE))
    Pf = np.empty((N, N_STATE, N_STATE))
    Phi = np.zeros((N, N_STATE, N_STATE))
    nis = np.full(N, np.nan)
    dof = np.zeros(N, dtype=np.int64)
    used = np.zeros((N, N_MEAS), dtype=bool)
    gated = np.zeros((N, N_MEAS), dtype=bool)
    ups = []
    hold = np.zeros(N_MEAS, int) if gate_hold is None else np.asarray(gate_hold, int)
    runs = np.zeros(N_MEAS, int)  # consecutive gated samples per channel
    x, P = np.asarray(x0, float).copy(), np.asarray(P0, float).copy()
    for k in range(N):
        if k > 0:
            x, P, Phi[k] = ekf_predict(x, P, model, Qd[k] if np.ndim(Qd) == 3 else Qd)
        thr = gate_threshold[k] if np.ndim(gate_threshold) else gate_threshold
        up = ekf_update(x, P, z[k], valid[k], model, R_diag, np.where((hold > 0) & (runs >= hold), np.inf, thr))
        ups.append(up)
        x, P = up.x, up.P
        xf[k], Pf[k] = x, P
        nis[k], dof[k] = up.nis, up.dof
        used[k], gated[k] = up.used, up.gated
        runs = np.where(up.gated, runs + 1, np.where(up.used, 0, runs))
    sm = mbf_smooth(xf, Pf, Phi, [u.H if u.dof else None for u in ups], [u.v for u in ups],
                    [u.S for u in ups], [u.K for u in ups])
    nis_s = np.full(N, np.nan)
    for k in range(N):
        if ups[k].dof == 0:
            continue
        idx = np.flatnonzero(used[k])
        e = z[k, idx] - measure(sm.x_smooth[k], model)[idx]
        r = R_diag[idx]
        var = r * r * np.diag(sm.D[k])
        nis_s[k] = float(np.sum(e * e / var))
    return ReferenceRun(xf, Pf, sm.x_smooth, sm.P_smooth, nis, dof, nis_s, used, gated, ups, Phi)
