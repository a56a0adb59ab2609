"""The parametric check of the estimator's own bias (aerosid.identification.bias_check): on one
noisy regressor and plain least squares it finds the classical attenuation of its bootstrap world
(closed form), the +/- pairs cancel what is odd in the noise, a bias that is only Monte-Carlo noise
is not counted, and counting it makes the intervals of an attenuated estimator cover the truth."""
from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from aerosid.identification.bias_check import (EstimatorBias, estimator_bias, sensor_noise, with_bias_counted,
                                               with_noise)
from aerosid.identification.regression import fit_linear

THETA = np.array([0.2, -1.5])  # C = theta_0 + theta_1 alpha
SIGMA_X, SIGMA_U = 0.05, 0.03  # the true alpha's spread and the vane's white noise [rad]


def _flight(seed: int, n: int = 4000) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    alpha = SIGMA_X * rng.standard_normal(n)
    return pd.DataFrame({"t_s": np.arange(n) * 0.02, "flight": "f", "segment": 0,
                         "alpha_rad": alpha + SIGMA_U * rng.standard_normal(n), "beta_rad": np.zeros(n),
                         "C": THETA[0] + THETA[1] * alpha + 1e-3 * rng.standard_normal(n)})


def _regressors(frame: pd.DataFrame) -> dict[str, np.ndarray]:
    return {"C": np.column_stack([np.ones(len(frame)), frame["alpha_rad"].to_numpy()])}


def _ols(frame: pd.DataFrame) -> dict:
    return {"C": fit_linear(frame["C"].to_numpy(), _regressors(frame)["C"], names=["C_0", "C_alpha"], cov="ols")}


def _white_angles():
    return (SIGMA_U, SIGMA_U), None  # sigma per angle [rad], no low-pass: white


def test_plain_least_squares_shows_the_attenuation_of_its_bootstrap_world():
    fd = _flight(0)
    fits = _ols(fd)
    sigma, cut = _white_angles()
    check = estimator_bias(fd, _regressors, fits, _ols, sigma, cut, pairs=8)["C"]
    # the world's alpha is the measured one (variance sx^2 + su^2); with su^2 more, least squares keeps
    # the share (sx^2 + su^2) / (sx^2 + 2 su^2) of the world's slope
    var_w = float(np.var(fd["alpha_rad"]))
    expected = fits["C"].estimate[1] * (var_w / (var_w + SIGMA_U ** 2) - 1.0)
    mc = check.spread[1] / np.sqrt(check.pairs)
    assert check.bias[1] == pytest.approx(expected, abs=4 * mc + 0.02 * abs(expected))
    assert abs(check.bias[1]) > 10 * mc  # a clear bias, not noise
    assert abs(check.bias[0]) < 4 * check.spread[0] / np.sqrt(check.pairs) + 1e-3  # the intercept: none


def test_the_pairs_cancel_what_is_odd_in_the_noise():
    fd = _flight(1)

    def mean_alpha(frame: pd.DataFrame) -> dict:  # an estimator linear in the noise: no bias at all
        return {"C": SimpleNamespace(estimate=np.array([frame["alpha_rad"].mean()]), names=("m",))}

    sigma, cut = _white_angles()
    ones = lambda frame: {"C": np.ones((len(frame), 1))}  # noqa: E731
    check = estimator_bias(fd, ones, mean_alpha(fd), mean_alpha, sigma, cut, pairs=3)["C"]
    assert check.bias[0] == pytest.approx(0.0, abs=1e-15)


def test_noise_drawn_again_through_the_band_and_added_with_either_sign():
    n = 3000
    t = np.arange(n) * 0.01
    fd = pd.DataFrame({"t_s": t, "flight": "f", "segment": 0, "alpha_rad": 0.0, "beta_rad": 0.0,
                       "q_rad_s": 0.0, "eiv_sigma_q_rad_s": 0.01, "delta_p_rad": 0.0,
                       "eiv_sigma_delta_p_rad": 0.0, "band_hz": 2.0})
    noise = sensor_noise(fd, np.random.default_rng(3), None, None)
    assert set(noise) == {"q_rad_s"}  # no angle noise given, a zero-noise surface gets none
    # white noise of 0.01 through the band's low-pass (|H|^2 = 1/(1+(f/fb)^4): bandwidth 1.11 fb)
    assert np.std(noise["q_rad_s"]) == pytest.approx(0.01 * np.sqrt(1.11 * 2.0 / 50.0), rel=0.15)
    plus, minus = with_noise(fd, noise, 1.0), with_noise(fd, noise, -1.0)
    np.testing.assert_allclose(plus["q_rad_s"] + minus["q_rad_s"], 0.0, atol=1e-15)
    assert "q_rad_s" in fd and np.all(fd["q_rad_s"] == 0.0)  # the input is left as it was


