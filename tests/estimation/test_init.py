"""Filter initialisation pieces on signals whose right answer is known."""
import math

import numpy as np
import pytest

from aerosid.estimation import (PlantModel, initial_state, measurement_noise_from_dispersion, parabola_init,
                                process_noise_from_spectrum)


def test_parabola_exact_without_noise():
    t = 5.0 + np.arange(20) * 0.01
    tau = t - t[0]
    y = 1.5 - 2.0 * tau + 30.0 * tau**2
    fit = parabola_init(t, y, n=7, noise_sigma=0.1)
    assert fit.indices.tolist() == list(range(7))
    assert fit.value == pytest.approx(1.5, abs=1e-11)
    assert fit.rate == pytest.approx(-2.0, abs=1e-8)
    assert fit.accel == pytest.approx(60.0, abs=1e-5)


def test_parabola_uses_first_seven_valid_samples_and_closed_form_covariance():
    dt = 0.01
    t = np.arange(30) * dt
    valid = np.ones(30, bool)
    valid[[1, 4]] = False
    y = np.where(valid, 2.0 + t, np.nan)
    fit = parabola_init(t, y, valid=valid, noise_sigma=0.5)
    assert fit.indices.tolist() == [0, 2, 3, 5, 6, 7, 8]
    tau = t[fit.indices]
    A = np.stack([np.ones(7), tau, tau**2], axis=1)
    cov = 0.25 * np.linalg.inv(A.T @ A)
    assert fit.var_value == pytest.approx(cov[0, 0], rel=1e-9)
    assert fit.var_rate == pytest.approx(cov[1, 1], rel=1e-9)
    assert fit.var_accel == pytest.approx(4 * cov[2, 2], rel=1e-9)
    s0, s1, s2 = fit.variances_at(0.03)
    assert s0 == pytest.approx(cov[0, 0] + cov[1, 1] * 0.03**2 + cov[2, 2] * 0.03**4)
    assert s1 == pytest.approx(cov[1, 1] + 4 * cov[2, 2] * 0.03**2)
    assert "parabola fit" in fit.summary()


def test_parabola_variances_match_monte_carlo():
    """Parabola + white noise of known sigma: the fit's variances are the scatter of its estimates."""
    rng = np.random.default_rng(0)
    dt, sig = 0.01, 0.8
    t = np.arange(7) * dt
    truth = 0.3 + 4.0 * t - 50.0 * t**2
    est = []
    est_var = []
    for _ in range(4000):
        f = parabola_init(t, truth + rng.normal(0, sig, 7))
        est.append((f.value, f.rate, f.accel))
        est_var.append((f.var_value, f.var_rate, f.var_accel))
    est = np.array(est)
    ref = parabola_init(t, truth, noise_sigma=sig)
    tol = 4 * np.sqrt([ref.var_value, ref.var_rate, ref.var_accel]) / np.sqrt(4000)
    assert np.all(np.abs(est.mean(0) - [0.3, 4.0, -100.0]) < tol)
    np.testing.assert_allclose(est.var(0), [ref.var_value, ref.var_rate, ref.var_accel], rtol=0.08)
    # residual-based variance (n - 3 dof) is unbiased
    np.testing.assert_allclose(np.mean(est_var, 0), [ref.var_value, ref.var_rate, ref.var_accel], rtol=0.06)


def _sines(t, comps):
    return sum(a * np.sin(2 * np.pi * f * t + ph) for a, f, ph in comps)


