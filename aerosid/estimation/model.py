"""The 21-state plant and the 6 measurements of method.md §5 (plain numpy).

State vector (SI, radians), index in brackets::

    p q r                       [0..2]   body rates                       rad/s
    X1 X2 X3                    [3..5]   CG acceleration chain, body x     m/s^2, m/s^3, m/s^4
    Y1 Y2 Y3                    [6..8]   CG acceleration chain, body y
    Z1 Z2 Z3                    [9..11]  CG acceleration chain, body z
    L1 L2 L3                    [12..14] L_hat = L/Ixx chain               rad/s^2, rad/s^3, rad/s^4
    M1 M2 M3                    [15..17] M_hat = M/Iyy chain
    N1 N2 N3                    [18..20] N_hat = N/Izz chain

Convention (as in :mod:`aerosid.vehicles.rigid_body`): L, M, N chain states are the
aerodynamic moments divided by Ixx, Iyy, Izz [rad/s^2].

Each chain is a triple integrator driven by white noise on its third state
(x1' = x2, x2' = x3, x3' = w).  The rates obey the Euler equations

    omega' = g(omega, u),  u = (L1, M1, N1)

Measurements: accelerometers at ``offset_m`` from the CG (CG acceleration +
omega' x r + omega x (omega x r), omega' from the Euler equations, so h
depends on the state only) and the three gyros.

Discretisation over one sample interval dt [s]: the six chains are propagated
exactly (polynomials in time); the rates by one classical RK4 step in which the
input u(tau) is the *exact* chain polynomial (so RK4 is the only approximation,
local error O(dt^5)).  The transition matrix Phi is the exact Jacobian of that
discrete map (the RK4 stages differentiated analytically), checked against
finite differences in the tests.  Q_d is exact for the chains and, for the
rate rows, the 4-fold-integrator covariance of the rate response to the chain
noise (the gyroscopic feedback over one step, a relative O(|omega| dt) effect
on terms that are themselves O(dt^7), is neglected).  Q_d does not depend on
the state, so it is built once.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aerosid.vehicles.rigid_body import inertia_constants

STATE_NAMES = ("p", "q", "r", "X1", "X2", "X3", "Y1", "Y2", "Y3", "Z1", "Z2", "Z3",
               "L1", "L2", "L3", "M1", "M2", "M3", "N1", "N2", "N3")
MEAS_NAMES = ("ax", "ay", "az", "p", "q", "r")
STATE_UNITS = ("rad/s",) * 3 + ("m/s^2", "m/s^3", "m/s^4") * 3 + ("rad/s^2", "rad/s^3", "rad/s^4") * 3
MEAS_UNITS = ("m/s^2",) * 3 + ("rad/s",) * 3
CHAIN_NAMES = ("X", "Y", "Z", "L", "M", "N")
N_STATE = 21
N_MEAS = 6
#: first index of each chain, order X, Y, Z, L, M, N
CHAIN_START = (3, 6, 9, 12, 15, 18)
IX_ACC = (3, 6, 9)        # X1, Y1, Z1
IX_ANG = (12, 15, 18)     # L1, M1, N1

# layout of the parameter vector handed to the numba kernels
# c1 c2 c5 c6 c8 | apL apN arL arN | x y z | dt
PRM_LEN = 13


@dataclass(frozen=True)
class PlantModel:
    """Rigid-body constants, sensor position and sample interval of the plant.

    inertia_kg_m2: (Ixx, Iyy, Izz, Ixz) [kg m^2]; sensor_offset_m: accelerometer
    position relative to the CG in body axes [m]; dt_s: sample interval [s].
    """

    inertia_kg_m2: tuple
    sensor_offset_m: tuple
    dt_s: float

    @property
    def params(self) -> np.ndarray:
        """Flat float64 parameter vector used by the numba kernels (see PRM_LEN)."""
        c = inertia_constants(*[float(v) for v in self.inertia_kg_m2])
        x, y, z = (float(v) for v in self.sensor_offset_m)
        return np.array([c.c1, c.c2, c.c5, c.c6, c.c8,
                         c.c3 * c.Ixx, c.c4 * c.Izz, c.c4 * c.Ixx, c.c9 * c.Izz,
                         x, y, z, float(self.dt_s)], dtype=np.float64)

    @property
    def input_matrix(self) -> np.ndarray:
        """B = d omega' / d(L1, M1, N1) [dimensionless], 3x3."""
        prm = self.params
        return np.array([[prm[5], 0.0, prm[6]], [0.0, 1.0, 0.0], [prm[7], 0.0, prm[8]]])


