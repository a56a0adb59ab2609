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

NS = 21          # states
NP = 24          # padded dimension: trip counts that are a multiple of 4 let LLVM vectorise
NM = 6


@njit(cache=True)
def _propagate(x, prm, xn, F, wv, Wi, J, accJ):
    """x_{k+1} = f_d(x_k) into xn; rate rows of Phi into F (3,12).
    Work: wv (4,3) [w0, wi, k, acck], Wi, J, accJ (3,12)."""
    c1 = prm[0]
    c2 = prm[1]
    c5 = prm[2]
    c6 = prm[3]
    c8 = prm[4]
    b00 = prm[5]
    b02 = prm[6]
    b20 = prm[7]
    b22 = prm[8]
    dt = prm[12]
    for i in range(3):
        wv[0, i] = x[i]
        wv[1, i] = x[i]
        wv[3, i] = 0.0
        for j in range(12):
            Wi[i, j] = 0.0
            accJ[i, j] = 0.0
        Wi[i, i] = 1.0
    for st in range(4):
        if st == 0:
            tau = 0.0
            wt = 1.0
            nxt = 0.5 * dt
        elif st == 1:
            tau = 0.5 * dt
            wt = 2.0
            nxt = 0.5 * dt
        elif st == 2:
            tau = 0.5 * dt
            wt = 2.0
            nxt = dt
        else:
            tau = dt
            wt = 1.0
            nxt = 0.0
        ht = 0.5 * tau * tau
        L = x[12] + x[13] * tau + x[14] * ht
        M = x[15] + x[16] * tau + x[17] * ht
        N = x[18] + x[19] * tau + x[20] * ht
        p = wv[1, 0]
        q = wv[1, 1]
        r = wv[1, 2]
        k0 = (c1 * r + c2 * p) * q + b00 * L + b02 * N
        k1 = c5 * p * r - c6 * (p * p - r * r) + M
        k2 = (c8 * p - c2 * r) * q + b20 * L + b22 * N
        g00 = c2 * q
        g01 = c1 * r + c2 * p
        g02 = c1 * q
        g10 = c5 * r - 2.0 * c6 * p
        g12 = c5 * p + 2.0 * c6 * r
        g20 = c8 * q
        g21 = c8 * p - c2 * r
        g22 = -c2 * q
        for j in range(12):
            J[0, j] = g00 * Wi[0, j] + g01 * Wi[1, j] + g02 * Wi[2, j]
            J[1, j] = g10 * Wi[0, j] + g12 * Wi[2, j]
            J[2, j] = g20 * Wi[0, j] + g21 * Wi[1, j] + g22 * Wi[2, j]
        # + B du(tau)/d(chain states)
        J[0, 3] += b00
        J[0, 4] += b00 * tau
        J[0, 5] += b00 * ht
        J[0, 9] += b02
        J[0, 10] += b02 * tau
        J[0, 11] += b02 * ht
        J[1, 6] += 1.0
        J[1, 7] += tau
        J[1, 8] += ht
        J[2, 3] += b20
        J[2, 4] += b20 * tau
        J[2, 5] += b20 * ht
        J[2, 9] += b22
        J[2, 10] += b22 * tau
        J[2, 11] += b22 * ht
        wv[2, 0] = k0
        wv[2, 1] = k1
        wv[2, 2] = k2
        for i in range(3):
            wv[3, i] += wt * wv[2, i]
            for j in range(12):
                accJ[i, j] += wt * J[i, j]
        if st < 3:
            for i in range(3):
                wv[1, i] = wv[0, i] + nxt * wv[2, i]
                for j in range(12):
                    Wi[i, j] = nxt * J[i, j]
                Wi[i, i] += 1.0
    h6 = dt / 6.0
    for i in range(3):
        xn[i] = wv[0, i] + h6 * wv[3, i]
        for j in range(12):
            F[i, j] = h6 * accJ[i, j]
        F[i, i] += 1.0
    h2 = 0.5 * dt * dt
    for s in range(3, 21, 3):
        xn[s] = x[s] + dt * x[s + 1] + h2 * x[s + 2]
        xn[s + 1] = x[s + 1] + dt * x[s + 2]
        xn[s + 2] = x[s + 2]
    for s in range(NS, NP):
        xn[s] = 0.0


