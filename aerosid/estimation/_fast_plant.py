"""The plant inside the compiled filter (:mod:`._fast`): state propagation with the
rate rows of its Jacobian, and the measurement with its Jacobian.  Array layouts: the
module doc of :mod:`._fast`.
"""
from __future__ import annotations

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
