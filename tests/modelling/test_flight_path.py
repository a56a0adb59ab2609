"""Closed-form checks of the flight-path alpha-dot (aerosid.modelling.flight_path)."""
from types import SimpleNamespace

import numpy as np
import pandas as pd
import scipy.signal

from aerosid.modelling.flight_path import (KINEMATIC_BAND_FRACTION, complementary_alpha, flight_data_alpha,
                                           gravity_alpha_dot, kinematic_alpha_dot_no_gravity)

G0 = 9.80665


def _flight(t: np.ndarray, bank: float = 0.3):
    """A rigid-body flight from analytic alpha, beta, V and attitude: body rates from the Euler
    angles' kinematics, specific forces f = dv/dt + w x v - g_body (no aerodynamics involved)."""
    alpha = 0.06 + 0.03 * np.sin(2 * np.pi * 0.5 * t) + 0.01 * np.sin(2 * np.pi * 1.3 * t)
    alpha_dot = 0.03 * 2 * np.pi * 0.5 * np.cos(2 * np.pi * 0.5 * t) + 0.01 * 2 * np.pi * 1.3 * np.cos(2 * np.pi * 1.3 * t)
    beta = 0.02 * np.sin(2 * np.pi * 0.3 * t)
    V = 50 + 2 * np.sin(0.2 * t)
    theta = 0.05 + 0.02 * np.sin(0.4 * t)
    phi = bank * np.sin(0.7 * t)
    dt = t[1] - t[0]
    theta_d, phi_d = np.gradient(theta, dt), np.gradient(phi, dt)
    psi_d = 0.05 * np.sin(0.5 * t)
    p = phi_d - psi_d * np.sin(theta)
    q = theta_d * np.cos(phi) + psi_d * np.cos(theta) * np.sin(phi)
    r = -theta_d * np.sin(phi) + psi_d * np.cos(theta) * np.cos(phi)
    u, v, w = V * np.cos(alpha) * np.cos(beta), V * np.sin(beta), V * np.sin(alpha) * np.cos(beta)
    ud, vd, wd = (np.gradient(x, dt) for x in (u, v, w))
    ax = ud + q * w - r * v + G0 * np.sin(theta)
    az = wd + p * v - q * u - G0 * np.cos(theta) * np.cos(phi)
    return dict(t=t, alpha=alpha, alpha_dot=alpha_dot, beta=beta, V=V, theta=theta, phi=phi, p=p, q=q, r=r,
                ax=ax, az=az)


def test_kinematic_alpha_dot_equals_the_analytic_derivative():
    f = _flight(np.arange(0.0, 20.0, 1e-3))
    K = kinematic_alpha_dot_no_gravity(f["alpha"], f["beta"], f["p"], f["q"], f["r"], f["ax"], f["az"], f["V"])
    G = gravity_alpha_dot(f["alpha"], f["beta"], f["theta"], f["phi"], f["V"])
    inner = slice(10, -10)  # np.gradient's one-sided ends
    assert np.max(np.abs((K + G - f["alpha_dot"])[inner])) < 1e-5
    # without the gravity term it is off by ~g/V: the term is not negligible
    assert np.median(np.abs(K - f["alpha_dot"])) > 0.15


def test_flight_data_signs_give_the_kinematic_alpha_dot():
    """C_A, C_N as aerosid.identification.flight_coefficients defines them (C_A = -m a_x/(qbar S),
    C_N = -m a_z/(qbar S)) give back the same K through flight_data_alpha."""
    f = _flight(np.arange(0.0, 20.0, 0.01))
    veh = SimpleNamespace(mass_kg=1000.0, S_m2=15.0, length_pitch_m=1.5)
    qbar = 0.5 * 1.1 * f["V"] ** 2
    fd = pd.DataFrame({"CA": -veh.mass_kg * f["ax"] / (qbar * veh.S_m2), "CN": -veh.mass_kg * f["az"] / (qbar * veh.S_m2),
                       "qbar_pa": qbar})
    sig = {k: f[k] for k in ("t", "alpha", "beta", "p", "q", "r", "V")}
    kin = flight_data_alpha(fd, sig, veh, 2.0, None)
    K = kinematic_alpha_dot_no_gravity(f["alpha"], f["beta"], f["p"], f["q"], f["r"], f["ax"], f["az"], f["V"])
    assert np.allclose(kin.kinematic, K, rtol=0, atol=1e-12)
    assert kin.cutoff_hz == 2.0 / KINEMATIC_BAND_FRACTION


