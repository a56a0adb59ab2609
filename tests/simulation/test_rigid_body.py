"""Closed forms and invariants of the rotational dynamics (JSBSim TestPQRdot style)."""
import numpy as np
import pytest

from aerosid.vehicles.rigid_body import (angular_momentum, body_rate_derivatives, inertia_constants,
                                lever_arm_acceleration, rotational_energy)

INERTIA = inertia_constants(220.0, 2400.0, 2450.0, 12.0)


def rk4_rates(w0, moments, dt, n, c=INERTIA):
    w = np.array(w0, float)
    out = [w.copy()]
    f = lambda w: np.array(body_rate_derivatives(*w, *moments, c))  # noqa: E731
    for _ in range(n):
        k1 = f(w); k2 = f(w + dt / 2 * k1); k3 = f(w + dt / 2 * k2); k4 = f(w + dt * k3)
        w = w + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        out.append(w.copy())
    return np.array(out)


def test_torque_free_rotation_conserves_energy_and_momentum_magnitude():
    w = rk4_rates([1.5, 0.3, -0.4], (0.0, 0.0, 0.0), 1e-3, 20000)
    H = np.array([np.linalg.norm(angular_momentum(*wk, INERTIA)) for wk in w])
    E = np.array([rotational_energy(*wk, INERTIA) for wk in w])
    # the motion is far from trivial: p exchanges energy with q and r
    assert np.ptp(w[:, 1]) > 0.05
    assert np.ptp(H) / H[0] < 1e-9
    assert np.ptp(E) / E[0] < 1e-9


def test_euler_equations_match_the_vector_form():
    """omega_dot = I^-1 (M - omega x I omega) with the full tensor, at random states."""
    rng = np.random.default_rng(0)
    I = np.array([[INERTIA.Ixx, 0, -INERTIA.Ixz], [0, INERTIA.Iyy, 0], [-INERTIA.Ixz, 0, INERTIA.Izz]])
    for _ in range(20):
        w = rng.normal(size=3)
        m_hat = rng.normal(size=3)
        M = m_hat * np.array([INERTIA.Ixx, INERTIA.Iyy, INERTIA.Izz])
        expected = np.linalg.solve(I, M - np.cross(w, I @ w))
        got = np.array(body_rate_derivatives(*w, *m_hat, INERTIA))
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)


def test_constant_pitch_moment_gives_closed_form_q_dot():
    m_hat = 0.37  # rad/s^2
    w = rk4_rates([0.0, 0.0, 0.0], (0.0, m_hat, 0.0), 0.01, 500)
    t = np.arange(501) * 0.01
    np.testing.assert_allclose(w[:, 1], m_hat * t, rtol=0, atol=1e-12)
    assert np.all(w[:, [0, 2]] == 0.0)


def test_non_physical_inertia_is_rejected():
    with pytest.raises(ValueError, match="Gamma"):
        inertia_constants(100.0, 200.0, 100.0, 100.0)
    with pytest.raises(ValueError, match="positive"):
        inertia_constants(-1.0, 200.0, 100.0, 0.0)


def test_lever_arm_is_omega_dot_cross_r_plus_centripetal():
    rng = np.random.default_rng(1)
    for _ in range(10):
        w, wd, r = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
        expected = np.cross(wd, r) + np.cross(w, np.cross(w, r))
        np.testing.assert_allclose(lever_arm_acceleration(*w, *wd, r), expected, atol=1e-12)