@njit(cache=True)
def _phi_rows(F, dt, S, A):
    """A = Phi S for a padded (24,24) S (row operations: chain blocks + rate rows)."""
    h2 = 0.5 * dt * dt
    for s in range(3, 21, 3):
        S0 = S[s]
        S1 = S[s + 1]
        S2 = S[s + 2]
        A0 = A[s]
        A1 = A[s + 1]
        A2 = A[s + 2]
        for b in range(NP):
            A0[b] = S0[b] + (dt * S1[b] + h2 * S2[b])
            A1[b] = S1[b] + dt * S2[b]
            A2[b] = S2[b]
    for i in range(3):
        f0 = F[i, 0]
        f1 = F[i, 1]
        f2 = F[i, 2]
        f3 = F[i, 3]
        f4 = F[i, 4]
        f5 = F[i, 5]
        f6 = F[i, 6]
        f7 = F[i, 7]
        f8 = F[i, 8]
        f9 = F[i, 9]
        f10 = F[i, 10]
        f11 = F[i, 11]
        Ai = A[i]
        S0 = S[0]
        S1 = S[1]
        S2 = S[2]
        S12 = S[12]
        S13 = S[13]
        S14 = S[14]
        S15 = S[15]
        S16 = S[16]
        S17 = S[17]
        S18 = S[18]
        S19 = S[19]
        S20 = S[20]
        for b in range(NP):
            Ai[b] = ((f0 * S0[b] + f1 * S1[b] + f2 * S2[b])
                     + (f3 * S12[b] + f4 * S13[b] + f5 * S14[b])
                     + (f6 * S15[b] + f7 * S16[b] + f8 * S17[b])
                     + (f9 * S18[b] + f10 * S19[b] + f11 * S20[b]))
    for s in range(NS, NP):
        for b in range(NP):
            A[s, b] = 0.0


@njit(cache=True)
def _phit_rows(F, dt, S, A):
    """A = Phi' S for a padded (24,24) S."""
    h2 = 0.5 * dt * dt
    for s in range(3, 21, 3):
        S0 = S[s]
        S1 = S[s + 1]
        S2 = S[s + 2]
        A0 = A[s]
        A1 = A[s + 1]
        A2 = A[s + 2]
        for b in range(NP):
            A0[b] = S0[b]
            A1[b] = dt * S0[b] + S1[b]
            A2[b] = h2 * S0[b] + (dt * S1[b] + S2[b])
    R0 = S[0]
    R1 = S[1]
    R2 = S[2]
    for j in range(3):
        f0 = F[0, j]
        f1 = F[1, j]
        f2 = F[2, j]
        Aj = A[j]
        for b in range(NP):
            Aj[b] = f0 * R0[b] + f1 * R1[b] + f2 * R2[b]
    for l in range(9):
        f0 = F[0, 3 + l]
        f1 = F[1, 3 + l]
        f2 = F[2, 3 + l]
        Aj = A[12 + l]
        for b in range(NP):
            Aj[b] = Aj[b] + (f0 * R0[b] + f1 * R1[b] + f2 * R2[b])
    for s in range(NS, NP):
        for b in range(NP):
            A[s, b] = 0.0


@njit(cache=True)
def _phi_vec(F, dt, v, out):
    """out = Phi v (structured)."""
    h2 = 0.5 * dt * dt
    for s in range(3, 21, 3):
        out[s] = v[s] + (dt * v[s + 1] + h2 * v[s + 2])
        out[s + 1] = v[s + 1] + dt * v[s + 2]
        out[s + 2] = v[s + 2]
    for i in range(3):
        out[i] = ((F[i, 0] * v[0] + F[i, 1] * v[1] + F[i, 2] * v[2])
                  + (F[i, 3] * v[12] + F[i, 4] * v[13] + F[i, 5] * v[14])
                  + (F[i, 6] * v[15] + F[i, 7] * v[16] + F[i, 8] * v[17])
                  + (F[i, 9] * v[18] + F[i, 10] * v[19] + F[i, 11] * v[20]))
    for s in range(NS, NP):
        out[s] = 0.0