@pytest.mark.parametrize("order", [3, 4])
def test_spectrum_q_for_sum_of_sines(order):
    """Known band and amplitudes: ms of the order-th derivative = sum A^2 (2 pi f)^(2 order) / 2,
    q = ms / (2 f_band), f_band = highest component."""
    dt = 0.01
    t = np.arange(8000) * dt
    comps = [(2.0, 0.37, 0.1), (1.0, 0.81, 1.0), (0.5, 1.43, 2.0)]
    rng = np.random.default_rng(1)
    y = 4.0 + 0.1 * t + _sines(t, comps) + rng.normal(0, 0.05, t.size)
    sp = process_noise_from_spectrum(y, dt, f_max_hz=4.0, order=order, noise_sigma=0.05)
    ms = sum(a * a * (2 * np.pi * f) ** (2 * order) / 2 for a, f, _ in comps)
    assert sp.ms_derivative == pytest.approx(ms, rel=0.05)
    assert sp.f_max_hz == pytest.approx(1.43, abs=0.04)
    assert sp.q == pytest.approx(sp.ms_derivative / (2 * sp.f_max_hz), rel=1e-12)
    # the floor estimated from the data instead of a given sigma gives the same answer
    sp2 = process_noise_from_spectrum(y, dt, f_max_hz=4.0, order=order)
    assert sp2.ms_derivative == pytest.approx(ms, rel=0.05)
    assert "spectrum" in sp.summary()


def test_spectrum_pure_noise_gives_floor_bound():
    rng = np.random.default_rng(2)
    y = rng.normal(0, 1.0, 8000)
    sp = process_noise_from_spectrum(y, 0.01, f_max_hz=4.0, noise_sigma=1.0)
    assert sp.n_bins == 0
    assert sp.f_max_hz == 0.5  # no significant bin: the slow-signal bound at f_max / 8


@pytest.mark.parametrize("sigma", [0.05, 0.8, 2.0])
def test_dispersion_recovers_known_sigma(sigma):
    rng = np.random.default_rng(3)
    dt = 0.01
    t = np.arange(8000) * dt
    y = 3.0 - 0.2 * t + _sines(t, [(5.0, 0.4, 0.0), (2.0, 1.7, 1.0)]) + rng.normal(0, sigma, t.size)
    nd = measurement_noise_from_dispersion(y, dt, f_cut_hz=4.0)
    assert nd.sigma == pytest.approx(sigma, rel=0.04)
    assert nd.sigma_std == pytest.approx(sigma, rel=0.04)
    # the seed's (dy/3) rule: the largest of 8000 Gaussian deviations is ~4 sigma, not 3
    assert nd.sigma_seed > 1.15 * sigma
    assert nd.delta_y / sigma == pytest.approx(math.sqrt(2 * math.log(8000)), rel=0.2)
    assert nd.variance == pytest.approx(nd.sigma**2)


def test_dispersion_robust_to_outliers_and_ignores_invalid_samples():
    rng = np.random.default_rng(4)
    dt = 0.01
    t = np.arange(8000) * dt
    y = _sines(t, [(5.0, 0.4, 0.0)]) + rng.normal(0, 1.0, t.size)
    valid = np.ones(t.size, bool)
    y[rng.choice(t.size, 40, replace=False)] += 40.0          # outliers
    gap = slice(3000, 3400)
    y[gap] = np.interp(t[gap], [t[2999], t[3400]], [y[2999], y[3400]])  # interpolated gap
    valid[gap] = False
    nd = measurement_noise_from_dispersion(y, dt, 4.0, valid=valid)
    assert nd.sigma == pytest.approx(1.0, rel=0.05)
    assert nd.sigma_seed > 5.0        # one outlier ruins the seed rule
    assert nd.n <= valid.sum() - 200 and nd.n > valid.sum() - 400


def test_initial_state_from_truth_parabolas():
    """Noise-free parabolic channels: X0 reproduces the truth through the Euler equations."""
    from aerosid.estimation import measure
    model = PlantModel((150.0, 2500.0, 2550.0, 12.0), (1.0, 0.1, -0.2), 0.01)
    t = np.arange(20) * 0.01
    rng = np.random.default_rng(5)
    x_true = rng.normal(0, 0.3, 21)
    for s in range(3, 21, 3):
        x_true[s + 2] = 0.0          # L3 etc. zero so that the chains are exact parabolas
    # generate z by propagating the exact chains; rates via the model's propagation
    from aerosid.estimation import propagate
    X = [x_true]
    for _ in range(19):
        X.append(propagate(X[-1], model)[0])
    X = np.array(X)
    z = np.array([measure(x, model) for x in X])
    x0, P0, fits = initial_state(t, z, np.ones_like(z, bool), model, np.full(6, 1e-3))
    np.testing.assert_allclose(x0[0:3], x_true[0:3], atol=1e-6)
    np.testing.assert_allclose(x0[[12, 15, 18]], x_true[[12, 15, 18]], atol=2e-3)
    np.testing.assert_allclose(x0[[3, 6, 9]], x_true[[3, 6, 9]], atol=2e-3)
    assert np.all(np.diag(P0) > 0) and np.count_nonzero(P0 - np.diag(np.diag(P0))) == 0


