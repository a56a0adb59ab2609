"""Plant and measurement model: analytic Jacobians vs finite differences, discretisation."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from aerosid.estimation import (PlantModel, continuous_dynamics, continuous_jacobian, discrete_process_noise,
                                measure, measure_many, measurement_jacobian, propagate)
from aerosid.estimation.model import IX_ANG, chain_transition, rate_rhs
from aerosid.vehicles.rigid_body import body_rate_derivatives, inertia_constants, lever_arm_acceleration

MODEL = PlantModel((150.0, 2500.0, 2550.0, 40.0), (1.1, -0.2, 0.3), 0.01)


def _state(seed=0):
    rng = np.random.default_rng(seed)
    x = rng.normal(0, 1, 21)
    x[0:3] = rng.normal(0, 0.8, 3)
    return x


def _fd(fun, x, eps=1e-6):
    cols = []
    for i in range(x.size):
        d = np.zeros_like(x)
        d[i] = eps * max(1.0, abs(x[i]))
        cols.append((fun(x + d) - fun(x - d)) / (2 * d[i]))
    return np.stack(cols, axis=1)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_continuous_jacobian_matches_finite_differences(seed):
    x = _state(seed)
    A = continuous_jacobian(x, MODEL)
    np.testing.assert_allclose(A, _fd(lambda v: continuous_dynamics(v, MODEL), x), atol=1e-7, rtol=1e-7)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_measurement_jacobian_matches_finite_differences(seed):
    x = _state(seed)
    H = measurement_jacobian(x, MODEL)
    np.testing.assert_allclose(H, _fd(lambda v: measure(v, MODEL), x), atol=1e-7, rtol=1e-7)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_transition_is_the_jacobian_of_the_discrete_map(seed):
    x = _state(seed)
    _, Phi = propagate(x, MODEL)
    np.testing.assert_allclose(Phi, _fd(lambda v: propagate(v, MODEL)[0], x), atol=1e-8, rtol=1e-7)
    # structure: chains are the exact triple-integrator blocks, X/Y/Z chains decoupled from the rates
    for s in range(3, 21, 3):
        np.testing.assert_array_equal(Phi[s:s + 3, s:s + 3], chain_transition(0.01))
    assert not Phi[0:3, 3:12].any()


def test_measurement_model_matches_rigid_body_module():
    """h(x) = CG acceleration + lever-arm terms from aerosid.vehicles.rigid_body (L, M, N per inertia)."""
    x = _state(4)
    c = inertia_constants(*MODEL.inertia_kg_m2)
    p, q, r = x[0:3]
    pd, qd, rd = body_rate_derivatives(p, q, r, x[12], x[15], x[18], c)
    la = lever_arm_acceleration(p, q, r, pd, qd, rd, MODEL.sensor_offset_m)
    h = measure(x, MODEL)
    np.testing.assert_allclose(h[:3], x[[3, 6, 9]] + np.array(la), rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(h[3:], x[:3])
    np.testing.assert_allclose(rate_rhs(x[:3], x[list(IX_ANG)], MODEL.params), [pd, qd, rd], rtol=1e-13)
    X = np.stack([_state(i) for i in range(5)])
    np.testing.assert_allclose(measure_many(X, MODEL), np.stack([measure(v, MODEL) for v in X]), rtol=1e-13,
                               atol=1e-12)


def test_propagation_accuracy_against_tight_ode_solution():
    """RK4 with exact chain inputs: one 10 ms step within 1e-10 rad/s of DOP853."""
    x = _state(5)
    xn, _ = propagate(x, MODEL)
    prm = MODEL.params
    ang = np.array(IX_ANG)

    def rhs(t, w):
        u = x[ang] + x[ang + 1] * t + x[ang + 2] * t * t / 2
        return rate_rhs(w, u, prm)

    sol = solve_ivp(rhs, (0, 0.01), x[:3], method="DOP853", rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(xn[:3], sol.y[:, -1], atol=1e-10)


def test_discrete_process_noise_closed_form_and_psd():
    q = np.array([2.0, 3.0, 5.0, 7.0, 11.0, 13.0])
    dt = MODEL.dt_s
    Q = discrete_process_noise(q, MODEL)
    blk = np.array([[dt**5 / 20, dt**4 / 8, dt**3 / 6], [dt**4 / 8, dt**3 / 3, dt**2 / 2],
                    [dt**3 / 6, dt**2 / 2, dt]])
    for i, s in enumerate(range(3, 21, 3)):
        np.testing.assert_allclose(Q[s:s + 3, s:s + 3], q[i] * blk, rtol=1e-14)
    np.testing.assert_array_equal(Q, Q.T)
    assert np.linalg.eigvalsh(Q / np.max(np.abs(Q))).min() > -1e-12
    # rates see the L, M, N noise integrated once more: Var(q) = q_M dt^7/252 (B row of q is (0, 1, 0))
    np.testing.assert_allclose(Q[1, 1], q[4] * dt**7 / 252, rtol=1e-12)
    # Q_d agrees with the numerically integrated continuous-time noise on the chains
    A = continuous_jacobian(np.zeros(21), MODEL)
    G = np.zeros((21, 6))
    for i, s in enumerate(range(3, 21, 3)):
        G[s + 2, i] = 1.0
    from scipy.linalg import expm
    n = 21
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n] = -A
    M[:n, n:] = G @ np.diag(q) @ G.T
    M[n:, n:] = A.T
    E = expm(M * dt)
    Qvl = E[n:, n:].T @ E[:n, n:]
    np.testing.assert_allclose(Q[3:, 3:], Qvl[3:, 3:], rtol=1e-6, atol=1e-16)
    np.testing.assert_allclose(Q[:3, :], Qvl[:3, :], rtol=1e-6, atol=1e-3 * np.abs(Qvl[:3, :]).max())