@njit(cache=True)
def _phit_vec(F, dt, v, out):
    """out = Phi' v (structured)."""
    h2 = 0.5 * dt * dt
    for s in range(3, 21, 3):
        out[s] = v[s]
        out[s + 1] = dt * v[s] + v[s + 1]
        out[s + 2] = h2 * v[s] + (dt * v[s + 1] + v[s + 2])
    for j in range(3):
        out[j] = F[0, j] * v[0] + F[1, j] * v[1] + F[2, j] * v[2]
    for l in range(9):
        out[12 + l] = out[12 + l] + (F[0, 3 + l] * v[0] + F[1, 3 + l] * v[1] + F[2, 3 + l] * v[2])
    for s in range(NS, NP):
        out[s] = 0.0


@njit(cache=True)
def _predict_cov(P, F, Qd, dt, A, Pout):
    """Pout = Phi P Phi' + Qd for symmetric P; A (24,24) work.

    A = P Phi' row by row (row b of P Phi' is Phi applied to row b of P, P symmetric),
    then Pout = Phi A by row operations, symmetrised (the Joseph update then keeps
    P bitwise symmetric).
    """
    for b in range(NP):
        _phi_vec(F, dt, P[b], A[b])
    _phi_rows(F, dt, A, Pout)
    for a in range(NP):
        Pout[a, a] = Pout[a, a] + Qd[a, a]
        for b in range(a + 1, NP):
            m = 0.5 * (Pout[a, b] + Pout[b, a])
            Pout[a, b] = m + Qd[a, b]
            Pout[b, a] = m + Qd[b, a]


@njit(cache=True)
def _carry_back(F, dt, Lam, B):
    """Lam <- Phi' Lam Phi in place (rows: Lam Phi, then Phi' by row operations), symmetrised
    (an asymmetry left in Lambda grows over a long backward pass); B work."""
    for b in range(NP):
        _phit_vec(F, dt, Lam[b], B[b])
    _phit_rows(F, dt, B, Lam)
    for a in range(NP):
        for b in range(a + 1, NP):
            m = 0.5 * (Lam[a, b] + Lam[b, a])
            Lam[a, b] = m
            Lam[b, a] = m


@njit(cache=True)
def _symv(M, x, out):
    """out = M x for symmetric (24,24) M (sum of rows, 4 at a time)."""
    for b in range(NP):
        out[b] = 0.0
    for l in range(0, NP, 4):
        x0 = x[l]
        x1 = x[l + 1]
        x2 = x[l + 2]
        x3 = x[l + 3]
        M0 = M[l]
        M1 = M[l + 1]
        M2 = M[l + 2]
        M3 = M[l + 3]
        for b in range(NP):
            out[b] = out[b] + ((x0 * M0[b] + x1 * M1[b]) + (x2 * M2[b] + x3 * M3[b]))


@njit(cache=True)
def _symm(L, P, W):
    """W = L P for (24,24) L and symmetric-or-not P (rows of P combined, 4 at a time)."""
    for a in range(NP):
        Wa = W[a]
        for b in range(NP):
            Wa[b] = 0.0
        for l in range(0, NP, 4):
            l0 = L[a, l]
            l1 = L[a, l + 1]
            l2 = L[a, l + 2]
            l3 = L[a, l + 3]
            P0 = P[l]
            P1 = P[l + 1]
            P2 = P[l + 2]
            P3 = P[l + 3]
            for b in range(NP):
                Wa[b] = Wa[b] + ((l0 * P0[b] + l1 * P1[b]) + (l2 * P2[b] + l3 * P3[b]))


