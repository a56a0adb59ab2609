"""Compiled (numba) EKF + MBF smoother exploiting the plant's structure.

Same mathematics as :mod:`.ekf` (the tests check agreement to rounding), but:

* Phi is never formed: the six chain blocks are the known triple-integrator
  matrix and only the 3 x 12 rate rows (d omega_{k+1} / d(omega, L, M, N chains))
  are computed, so Phi P Phi' costs ~2.3e3 multiply-adds instead of 1.9e4.
* R is diagonal, so the vector update is done as six scalar updates (exactly
  equivalent), each in Joseph form
      P+ = (I - k h') P (I - k h')' + r k k' = P - (k u' + u k') + s k k',
  u = P h, s = h'u + r, k = u / s, written so that P+ is bitwise symmetric.
  h has at most 7 non-zeros.  NIS = sum of v_j^2 / s_j of the sequential
  (conditional) innovations = v' S^-1 v.
* The MBF backward recursion is run scalar by scalar in reverse channel order
  (Lambda <- (I - h k') Lambda (I - k h') + h h'/s touches only the rows and
  columns in h's support).
* Memory: the forward pass stores the filtered state and sigma (outputs), the
  used/gated flags and P(k|k) only every ``seg`` samples (checkpoints).  The
  backward pass re-runs the forward covariance recursion segment by segment
  from its checkpoint (bit-identical: same code, same inputs, gate decisions
  replayed from the stored flags) into a small segment buffer, then sweeps
  the segment backward.  Cost: the covariance recursion runs twice; memory:
  21*21*8/seg bytes per sample for the checkpoints plus a fixed buffer.

Array layouts: x (24,), P (24,24) C-contiguous float64, padded with three zero
states so that row loops have a trip count LLVM vectorises; F (3,12) are the rate
rows of Phi over the columns (p, q, r, L1, L2, L3, M1, M2, M3, N1, N2, N3).
prm: see model.PRM_LEN.
"""
from __future__ import annotations

import numpy as np
from numba import njit

# the plant and the covariance algebra (NP, _propagate, _measure are also used from here by
# estimation/pipeline.py and bench/bench_filter.py)
from ._fast_linalg import _carry_back, _nz, _predict_cov, _symm, _symv, _update
from ._fast_plant import NM, NP, NS, _measure, _propagate  # noqa: F401


@njit(cache=True)
def _step_q(Qd, Qc, qm, k, Qk):
    """The process noise of the transition into sample k: Qd itself when every chain's
    multiplier qm[k] is one (the stationary path, bit for bit), else
    Qk = Qd + sum_c (qm[k, c] - 1) Qc[c] (Qc[c]: chain c's share of Qd, its rate block
    included) -- a chain's spectral intensity scaled locally.  qm with no rows: Qd throughout."""
    if qm.shape[0] == 0:
        return Qd
    one = True
    for c in range(qm.shape[1]):
        if qm[k, c] != 1.0:
            one = False
    if one:
        return Qd
    for a in range(NP):
        for b in range(NP):
            Qk[a, b] = Qd[a, b]
    for c in range(qm.shape[1]):
        f = qm[k, c] - 1.0
        if f != 0.0:
            Qc_ = Qc[c]
            for a in range(NP):
                for b in range(NP):
                    Qk[a, b] += f * Qc_[a, b]
    return Qk