def test_vane_noise_stays_out_of_the_high_band():
    """Vane alpha = alpha + band-limited white noise: the complementary alpha-dot's error above
    2 f_c is a small fraction of the vane derivative's, and the gravity part is recovered."""
    fs, band = 100.0, 2.0
    f = _flight(np.arange(0.0, 60.0, 1 / fs), bank=0.05)
    rng = np.random.default_rng(3)
    sos = scipy.signal.butter(2, band, fs=fs, output="sos")
    vane = f["alpha"] + scipy.signal.sosfiltfilt(sos, 0.003 * rng.standard_normal(len(f["t"])))
    K = kinematic_alpha_dot_no_gravity(vane, f["beta"], f["p"], f["q"], f["r"], f["ax"], f["az"], f["V"])
    fc = band / KINEMATIC_BAND_FRACTION
    kin = complementary_alpha(f["t"], None, vane, K, fc)
    hp = scipy.signal.butter(2, 2 * fc, btype="high", fs=fs, output="sos")
    inner = slice(int(5 * fs), -int(5 * fs))

    def high_rms(x):
        return float(np.sqrt(np.mean(scipy.signal.sosfiltfilt(hp, x)[inner] ** 2)))

    vane_dot = np.gradient(vane, 1 / fs)
    e_vane, e_kin = high_rms(vane_dot - f["alpha_dot"]), high_rms(kin.alpha_dot - f["alpha_dot"])
    assert e_kin < 0.1 * e_vane
    assert high_rms(kin.alpha - f["alpha"]) < 0.1 * high_rms(vane - f["alpha"])
    G = gravity_alpha_dot(f["alpha"], f["beta"], f["theta"], f["phi"], f["V"])
    assert np.sqrt(np.mean((kin.gravity_hat - G)[inner] ** 2)) < 0.05 * np.mean(G)


def test_groups_are_filtered_apart_and_short_ones_stay_nan():
    t = np.r_[np.arange(0, 10, 0.01), np.arange(20, 20.03, 0.01)]
    groups = np.r_[np.zeros(1000, int), np.ones(3, int)]
    out = complementary_alpha(t, groups, np.full(t.size, 0.1), np.zeros(t.size), 0.4)
    assert np.allclose(out.alpha[:1000], 0.1) and np.allclose(out.alpha_dot[:1000], 0.0, atol=1e-12)
    assert np.all(np.isnan(out.alpha[1000:]))


def test_vehicle_signals_switch(monkeypatch):
    """vehicle_signals of a vane aircraft: the vanes' derivative by default; with the switch on,
    the complementary alpha-dot (exact here: noise-free kinematics, slow gravity term)."""
    import aerosid.modelling.models as models

    fs = 100.0
    f = _flight(np.arange(0.0, 40.0, 1 / fs), bank=0.05)
    veh = SimpleNamespace(mass_kg=1000.0, S_m2=15.0, length_pitch_m=1.5, length_lateral_m=10.0,
                          derivative_half_window_s=0.25, air_data_source="vanes")
    qbar = 0.5 * 1.1 * f["V"] ** 2
    n = len(f["t"])
    fd = pd.DataFrame({"t_s": f["t"], "flight": "f", "segment": "s", "alpha_rad": f["alpha"], "beta_rad": f["beta"],
                       "alpha_r_rad": f["alpha"], "phi_r_rad": np.zeros(n), "mach": np.full(n, 0.15),
                       "V_m_s": f["V"], "qbar_pa": qbar, "delta_p_rad": np.zeros(n), "delta_y_rad": np.zeros(n),
                       "delta_r_rad": np.zeros(n), "p_rad_s": f["p"], "q_rad_s": f["q"], "r_rad_s": f["r"],
                       "band_hz": np.full(n, 2.0),
                       "CA": -veh.mass_kg * f["ax"] / (qbar * veh.S_m2), "CN": -veh.mass_kg * f["az"] / (qbar * veh.S_m2)})
    scale = veh.length_pitch_m / (2 * f["V"])
    inner = slice(int(5 * fs), -int(5 * fs))
    vane = models.vehicle_signals(fd, veh)["alpha_dot_hat"]
    monkeypatch.setattr(models, "KINEMATIC_ALPHA_DOT", True)
    kin = models.vehicle_signals(fd, veh)["alpha_dot_hat"]
    assert not np.allclose(vane, kin)
    assert np.max(np.abs((kin - f["alpha_dot"] * scale)[inner])) < 0.01 * np.max(np.abs(f["alpha_dot"] * scale))
    veh.air_data_source = "database"  # inverted angles: left as they are
    assert np.array_equal(models.vehicle_signals(fd, veh)["alpha_dot_hat"], vane)