# ----------------------------------------------------------------------------- rates
def rate_rhs(w: np.ndarray, u: np.ndarray, prm: np.ndarray) -> np.ndarray:
    """Euler equations: omega' [rad/s^2] from omega=(p,q,r) [rad/s] and u=(L1,M1,N1) [rad/s^2]."""
    c1, c2, c5, c6, c8, apL, apN, arL, arN = prm[:9]
    p, q, r = w
    L, M, N = u
    return np.array([(c1 * r + c2 * p) * q + apL * L + apN * N,
                     c5 * p * r - c6 * (p * p - r * r) + M,
                     (c8 * p - c2 * r) * q + arL * L + arN * N])


def rate_jacobian(w: np.ndarray, prm: np.ndarray) -> np.ndarray:
    """G = d omega'/d omega [1/s], 3x3."""
    c1, c2, c5, c6, c8 = prm[:5]
    p, q, r = w
    return np.array([[c2 * q, c1 * r + c2 * p, c1 * q],
                     [c5 * r - 2.0 * c6 * p, 0.0, c5 * p + 2.0 * c6 * r],
                     [c8 * q, c8 * p - c2 * r, -c2 * q]])


def _input_matrix(prm):
    return np.array([[prm[5], 0.0, prm[6]], [0.0, 1.0, 0.0], [prm[7], 0.0, prm[8]]])


def continuous_dynamics(x: np.ndarray, model: PlantModel) -> np.ndarray:
    """x' for the 21-state plant with zero process noise (units of x per second)."""
    prm = model.params
    xd = np.zeros(N_STATE)
    xd[0:3] = rate_rhs(x[0:3], x[list(IX_ANG)], prm)
    for s in CHAIN_START:
        xd[s] = x[s + 1]
        xd[s + 1] = x[s + 2]
    return xd


def continuous_jacobian(x: np.ndarray, model: PlantModel) -> np.ndarray:
    """A = d x'/d x [1/s], 21x21 (analytic)."""
    prm = model.params
    A = np.zeros((N_STATE, N_STATE))
    A[0:3, 0:3] = rate_jacobian(x[0:3], prm)
    A[0:3, list(IX_ANG)] = _input_matrix(prm)
    for s in CHAIN_START:
        A[s, s + 1] = 1.0
        A[s + 1, s + 2] = 1.0
    return A


def chain_transition(dt_s: float) -> np.ndarray:
    """Exact 3x3 transition of a triple integrator over dt_s [s]."""
    return np.array([[1.0, dt_s, 0.5 * dt_s * dt_s], [0.0, 1.0, dt_s], [0.0, 0.0, 1.0]])


def propagate(x: np.ndarray, model: PlantModel) -> tuple[np.ndarray, np.ndarray]:
    """Discrete transition over model.dt_s: returns (x_next, Phi) with Phi = d x_next/d x (21x21).

    Chains exact; rates by RK4 with the exact chain polynomials as input (see module doc).
    """
    prm = model.params
    dt = float(model.dt_s)
    B = _input_matrix(prm)
    x = np.asarray(x, dtype=float)
    ang = np.array(IX_ANG)
    U = np.stack([x[ang], x[ang + 1], x[ang + 2]], axis=1)   # 3 x 3: rows L,M,N; cols 1,2,3

    def u_at(tau):
        return U[:, 0] + U[:, 1] * tau + U[:, 2] * (0.5 * tau * tau)

    def du_at(tau):   # B d u(tau) / d(p, q, r, L1, L2, L3, M1 ... N3): 3 x 12
        D = np.zeros((3, 12))
        for c in range(3):
            D[c, 3 + 3 * c:6 + 3 * c] = (1.0, tau, 0.5 * tau * tau)
        return B @ D

    w0 = x[0:3]
    W1 = np.hstack([np.eye(3), np.zeros((3, 9))])
    taus = (0.0, 0.5 * dt, 0.5 * dt, dt)
    steps = (0.5 * dt, 0.5 * dt, dt)
    wi, Wi = w0, W1
    ks, Js = [], []
    for i in range(4):
        k = rate_rhs(wi, u_at(taus[i]), prm)
        J = rate_jacobian(wi, prm) @ Wi + du_at(taus[i])
        ks.append(k)
        Js.append(J)
        if i < 3:
            wi = w0 + steps[i] * k
            Wi = W1 + steps[i] * J
    w1 = w0 + dt / 6.0 * (ks[0] + 2.0 * ks[1] + 2.0 * ks[2] + ks[3])
    Fw = W1 + dt / 6.0 * (Js[0] + 2.0 * Js[1] + 2.0 * Js[2] + Js[3])

    Phi = np.zeros((N_STATE, N_STATE))
    Fc = chain_transition(dt)
    xn = np.empty(N_STATE)
    xn[0:3] = w1
    for s in CHAIN_START:
        Phi[s:s + 3, s:s + 3] = Fc
        xn[s:s + 3] = Fc @ x[s:s + 3]
    Phi[0:3, 0:3] = Fw[:, 0:3]
    Phi[0:3, 12:21] = Fw[:, 3:12]
    return xn, Phi