@njit(cache=True)
def forward(z, cand, x0, P0, prm, Qd, Qc, qm, rdiag, gate_thr, do_gate, gate_on, hold, seg,
            xf, sf, nis, dof, used, gated, ckpt, stats, innov):
    """Forward EKF over all samples.  x0 (24,), P0, Qd (24,24) padded; Qc (6,24,24) the
    chains' shares of Qd and qm (N,6) their multipliers on the transition into sample k
    (time-varying process noise, :func:`_step_q`; all ones or no rows: Qd itself); gate_on (N,)
    bool, the samples where the gate applies when do_gate (no rows: everywhere); hold (6,)
    int: after this many consecutive gated samples a channel is taken once without its gate
    (0: never; :func:`aerosid.estimation.ekf.run_reference`).  Writes xf, sf
    (N,21) (filtered state and sigma), nis (NaN if no update), dof, used, gated,
    innov (N,6) the standardised conditional innovation squared v^2/s of every channel
    tested, used or gated (NaN if not a candidate), stats[4] (per-channel sum of v^2/s)
    and the checkpoints ckpt[g] = P(k|k) at k = g*seg - 1 (g >= 1).  Returns the count of
    non-positive variances (0 when healthy)."""
    N = z.shape[0]
    dt = prm[12]
    x = x0.copy()
    P = P0.copy()
    xn = np.empty(NP)
    Pn = np.empty((NP, NP))
    A = np.empty((NP, NP))
    F = np.empty((3, 12))
    wv = np.empty((4, 3))
    Wi = np.empty((3, 12))
    J = np.empty((3, 12))
    accJ = np.empty((3, 12))
    hx = np.empty(NM)
    H = np.zeros((NM, NP))
    K = np.zeros((NM, NP))
    v = np.zeros(NM)
    s = np.ones(NM)
    u = np.empty(NP)
    dx = np.empty(NP)
    us = np.zeros(NM, dtype=np.bool_)
    gs = np.zeros(NM, dtype=np.bool_)
    Qk = np.empty((NP, NP))
    thr_k = np.empty(NM)
    runs = np.zeros(NM, dtype=np.int64)
    bad = 0
    for k in range(N):
        if k > 0:
            _propagate(x, prm, xn, F, wv, Wi, J, accJ)
            _predict_cov(P, F, _step_q(Qd, Qc, qm, k, Qk), dt, A, Pn)
            tmpx = x
            x = xn
            xn = tmpx
            tmpP = P
            P = Pn
            Pn = tmpP
        _measure(x, prm, hx, H)
        gate_k = do_gate and (gate_on.shape[0] == 0 or gate_on[k])
        for j in range(NM):
            thr_k[j] = np.inf if (hold[j] > 0 and runs[j] >= hold[j]) else gate_thr
        nk, dk = _update(x, P, z[k], cand[k], rdiag, thr_k, gate_k, hx, H, K, v, s, us, gs, u, dx)
        nis[k] = nk if dk > 0 else np.nan
        dof[k] = dk
        for j in range(NM):
            used[k, j] = us[j]
            gated[k, j] = gs[j]
            if gs[j]:
                runs[j] += 1
            elif us[j]:
                runs[j] = 0
            innov[k, j] = v[j] * v[j] / s[j] if (us[j] or gs[j]) else np.nan
            if us[j]:
                stats[4, j] += v[j] * v[j] / s[j]
        for i in range(NS):
            xf[k, i] = x[i]
            d = P[i, i]
            if d <= 0.0:
                bad += 1
                d = 0.0
            sf[k, i] = np.sqrt(d)
        if (k + 1) % seg == 0 and k + 1 < N:
            g = (k + 1) // seg
            for a in range(NP):
                for b in range(NP):
                    ckpt[g, a, b] = P[a, b]
    return bad