def test_a_bias_that_is_only_monte_carlo_noise_is_not_counted():
    check = EstimatorBias(("a", "b"), bias=np.array([1.0, 0.1]), spread=np.array([0.2, 1.0]), pairs=4)
    counted = check.counted
    assert counted[0] == pytest.approx(1.0 * np.sqrt(1 - 0.04 / 4), rel=1e-12)
    assert counted[1] == 0.0


def test_the_counted_bias_goes_into_the_covariance_and_the_warning_names_what_it_moved():
    fd = _flight(2)
    fit = _ols(fd)["C"]
    check = EstimatorBias(fit.names, bias=np.array([0.0, 0.3]), spread=np.zeros(2), pairs=4)
    out = with_bias_counted(fit, check)
    np.testing.assert_allclose(out.cov, np.asarray(fit.cov) + np.outer([0.0, 0.3], [0.0, 0.3]))
    np.testing.assert_array_equal(out.estimate, fit.estimate)  # counted, not subtracted
    assert "C_alpha" in out.warnings[-1] and "C_0" not in out.warnings[-1]
    quiet = with_bias_counted(fit, EstimatorBias(fit.names, np.zeros(2), np.zeros(2), 4))
    assert quiet.warnings == fit.warnings  # nothing counted: no warning


def test_the_world_holds_the_estimators_coefficients_not_least_squares():
    fd = _flight(5)
    fit = _ols(fd)["C"]
    shifted = {"C": SimpleNamespace(estimate=fit.estimate + np.array([0.01, 0.2]), names=fit.names)}
    # without noise to draw, least squares on the world returns the world's coefficients exactly
    check = estimator_bias(fd, _regressors, shifted, _ols, None, None, pairs=2)["C"]
    np.testing.assert_allclose(check.bias, 0.0, atol=1e-10)
    with pytest.raises(ValueError, match="at least 2"):
        estimator_bias(fd, _regressors, shifted, _ols, None, None, pairs=1)


def test_counting_the_bias_makes_an_attenuated_estimator_cover_the_truth():
    sigma, cut = _white_angles()
    plain, counted = [], []
    for seed in range(12):
        fd = _flight(100 + seed, n=2000)
        fit = _ols(fd)["C"]
        out = with_bias_counted(fit, estimator_bias(fd, _regressors, {"C": fit}, _ols, sigma, cut, pairs=4)["C"])
        plain.append(abs(fit.estimate[1] - THETA[1]) <= 1.96 * fit.std_error[1])
        counted.append(abs(out.estimate[1] - THETA[1]) <= 1.96 * out.std_error[1])
    # least squares keeps sx^2 / (sx^2 + su^2) = 74 % of the slope with a sigma of ~2 %: never covers
    assert sum(plain) == 0
    assert sum(counted) >= 11


def test_on_the_reference_flight_the_check_leaves_the_estimates_and_adds_next_to_nothing(reference_run, monkeypatch):
    from aerosid.identification.identify import BIAS_PAIRS, BIAS_PAIRS_ENV, identify
    from aerosid.vehicles.vehicle import load_vehicle

    vehicle = load_vehicle("seed-rlv")
    plain = reference_run.identification  # the suite runs without the check (conftest)
    checked = identify(reference_run.flight_data, vehicle, bias_pairs=BIAS_PAIRS)
    for ch, fit in checked.fits.items():
        np.testing.assert_array_equal(fit.estimate, plain.fits[ch].estimate)
        grew = fit.std_error / plain.fits[ch].std_error
        assert np.all(grew >= 1 - 1e-12)
        # the reference flight's estimates hold (coverage 90-100 % on the bench): every counted bias
        # stays below the coefficient's own sigma, and what moved a sigma by > 5 % is named
        assert np.all(grew[np.isfinite(grew)] < np.sqrt(2.0)), (ch, grew)
        note = next((w for w in fit.warnings if "estimator's own bias" in w), "")
        for name, g in zip(fit.names, grew):
            named = re.search(rf"\b{re.escape(name)} [+-]", note) is not None
            assert named == bool(g > 1.05), (ch, name, g, note)
    monkeypatch.setenv(BIAS_PAIRS_ENV, "x")
    with pytest.raises(ValueError, match="AEROSID_BIAS_PAIRS='x'"):
        identify(reference_run.flight_data, vehicle)
    with pytest.raises(ValueError, match="at least 2"):
        identify(reference_run.flight_data, vehicle, bias_pairs=1)
    monkeypatch.setenv(BIAS_PAIRS_ENV, "1")
    with pytest.raises(ValueError, match="AEROSID_BIAS_PAIRS=1"):
        identify(reference_run.flight_data, vehicle)