@njit(cache=True)
def _measure(x, prm, hx, H):
    """h(x) into hx (6,), dense Jacobian rows into H (6,24) (only the non-zeros written;
    H must be zero elsewhere)."""
    c1 = prm[0]
    c2 = prm[1]
    c5 = prm[2]
    c6 = prm[3]
    c8 = prm[4]
    b00 = prm[5]
    b02 = prm[6]
    b20 = prm[7]
    b22 = prm[8]
    ox = prm[9]
    oy = prm[10]
    oz = prm[11]
    p = x[0]
    q = x[1]
    r = x[2]
    L = x[12]
    M = x[15]
    N = x[18]
    pd = (c1 * r + c2 * p) * q + b00 * L + b02 * N
    qd = c5 * p * r - c6 * (p * p - r * r) + M
    rd = (c8 * p - c2 * r) * q + b20 * L + b22 * N
    wr = p * ox + q * oy + r * oz
    ww = p * p + q * q + r * r
    hx[0] = x[3] + p * wr - ox * ww + (oz * qd - oy * rd)
    hx[1] = x[6] + q * wr - oy * ww + (ox * rd - oz * pd)
    hx[2] = x[9] + r * wr - oz * ww + (oy * pd - ox * qd)
    hx[3] = p
    hx[4] = q
    hx[5] = r
    # G = d omega'/d omega
    g00 = c2 * q
    g01 = c1 * r + c2 * p
    g02 = c1 * q
    g10 = c5 * r - 2.0 * c6 * p
    g11 = 0.0
    g12 = c5 * p + 2.0 * c6 * r
    g20 = c8 * q
    g21 = c8 * p - c2 * r
    g22 = -c2 * q
    # E rows: E = [[0, z, -y], [-z, 0, x], [y, -x, 0]]
    w = (p, q, r)
    o = (ox, oy, oz)
    E = ((0.0, oz, -oy), (-oz, 0.0, ox), (oy, -ox, 0.0))
    G = ((g00, g01, g02), (g10, g11, g12), (g20, g21, g22))
    Bm = ((b00, 0.0, b02), (0.0, 1.0, 0.0), (b20, 0.0, b22))
    for i in range(3):
        for j in range(3):
            d = wr if i == j else 0.0
            d += w[i] * o[j] - 2.0 * o[i] * w[j]
            H[i, j] = d + E[i][0] * G[0][j] + E[i][1] * G[1][j] + E[i][2] * G[2][j]
            H[i, 12 + 3 * j] = E[i][0] * Bm[0][j] + E[i][1] * Bm[1][j] + E[i][2] * Bm[2][j]
        H[i, 3 + 3 * i] = 1.0
        H[3 + i, i] = 1.0


@njit(cache=True)
def _nz(j, out):
    """Column indices of the non-zeros of H row j into out; returns their count."""
    if j >= 3:
        out[0] = j - 3
        return 1
    out[0] = 0
    out[1] = 1
    out[2] = 2
    out[3] = 3 + 3 * j
    out[4] = 12
    out[5] = 15
    out[6] = 18
    return 7


@njit(cache=True)
def _update(x, P, zk, cand, rdiag, gate_thr, do_gate, hx, H, K, v, s, used, gated, u, dx):
    """Sequential-scalar Joseph update in place on x (24,), P (24,24).  Returns (nis, dof).

    H (6,24) holds the Jacobian at the prior x (from _measure), hx = h(x).  K (6,24),
    v (6,), s (6,) receive gain, conditional innovation and its variance of each
    used channel; used/gated (6,) bool are written.
    """
    for i in range(NP):
        dx[i] = 0.0
    nis = 0.0
    dof = 0
    for j in range(NM):
        used[j] = False
        gated[j] = False
        if not cand[j]:
            continue
        Hj = H[j]
        if j >= 3:
            c = j - 3
            vj = zk[j] - hx[j] - dx[c]
            Pc = P[c]
            for b in range(NP):
                u[b] = Pc[b]
            sj = rdiag[j] + u[c]
        else:
            ca = 3 + 3 * j
            h0 = Hj[0]
            h1 = Hj[1]
            h2 = Hj[2]
            h3 = Hj[ca]
            h4 = Hj[12]
            h5 = Hj[15]
            h6 = Hj[18]
            vj = zk[j] - hx[j] - ((h0 * dx[0] + h1 * dx[1] + h2 * dx[2])
                                  + (h3 * dx[ca] + h4 * dx[12] + h5 * dx[15] + h6 * dx[18]))
            P0 = P[0]
            P1 = P[1]
            P2 = P[2]
            P3 = P[ca]
            P4 = P[12]
            P5 = P[15]
            P6 = P[18]
            for b in range(NP):
                u[b] = ((h0 * P0[b] + h1 * P1[b]) + (h2 * P2[b] + h3 * P3[b])
                        + (h4 * P4[b] + h5 * P5[b] + h6 * P6[b]))
            sj = rdiag[j] + ((h0 * u[0] + h1 * u[1] + h2 * u[2])
                             + (h3 * u[ca] + h4 * u[12] + h5 * u[15] + h6 * u[18]))
        if do_gate and vj * vj > gate_thr * sj:
            gated[j] = True
            continue
        used[j] = True
        inv = 1.0 / sj
        kj = K[j]
        for b in range(NP):
            kj[b] = u[b] * inv
            dx[b] = dx[b] + kj[b] * vj
        # Joseph: P - (k u' + u k') + s k k'  (bitwise symmetric)
        for a in range(NP):
            ka = kj[a]
            ua = u[a]
            Pa = P[a]
            for b in range(NP):
                Pa[b] = (Pa[b] - (ka * u[b] + ua * kj[b])) + sj * (ka * kj[b])
        v[j] = vj
        s[j] = sj
        nis += vj * vj * inv
        dof += 1
    for i in range(NP):
        x[i] += dx[i]
    return nis, dof