def discrete_process_noise(q_chain: np.ndarray, model: PlantModel) -> np.ndarray:
    """Q_d (21x21) for chain white-noise intensities q_chain (6,), order X Y Z L M N.

    Units of q_chain: (m/s^5)^2 s = m^2/s^9 for X, Y, Z; rad^2/s^9 for L, M, N.
    Chains: exact triple-integrator covariance.  Rates: the response to the L, M, N
    noise through B treated as a 4th integration (module doc).
    """
    q_chain = np.asarray(q_chain, dtype=float)
    dt = float(model.dt_s)
    B = model.input_matrix
    Q = np.zeros((N_STATE, N_STATE))

    # a = number of integrations from the white noise: x3 -> 1, x2 -> 2, x1 -> 3, rate -> 4
    def qab(a, b):
        from math import factorial
        return dt ** (a + b - 1) / (factorial(a - 1) * factorial(b - 1) * (a + b - 1))

    for ci, s in enumerate(CHAIN_START):
        for i in range(3):
            for j in range(3):
                Q[s + i, s + j] = q_chain[ci] * qab(3 - i, 3 - j)
    for ci in range(3):          # L, M, N
        s = IX_ANG[ci]
        qc = q_chain[3 + ci]
        for i in range(3):
            for j in range(3):
                Q[i, j] += B[i, ci] * B[j, ci] * qc * qab(4, 4)
            for j in range(3):
                Q[i, s + j] = B[i, ci] * qc * qab(4, 3 - j)
                Q[s + j, i] = Q[i, s + j]
    return Q


# ----------------------------------------------------------------------------- measurements
def _skew_offset(r):
    """E with E @ wdot = wdot x r."""
    x, y, z = r
    return np.array([[0.0, z, -y], [-z, 0.0, x], [y, -x, 0.0]])


def measure(x: np.ndarray, model: PlantModel) -> np.ndarray:
    """h(x): (ax, ay, az) [m/s^2] at the sensor, (p, q, r) [rad/s]."""
    prm = model.params
    r = prm[9:12]
    w = x[0:3]
    wd = rate_rhs(w, x[list(IX_ANG)], prm)
    acc = x[list(IX_ACC)] + w * (w @ r) - r * (w @ w) + _skew_offset(r) @ wd
    return np.concatenate([acc, w])


def measurement_jacobian(x: np.ndarray, model: PlantModel) -> np.ndarray:
    """H = dh/dx (6x21), analytic."""
    prm = model.params
    r = prm[9:12]
    w = x[0:3]
    E = _skew_offset(r)
    H = np.zeros((N_MEAS, N_STATE))
    dD = (w @ r) * np.eye(3) + np.outer(w, r) - 2.0 * np.outer(r, w)
    H[0:3, 0:3] = dD + E @ rate_jacobian(w, prm)
    H[0:3, list(IX_ANG)] = E @ _input_matrix(prm)
    for i, s in enumerate(IX_ACC):
        H[i, s] = 1.0
    H[3:6, 0:3] = np.eye(3)
    return H


def measure_many(X: np.ndarray, model: PlantModel) -> np.ndarray:
    """h(x) for many states at once: X (N,21) -> (N,6) (same formulas as :func:`measure`)."""
    prm = model.params
    c1, c2, c5, c6, c8, apL, apN, arL, arN = prm[:9]
    r = prm[9:12]
    X = np.atleast_2d(np.asarray(X, dtype=float))
    p, q, rr = X[:, 0], X[:, 1], X[:, 2]
    L, M, N = X[:, 12], X[:, 15], X[:, 18]
    wd = np.stack([(c1 * rr + c2 * p) * q + apL * L + apN * N,
                   c5 * p * rr - c6 * (p * p - rr * rr) + M,
                   (c8 * p - c2 * rr) * q + arL * L + arN * N], axis=1)
    w = X[:, 0:3]
    acc = X[:, list(IX_ACC)] + w * (w @ r)[:, None] - r[None, :] * np.sum(w * w, axis=1)[:, None] \
        + wd @ _skew_offset(r).T
    return np.concatenate([acc, w], axis=1)
