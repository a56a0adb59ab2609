"""The predicted sigma of a design against a seeded Monte-Carlo of the regression."""
import numpy as np
import pytest
import scipy.signal
import scipy.stats

from aerosid.design.predict import ResidualModel, predict_covariance
from aerosid.identification.regression import fit_linear

N = 3000
FS = 100.0
PHI = 0.9  # AR(1) residual, correlation time ~0.1 s


def _ar1(rng, n, sigma=1e-3):
    e = rng.standard_normal(n + 500)
    x = scipy.signal.lfilter([1.0], [1.0, -PHI], e)[500:]
    return sigma * x / np.sqrt(1.0 / (1.0 - PHI**2))


def _regressors(kind: str) -> np.ndarray:
    t = np.arange(N) / FS
    if kind == "run":  # the "flown" manoeuvre: a slow doublet train
        u = np.sign(np.sin(2 * np.pi * 0.2 * t))
    else:  # the "design": a faster multisine
        u = np.cos(2 * np.pi * 0.5 * t) + np.cos(2 * np.pi * 0.9 * t - 1.0)
    x = scipy.signal.lfilter([0.05], [1.0, -0.95], u)  # a lagged response
    return np.column_stack([np.ones(N), u, x])


def test_predicted_sigma_matches_monte_carlo_of_the_regression():
    # the run: one residual realisation -> the residual model the design carries over
    rng = np.random.default_rng(1)
    theta = np.array([0.01, -0.2, 0.5])
    X_run = _regressors("run")
    fit = fit_linear(X_run @ theta + _ar1(rng, N), X_run, names=("c0", "cu", "cx"))
    resid = ResidualModel.from_residual(np.asarray(fit.residuals), FS, max_lag=fit.max_lag)
    # the design: new regressors, the same kind of noise
    X_new = _regressors("design")
    pred = predict_covariance(X_new, ("c0", "cu", "cx"), resid)
    M = 200
    est = np.empty((M, 3))
    for m in range(M):
        y = X_new @ theta + _ar1(np.random.default_rng(1000 + m), N)
        est[m] = fit_linear(y, X_new, names=("c0", "cu", "cx")).estimate
    lo, hi = scipy.stats.chi2.ppf([0.0005, 0.9995], M - 1) / (M - 1)
    for j, name in ((1, "cu"), (2, "cx")):
        ratio = est[:, j].var(ddof=1) / pred.sigma(name) ** 2
        # chi-square band of a variance from M draws, widened by the +-10 % the predicted
        # variance itself carries (one residual realisation of N_eff ~ 150 samples)
        assert lo / 1.25 <= ratio <= hi * 1.25, (name, ratio, lo, hi)


def test_prediction_on_the_runs_own_regressors_is_the_reported_sigma():
    rng = np.random.default_rng(3)
    X = _regressors("run")
    fit = fit_linear(X @ np.array([0.0, 1.0, 2.0]) + _ar1(rng, N), X, names=("a", "b", "c"))
    resid = ResidualModel.from_residual(np.asarray(fit.residuals), FS, max_lag=fit.max_lag)
    pred = predict_covariance(X, ("a", "b", "c"), resid)
    assert np.allclose([pred.sigma(n) for n in "abc"], fit.std_error, rtol=1e-6)
    assert pred.n_eff == pytest.approx(fit.n_eff, rel=1e-9)


def test_sigma_scales_inversely_with_the_excitation_and_detectable_size_uses_t_crit():
    rng = np.random.default_rng(5)
    X = _regressors("design")
    resid = ResidualModel.from_residual(_ar1(rng, N), FS)
    p1 = predict_covariance(X, ("a", "b", "c"), resid)
    X2 = X.copy()
    X2[:, 1:] *= 2.0
    p2 = predict_covariance(X2, ("a", "b", "c"), resid)
    assert p2.sigma("b") == pytest.approx(p1.sigma("b") / 2.0, rel=1e-9)
    tc = scipy.stats.t.isf(0.0005, p1.dof_eff)
    assert p1.detectable_size("b") == pytest.approx(tc * p1.sigma("b"), rel=1e-12)
    assert p1.reliable_size("b") > p1.detectable_size("b")
