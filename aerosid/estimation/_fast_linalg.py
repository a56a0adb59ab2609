"""Structured covariance algebra of the compiled filter (:mod:`._fast`): Phi applied by
its rate rows only, the covariance prediction, the backward carry, symmetric products,
and the scalar Joseph-form update of one channel.  Array layouts: the module doc of
:mod:`._fast`.
"""
from __future__ import annotations

from numba import njit

from ._fast_plant import NM, NP, NS


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
    used channel; used/gated (6,) bool are written.  gate_thr (6,): each channel's
    chi-square(1) limit when do_gate (inf: that channel is not gated).
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
        if do_gate and vj * vj > gate_thr[j] * sj:
            gated[j] = True
            v[j] = vj  # the rejected innovation, for the caller's diagnostics (not used again)
            s[j] = sj
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
