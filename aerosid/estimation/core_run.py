"""One EKF + MBF smoother pass over a segment (:func:`run_filter_smoother`) and its raw
per-sample output (:class:`CoreRun`): the compiled kernel (:mod:`._fast`) or the plain-numpy
reference (:mod:`.ekf`), same definitions.

Time-varying process noise: ``q_local`` (N,6), a multiplier on each chain's (X, Y, Z, L, M,
N) intensity on the transition into each sample; the step's Q is Qd + sum_c (m_c - 1) Qc_c
with Qc_c chain c's share of Qd.  All ones (or None) is the stationary filter, bit for bit.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cholesky, solve_triangular

from . import _fast
from .ekf import run_reference
from .model import (IX_ANG, N_MEAS, N_STATE, PlantModel, discrete_process_noise, measure, rate_jacobian,
                    rate_rhs)


def chain_shares(q_chain: np.ndarray, model: PlantModel) -> np.ndarray:
    """(6, 21, 21): chain c's share of the discrete Q for intensities q_chain (its triple
    integrator block and its part of the rate block); they sum to discrete_process_noise(q_chain)."""
    q = np.asarray(q_chain, dtype=float)
    return np.stack([discrete_process_noise(np.where(np.arange(6) == c, q, 0.0), model) for c in range(6)])


@dataclass(frozen=True)
class CoreRun:
    """Raw output of one filter + smoother pass (arrays per sample)."""

    x_filter: np.ndarray
    sigma_filter: np.ndarray
    x_smooth: np.ndarray
    sigma_smooth: np.ndarray
    nis_filter: np.ndarray
    nis_smoother: np.ndarray
    dof: np.ndarray
    used: np.ndarray
    gated: np.ndarray
    angacc: np.ndarray
    angacc_sigma: np.ndarray
    chan_nis_filter: np.ndarray
    chan_nis_smoother: np.ndarray
    chan_count: np.ndarray
    em_R: np.ndarray
    bad_variances: int
    innovation_sq: np.ndarray | None = None  # (N,6) v^2/s per channel tested (gated too), NaN if not


    def summary(self) -> str:
        return (f"core run: {self.x_filter.shape[0]} samples, mean NIS filter {np.nanmean(self.nis_filter):.3f}, "
                f"smoother {np.nanmean(self.nis_smoother):.3f}")


#: A sample interval [s] above which a breakdown's message names the coarse sampling (below 20 Hz).
COARSE_DT_S = 0.05


class FilterBreakdown(ArithmeticError):
    """The EKF's covariance lost positive definiteness (a Cholesky factor of the innovation
    covariance failed): a numerical breakdown of the filter, not a poor fit."""


def run_filter_smoother(z, cand, x0, P0, model: PlantModel, Qd, R_diag, gate_threshold=np.inf,
                        use_numba: bool = True, segment_length: int = 64, q_local=None,
                        q_shares=None, gate_off=None, gate_hold=None) -> CoreRun:
    """One EKF + MBF pass (_run_filter_smoother); a numerical breakdown of the covariance
    raises FilterBreakdown naming the sample interval, not the kernel's bare ZeroDivisionError
    (c182 thinned to 5 Hz: "division by zero")."""
    try:
        return _run_filter_smoother(z, cand, x0, P0, model, Qd, R_diag, gate_threshold, use_numba, segment_length,
                                    q_local, q_shares, gate_off, gate_hold)
    except (ZeroDivisionError, np.linalg.LinAlgError) as exc:
        coarse = (f" A record sampled below {1 / COARSE_DT_S:g} Hz gives the filter few samples per period of the "
                  "vehicle's motion; a faster record may run." if model.dt_s > COARSE_DT_S else "")
        raise FilterBreakdown(
            f"the filter's innovation covariance lost positive definiteness ({exc}) at a sample interval of "
            f"{model.dt_s:.4g} s: a numerical breakdown, not a fit.{coarse}") from None


def _run_filter_smoother(z, cand, x0, P0, model: PlantModel, Qd, R_diag, gate_threshold=np.inf,
                         use_numba: bool = True, segment_length: int = 64, q_local=None,
                         q_shares=None, gate_off=None, gate_hold=None) -> CoreRun:
    """One EKF + MBF pass.  z (N,6), cand (N,6) bool (channels allowed), x0/P0 prior at
    sample 0, Qd (21,21), R_diag (6,), gate_threshold (chi2(1) per channel, inf = off);
    q_local (N,6) chain multipliers per transition with q_shares (6,21,21) the chains'
    shares of Qd (:func:`chain_shares`), or None: stationary (module doc); gate_off (N,)
    bool: samples where the gate is lifted (None: nowhere); gate_hold (6,) int: the most
    consecutive samples a channel is gated before it is taken once without its gate (0 or
    None: no limit; :func:`aerosid.estimation.ekf.run_reference`)."""
    z = np.ascontiguousarray(z, dtype=np.float64)
    cand = np.ascontiguousarray(cand, dtype=np.bool_) & np.isfinite(z)
    zz = np.where(cand, z, 0.0)
    N = z.shape[0]
    R_diag = np.ascontiguousarray(R_diag, dtype=np.float64)
    qm = np.ones((N, 6)) if q_local is None else np.ascontiguousarray(q_local, dtype=np.float64)
    if qm.shape != (N, 6) or not np.all(np.isfinite(qm) & (qm > 0)):
        raise ValueError(f"q_local must be ({N}, 6), finite and positive; got shape {qm.shape}")
    local = bool(np.any(qm != 1.0))
    if local and q_shares is None:
        raise ValueError("q_local other than ones needs q_shares (chain_shares of the chain intensities)")
    Qc = np.zeros((6, N_STATE, N_STATE)) if q_shares is None else np.asarray(q_shares, dtype=np.float64)
    lifted = None if gate_off is None else np.ascontiguousarray(gate_off, dtype=np.bool_)
    if lifted is not None and lifted.shape != (N,):
        raise ValueError(f"gate_off must be ({N},) bool; got shape {lifted.shape}")
    hold = np.zeros(N_MEAS, np.int64) if gate_hold is None else np.ascontiguousarray(gate_hold, dtype=np.int64)
    if hold.shape != (N_MEAS,) or np.any(hold < 0):
        raise ValueError(f"gate_hold must be ({N_MEAS},) non-negative integers; got {gate_hold!r}")
    if not use_numba:
        Qk = Qd + np.einsum("kc,cij->kij", qm - 1.0, Qc) if local else Qd
        thr = gate_threshold if lifted is None else np.where(lifted, np.inf, gate_threshold)
        return _core_from_reference(run_reference(zz, cand, x0, P0, model, Qk, R_diag, thr, hold),
                                    zz, model, R_diag)
    seg = int(segment_length)
    nseg = (N + seg - 1) // seg
    NP = _fast.NP
    x0p = np.zeros(NP)
    x0p[:N_STATE] = x0
    P0p = np.zeros((NP, NP))
    P0p[:N_STATE, :N_STATE] = P0
    Qdp = np.zeros((NP, NP))
    Qdp[:N_STATE, :N_STATE] = Qd
    Qcp = np.zeros((6, NP, NP))
    Qcp[:, :N_STATE, :N_STATE] = Qc
    qk = qm if local else np.ones((0, 6))  # no rows: the kernel's stationary path, no per-step test
    innov = np.empty((N, N_MEAS))
    xf = np.empty((N, N_STATE))
    sf = np.empty((N, N_STATE))
    nis = np.empty(N)
    dof = np.empty(N, dtype=np.int64)
    used = np.empty((N, N_MEAS), dtype=np.bool_)
    gated = np.empty((N, N_MEAS), dtype=np.bool_)
    ckpt = np.empty((nseg, NP, NP))
    xs = np.empty((N, N_STATE))
    ss = np.empty((N, N_STATE))
    nis_s = np.empty(N)
    aa = np.empty((N, 3))
    aas = np.empty((N, 3))
    stats = np.zeros((5, N_MEAS))   # e2, var, n, chan nis smoother, chan nis filter
    Pb = np.empty((seg, NP, NP))
    Kb = np.zeros((seg, N_MEAS, NP))
    Hb = np.zeros((seg, N_MEAS, NP))
    vb = np.zeros((seg, N_MEAS))
    sb = np.ones((seg, N_MEAS))
    Fb = np.zeros((seg, 3, 12))
    thr = float(gate_threshold)
    do_gate = bool(np.isfinite(thr))
    bad = _fast.run(zz, cand, x0p, P0p, model.params, Qdp, Qcp, qk, R_diag,
                    thr if do_gate else 0.0, do_gate,
                    np.ones(0, np.bool_) if lifted is None else ~lifted, hold, seg, xf, sf, nis, dof, used, gated, ckpt,
                    xs, ss, nis_s, aa, aas, stats, Pb, Kb, Hb, vb, sb, Fb, innov)
    with np.errstate(invalid="ignore", divide="ignore"):
        em_R = (stats[0] + stats[1]) / stats[2]
    return CoreRun(xf, sf, xs, ss, nis, nis_s, dof, used, gated, aa, aas, stats[4], stats[3], stats[2],
                   em_R, int(bad), innov)


def _core_from_reference(ref, z, model: PlantModel, R_diag) -> CoreRun:
    """CoreRun from the plain-numpy run (same definitions as the compiled kernel)."""
    N = z.shape[0]
    prm = model.params
    Bm = model.input_matrix
    sf = np.sqrt(np.maximum(np.diagonal(ref.P_filter, axis1=1, axis2=2), 0.0))
    ss = np.sqrt(np.maximum(np.diagonal(ref.P_smooth, axis1=1, axis2=2), 0.0))
    aa = np.empty((N, 3))
    aas = np.empty((N, 3))
    cf = np.zeros(N_MEAS)
    cs = np.zeros(N_MEAS)
    cn = np.zeros(N_MEAS)
    e2 = np.zeros(N_MEAS)
    ev = np.zeros(N_MEAS)
    innov = np.full((N, N_MEAS), np.nan)  # the used channels' (the gated ones' are not kept)
    for k in range(N):
        xs = ref.x_smooth[k]
        aa[k] = rate_rhs(xs[0:3], xs[list(IX_ANG)], prm)
        J = np.zeros((3, N_STATE))
        J[:, 0:3] = rate_jacobian(xs[0:3], prm)
        J[:, list(IX_ANG)] = Bm
        aas[k] = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", J, ref.P_smooth[k], J), 0.0))
        up = ref.updates[k]
        if up.dof == 0:
            continue
        idx = np.flatnonzero(up.used)
        wv = solve_triangular(cholesky(up.S, lower=True), up.v, lower=True)
        cf[idx] += wv**2
        innov[k, idx] = wv**2
        e = z[k, idx] - measure(xs, model)[idx]
        r = R_diag[idx]
        var_e = r - np.diag(up.H @ ref.P_smooth[k] @ up.H.T)   # = R D R (MBF), diagonal
        cs[idx] += e * e / var_e
        cn[idx] += 1.0
        e2[idx] += e * e
        ev[idx] += r - var_e
    with np.errstate(invalid="ignore", divide="ignore"):
        em_R = (e2 + ev) / cn
    return CoreRun(ref.x_filter, sf, ref.x_smooth, ss, ref.nis_filter, ref.nis_smoother, ref.dof, ref.used,
                   ref.gated, aa, aas, cf, cs, cn, em_R, 0, innov)