@njit(cache=True)
def backward(z, used, x0, P0, prm, Qd, Qc, qm, rdiag, seg, xf, ckpt,
             xs, ss, nis_s, aa, aa_sig, stats, Pb, Kb, Hb, vb, sb, Fb):
    """MBF backward sweep with segment-wise recomputation of the forward covariances.

    Writes xs, ss (N,21) (smoothed state and sigma), nis_s (smoother NIS, NaN if no
    update), aa, aa_sig (N,3) smoothed angular accelerations p', q', r' and sigma
    [rad/s^2], and per-channel sums into stats (5,6): row 0 sum e^2, row 1 sum
    Var(eps | all data) (for the EM update of R), row 2 count, row 3 sum of
    e^2/Var(e) (row 4 is the filter's sum of v^2/s, written by forward).
    Pb (seg,24,24), Kb, Hb (seg,6,24), vb, sb (seg,6), Fb (seg,3,12) are work buffers.
    """
    N = z.shape[0]
    dt = prm[12]
    c1 = prm[0]
    c2 = prm[1]
    c5 = prm[2]
    c6 = prm[3]
    c8 = prm[4]
    b00 = prm[5]
    b02 = prm[6]
    b20 = prm[7]
    b22 = prm[8]
    nseg = (N + seg - 1) // seg
    lam = np.zeros(NP)
    Lam = np.zeros((NP, NP))
    B = np.empty((NP, NP))
    W = np.empty((NP, NP))
    tmp = np.empty(NP)
    w = np.empty(NP)
    hx = np.empty(NM)
    H = np.zeros((NM, NP))
    x = np.empty(NP)
    P = np.empty((NP, NP))
    xn = np.empty(NP)
    Pn = np.empty((NP, NP))
    A = np.empty((NP, NP))
    wv = np.empty((4, 3))
    Wi = np.empty((3, 12))
    J = np.empty((3, 12))
    accJ = np.empty((3, 12))
    u = np.empty(NP)
    dx = np.empty(NP)
    nz = np.empty(7, dtype=np.int64)
    us = np.zeros(NM, dtype=np.bool_)
    gs = np.zeros(NM, dtype=np.bool_)
    no_gate = np.zeros(NM)  # the replay takes the forward pass's decisions (used[k]): no gate
    inz = np.zeros(NP, dtype=np.bool_)
    Jr = np.zeros((3, NP))
    y = np.empty(NP)
    xsk = np.zeros(NP)
    Qk = np.empty((NP, NP))
    for g in range(nseg - 1, -1, -1):
        k0 = g * seg
        k1 = min(N, k0 + seg)
        # ---- recompute the forward covariances of this segment (same code as forward()),
        #      working directly in the segment buffers
        if g == 0:
            for a in range(NP):
                x[a] = x0[a]
                for b in range(NP):
                    P[a, b] = P0[a, b]
        else:
            for a in range(NP):
                x[a] = xf[k0 - 1, a] if a < NS else 0.0
                for b in range(NP):
                    P[a, b] = ckpt[g, a, b]
        for k in range(k0, k1):
            i = k - k0
            Pi = Pb[i]
            if k > 0:
                _propagate(x, prm, xn, Fb[i], wv, Wi, J, accJ)
                _predict_cov(P if i == 0 else Pb[i - 1], Fb[i], _step_q(Qd, Qc, qm, k, Qk), dt, A, Pi)
                tmpx = x
                x = xn
                xn = tmpx
            else:
                for a in range(NP):
                    for b in range(NP):
                        Pi[a, b] = P[a, b]
            _measure(x, prm, hx, Hb[i])
            _update(x, Pi, z[k], used[k], rdiag, no_gate, False, hx, Hb[i], Kb[i], vb[i], sb[i], us, gs, u, dx)
        # ---- backward sweep over the segment
        for k in range(k1 - 1, k0 - 1, -1):
            i = k - k0
            Pk = Pb[i]
            # smoothed state x(k|N) = x(k|k) - P(k|k) lam~_k
            _symv(Pk, lam, tmp)
            for a in range(NS):
                xsk[a] = xf[k, a] - tmp[a]
                xs[k, a] = xsk[a]
            # smoothed variances: diag(P) - diag(P Lam P);  W = Lam P
            _symm(Lam, Pk, W)
            for b in range(NP):
                tmp[b] = 0.0
            for l in range(0, NP, 4):
                P0r = Pk[l]
                P1r = Pk[l + 1]
                P2r = Pk[l + 2]
                P3r = Pk[l + 3]
                W0r = W[l]
                W1r = W[l + 1]
                W2r = W[l + 2]
                W3r = W[l + 3]
                for b in range(NP):
                    tmp[b] = tmp[b] + ((P0r[b] * W0r[b] + P1r[b] * W1r[b]) + (P2r[b] * W2r[b] + P3r[b] * W3r[b]))
            for a in range(NS):
                d = Pk[a, a] - tmp[a]
                ss[k, a] = np.sqrt(d) if d > 0.0 else 0.0
            # angular accelerations at the smoothed state and their sigma
            p = xsk[0]
            q = xsk[1]
            r = xsk[2]
            L = xsk[12]
            M = xsk[15]
            Nn = xsk[18]
            aa[k, 0] = (c1 * r + c2 * p) * q + b00 * L + b02 * Nn
            aa[k, 1] = c5 * p * r - c6 * (p * p - r * r) + M
            aa[k, 2] = (c8 * p - c2 * r) * q + b20 * L + b22 * Nn
            Jr[0, 0] = c2 * q
            Jr[0, 1] = c1 * r + c2 * p
            Jr[0, 2] = c1 * q
            Jr[1, 0] = c5 * r - 2.0 * c6 * p
            Jr[1, 1] = 0.0
            Jr[1, 2] = c5 * p + 2.0 * c6 * r
            Jr[2, 0] = c8 * q
            Jr[2, 1] = c8 * p - c2 * r
            Jr[2, 2] = -c2 * q
            Jr[0, 12] = b00
            Jr[0, 18] = b02
            Jr[1, 15] = 1.0
            Jr[2, 12] = b20
            Jr[2, 18] = b22
            for ia in range(3):
                # var = J P J' - y' Lam y with y = P J'  (Lam y = W J')
                j0 = Jr[ia, 0]
                j1 = Jr[ia, 1]
                j2 = Jr[ia, 2]
                j3 = Jr[ia, 12]
                j4 = Jr[ia, 15]
                j5 = Jr[ia, 18]
                var = 0.0
                for b in range(NP):
                    y[b] = (j0 * Pk[0, b] + j1 * Pk[1, b] + j2 * Pk[2, b]) + (j3 * Pk[12, b] + j4 * Pk[15, b] + j5 * Pk[18, b])
                for b in range(NP):
                    lb = (j0 * W[b, 0] + j1 * W[b, 1] + j2 * W[b, 2]) + (j3 * W[b, 12] + j4 * W[b, 15] + j5 * W[b, 18])
                    var -= y[b] * lb
                var += (j0 * y[0] + j1 * y[1] + j2 * y[2]) + (j3 * y[12] + j4 * y[15] + j5 * y[18])
                aa_sig[k, ia] = np.sqrt(var) if var > 0.0 else 0.0
            # smoother residuals at the smoothed state; fold the scalars in reverse order
            _measure(xsk, prm, hx, H)
            nsum = 0.0
            anyu = False
            for j in range(NM - 1, -1, -1):
                if not used[k, j]:
                    continue
                anyu = True
                kj = Kb[i, j]
                hj = Hb[i, j]
                m = _nz(j, nz)
                for t in range(m):
                    inz[nz[t]] = True
                _symv(Lam, kj, w)
                alpha = 0.0
                kl = 0.0
                for a in range(NP):
                    alpha += kj[a] * w[a]
                    kl += kj[a] * lam[a]
                sj = sb[i, j]
                dj = 1.0 / sj + alpha
                uj = vb[i, j] / sj + kl
                e = z[k, j] - hx[j]
                rj = rdiag[j]
                var_e = rj * rj * dj
                nsum += e * e / var_e
                stats[0, j] += e * e
                stats[1, j] += rj - var_e
                stats[2, j] += 1.0
                stats[3, j] += e * e / var_e
                # lam^ = lam~ - h u ;  Lam^ = Lam~ - h w' - w h' + d h h'
                for t in range(m):
                    c = nz[t]
                    lam[c] -= hj[c] * uj
                for t in range(m):
                    a = nz[t]
                    ha = hj[a]
                    wa = w[a]
                    La = Lam[a]
                    for b in range(NP):
                        La[b] = (La[b] - (ha * w[b] + wa * hj[b])) + dj * (ha * hj[b])
                for a in range(NP):
                    if inz[a]:
                        continue
                    wa = w[a]
                    for t in range(m):
                        b = nz[t]
                        Lam[a, b] = (Lam[a, b] - (0.0 * w[b] + wa * hj[b])) + dj * (0.0 * hj[b])
                for t in range(m):
                    inz[nz[t]] = False
            nis_s[k] = nsum if anyu else np.nan
            # carry back through Phi_k (transition k-1 -> k)
            if k > 0:
                F = Fb[i]
                for c in range(NP):
                    tmp[c] = lam[c]
                h2 = 0.5 * dt * dt
                for s_ in range(3, 21, 3):
                    lam[s_ + 1] = dt * tmp[s_] + tmp[s_ + 1]
                    lam[s_ + 2] = h2 * tmp[s_] + (dt * tmp[s_ + 1] + tmp[s_ + 2])
                for jj in range(3):
                    lam[jj] = F[0, jj] * tmp[0] + F[1, jj] * tmp[1] + F[2, jj] * tmp[2]
                for l in range(9):
                    lam[12 + l] = lam[12 + l] + (F[0, 3 + l] * tmp[0] + F[1, 3 + l] * tmp[1] + F[2, 3 + l] * tmp[2])
                _carry_back(F, dt, Lam, B)


@njit(cache=True)
def run(z, cand, x0, P0, prm, Qd, Qc, qm, rdiag, gate_thr, do_gate, gate_on, hold, seg,
        xf, sf, nis, dof, used, gated, ckpt,
        xs, ss, nis_s, aa, aa_sig, stats, Pb, Kb, Hb, vb, sb, Fb, innov):
    """forward() then backward(); returns forward()'s count of bad variances."""
    bad = forward(z, cand, x0, P0, prm, Qd, Qc, qm, rdiag, gate_thr, do_gate, gate_on, hold, seg,
                  xf, sf, nis, dof, used, gated, ckpt, stats, innov)
    backward(z, used, x0, P0, prm, Qd, Qc, qm, rdiag, seg, xf, ckpt,
             xs, ss, nis_s, aa, aa_sig, stats, Pb, Kb, Hb, vb, sb, Fb)
    return bad