@njit(cache=True)
def forward(z, cand, x0, P0, prm, Qd, rdiag, gate_thr, do_gate, seg,
            xf, sf, nis, dof, used, gated, ckpt, stats):
    """Forward EKF over all samples.  x0 (24,), P0, Qd (24,24) padded.  Writes xf, sf
    (N,21) (filtered state and sigma), nis (NaN if no update), dof, used, gated,
    stats[4] (per-channel sum of v^2/s) and the checkpoints ckpt[g] = P(k|k) at
    k = g*seg - 1 (g >= 1).  Returns the count of non-positive variances (0 when healthy)."""
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
    bad = 0
    for k in range(N):
        if k > 0:
            _propagate(x, prm, xn, F, wv, Wi, J, accJ)
            _predict_cov(P, F, Qd, dt, A, Pn)
            tmpx = x
            x = xn
            xn = tmpx
            tmpP = P
            P = Pn
            Pn = tmpP
        _measure(x, prm, hx, H)
        nk, dk = _update(x, P, z[k], cand[k], rdiag, gate_thr, do_gate, hx, H, K, v, s, us, gs, u, dx)
        nis[k] = nk if dk > 0 else np.nan
        dof[k] = dk
        for j in range(NM):
            used[k, j] = us[j]
            gated[k, j] = gs[j]
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
def backward(z, used, x0, P0, prm, Qd, rdiag, seg, xf, ckpt,
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
    inz = np.zeros(NP, dtype=np.bool_)
    Jr = np.zeros((3, NP))
    y = np.empty(NP)
    xsk = np.zeros(NP)
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
                _predict_cov(P if i == 0 else Pb[i - 1], Fb[i], Qd, dt, A, Pi)
                tmpx = x
                x = xn
                xn = tmpx
            else:
                for a in range(NP):
                    for b in range(NP):
                        Pi[a, b] = P[a, b]
            _measure(x, prm, hx, Hb[i])
            _update(x, Pi, z[k], used[k], rdiag, 0.0, False, hx, Hb[i], Kb[i], vb[i], sb[i], us, gs, u, dx)
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
def run(z, cand, x0, P0, prm, Qd, rdiag, gate_thr, do_gate, seg,
        xf, sf, nis, dof, used, gated, ckpt,
        xs, ss, nis_s, aa, aa_sig, stats, Pb, Kb, Hb, vb, sb, Fb):
    """forward() then backward(); returns forward()'s count of bad variances."""
    bad = forward(z, cand, x0, P0, prm, Qd, rdiag, gate_thr, do_gate, seg,
                  xf, sf, nis, dof, used, gated, ckpt, stats)
    backward(z, used, x0, P0, prm, Qd, rdiag, seg, xf, ckpt,
             xs, ss, nis_s, aa, aa_sig, stats, Pb, Kb, Hb, vb, sb, Fb)
    return bad