def test_white_floor_equals_the_dispersion_for_white_noise_and_ignores_a_gap():
    """White noise over a low-frequency signal: the density near Nyquist implies the same sigma
    as the high-passed dispersion (whiteness 1); an interpolated stretch (no noise) is left out."""
    rng = np.random.default_rng(11)
    dt = 0.01
    t = np.arange(8000) * dt
    y = _sines(t, [(5.0, 0.4, 0.0), (2.0, 1.7, 1.0)]) + rng.normal(0, 0.3, t.size)
    valid = np.ones(t.size, bool)
    gap = slice(2000, 5000)
    y[gap] = np.interp(t[gap], [t[1999], t[5000]], [y[1999], y[5000]])
    valid[gap] = False
    nd = measurement_noise_from_dispersion(y, dt, 4.0, valid=valid)
    assert nd.sigma_floor == pytest.approx(0.3, rel=0.08)
    assert nd.whiteness == pytest.approx(1.0, abs=0.1)


def test_a_low_passed_recording_is_not_white_and_its_floor_is_the_noise_left_near_nyquist():
    """Noise low-passed before recording (4th-order Butterworth at 8 Hz, 100 Hz sampling) plus a
    small white quantisation-like noise: the dispersion above 4 Hz holds the filtered noise, the
    floor only the white part, so whiteness is far above 1."""
    from scipy.signal import butter, lfilter

    from aerosid.estimation.findings import NOT_WHITE
    rng = np.random.default_rng(12)
    dt = 0.01
    t = np.arange(8000) * dt
    b, a = butter(4, 8.0, fs=1.0 / dt)
    coloured = lfilter(b, a, rng.normal(0, 1.0, t.size))
    y = _sines(t, [(5.0, 0.4, 0.0)]) + coloured + rng.normal(0, 0.02, t.size)
    nd = measurement_noise_from_dispersion(y, dt, 4.0)
    assert nd.sigma_floor == pytest.approx(0.02, rel=0.25)
    assert nd.whiteness > 5 * NOT_WHITE
    short = measurement_noise_from_dispersion(y[:40], dt, 4.0)
    assert math.isnan(short.sigma_floor) and math.isnan(short.whiteness)


def test_the_white_floor_needs_one_long_enough_run_and_is_unbiased_on_a_short_one():
    """Many valid samples in runs shorter than 64: no floor (NaN) while sigma is still estimated;
    on a 64-sample run of white noise (nperseg 16, the Nyquist bin left out) the floor is unbiased."""
    from aerosid.estimation.init import white_floor_sigma
    rng = np.random.default_rng(13)
    dt = 0.01
    y = rng.normal(0, 1.0, 4000)
    valid = (np.arange(4000) % 60) < 50  # runs of 50 valid samples
    nd = measurement_noise_from_dispersion(y, dt, 4.0, valid=valid)
    assert math.isnan(nd.sigma_floor) and nd.sigma == pytest.approx(1.0, rel=0.1)
    assert math.isnan(white_floor_sigma(y, dt, np.zeros(4000, bool), 4.0))
    floors = [white_floor_sigma(rng.normal(0, 1.0, 64), dt, np.ones(64, bool), 4.0) for _ in range(400)]
    assert np.mean(np.square(floors)) == pytest.approx(1.0, rel=0.06)
