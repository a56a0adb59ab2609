"""Tests of aerosid.identification.regression (method.md §11-§12): recovery, honest uncertainty, diagnostics."""
from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
import scipy.linalg
import scipy.signal
import scipy.stats
import statsmodels.api as sm

from aerosid.identification.regression import LinearFit, fit_linear, residual_autocovariance

FS = 100.0  # Hz
N = 8000  # 80 s at 100 Hz
NAMES = ("CN_0", "CN_alpha", "CN_delta")
TRUE = np.array([0.05, 1.75, 0.069])  # intercept, per rad, per rad (delta_p/2)


def manoeuvre(rng: np.random.Generator, n: int = N) -> np.ndarray:
    """Regressors [1, alpha, delta_p/2] [rad]: ~0.1-0.3 Hz multisine fin input and an alpha
    that follows it (low-passed) on top of a 0.17 Hz oscillation about 1.6 deg."""
    t = np.arange(n) / FS
    delta = np.zeros(n)
    for f in (0.13, 0.21, 0.31):
        delta += np.deg2rad(0.7) * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
    b, a = scipy.signal.butter(2, 0.25 / (FS / 2))
    alpha = (
        np.deg2rad(1.6)
        + np.deg2rad(1.0) * np.sin(2 * np.pi * 0.17 * t + rng.uniform(0, 2 * np.pi))
        + 0.5 * scipy.signal.lfilter(b, a, delta)
    )
    return np.column_stack([np.ones(n), alpha, delta / 2])


def ar1(rng: np.random.Generator, n: int, phi: float, sigma: float) -> np.ndarray:
    """Stationary AR(1) with marginal standard deviation sigma."""
    w = rng.normal(0.0, sigma * np.sqrt(1 - phi**2), n)
    w[0] = rng.normal(0.0, sigma)
    return scipy.signal.lfilter([1.0], [1.0, -phi], w)


def covered(ci: np.ndarray, truth: np.ndarray) -> np.ndarray:
    return (ci[:, 0] <= truth) & (truth <= ci[:, 1])


# ----------------------------------------------------------------------------- (a) white noise
@pytest.mark.parametrize("seed", range(5))
def test_white_noise_recovery_and_sigma_ratio(seed):
    rng = np.random.default_rng(seed)
    X = manoeuvre(rng)
    y = X @ TRUE + rng.normal(0.0, 0.002, N)
    fit = fit_linear(y, X, names=NAMES, channel="CN")
    z = np.abs(fit.estimate - TRUE) / fit.std_error
    assert np.all(z < 3.0), z
    ratio = fit.std_error / fit.std_error_ols
    assert np.all((ratio > 0.8) & (ratio < 1.25)), ratio
    assert fit.n_eff > 0.5 * N
    assert fit.r2 > 0.9


def test_white_noise_no_lag_equals_ols_exactly():
    rng = np.random.default_rng(11)
    X = manoeuvre(rng, 2000)
    y = X @ TRUE + rng.normal(0.0, 0.002, 2000)
    fit = fit_linear(y, X, names=NAMES, block=0)
    np.testing.assert_allclose(fit.cov, fit.cov_ols, rtol=1e-10)


# ----------------------------------------------------------------------------- (b) coloured noise
def _coverage(seeds, cov, phi=0.99, sigma=0.002):
    cov_c, cov_o, ratios, errs = [], [], [], []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        X = manoeuvre(rng)
        y = X @ TRUE + ar1(rng, N, phi, sigma)
        fit = fit_linear(y, X, names=NAMES, channel="CN", cov=cov)
        cov_c.append(covered(fit.conf_int(0.05), TRUE))
        cov_o.append(covered(fit.conf_int_ols(0.05), TRUE))
        ratios.append(fit.std_error / fit.std_error_ols)
        errs.append((fit.estimate - TRUE) / fit.std_error)
    return (np.mean(cov_c, axis=0), np.mean(cov_o, axis=0), np.median(ratios, axis=0), np.array(errs))


def test_coloured_noise_coverage_morelli_klein(record_property):
    """AR(1) phi = 0.99 (1 s correlation time) on 0.1-0.3 Hz manoeuvres, N = 8000, 300 seeds.

    300 seeds (not the minimum 40) so that the binomial noise of the coverage estimate
    (sd ~1.3 %) is small against the margin between nominal 95 % and the 90 % floor."""
    corrected, ols, ratio, z = _coverage(range(300), "morelli_klein")
    msg = f"coverage corrected {corrected}, OLS {ols}, median sigma ratio {ratio}"
    print(msg)
    record_property("coverage", msg)
    assert np.all(corrected >= 0.90), msg
    assert np.all(ols < corrected), msg
    assert np.all(ols < 0.5), msg  # plain OLS intervals are far too narrow
    assert np.all(ratio > 3.0), msg
    # the normalised errors are roughly unit-variance (not hugely over-conservative either)
    assert np.all(np.std(z, axis=0) < 1.3) and np.all(np.std(z, axis=0) > 0.7), np.std(z, axis=0)


def test_coloured_noise_coverage_hac(record_property):
    corrected, ols, ratio, _ = _coverage(range(40), "hac")
    msg = f"HAC coverage {corrected}, OLS {ols}, median sigma ratio {ratio}"
    print(msg)
    record_property("coverage_hac", msg)
    assert np.all(corrected >= 0.80), msg
    assert np.all(ols < corrected), msg


def test_statsmodels_default_newey_west_lag_is_too_short():
    """The documented reason for our lag rule: 10 lags (statsmodels' rule at N=8000) undercover."""
    cov_short = []
    for seed in range(40):
        rng = np.random.default_rng(seed)
        X = manoeuvre(rng)
        y = X @ TRUE + ar1(rng, N, 0.99, 0.002)
        fit = fit_linear(y, X, names=NAMES, cov="hac", hac_maxlags=int(4 * (N / 100) ** (2 / 9)))
        cov_short.append(covered(fit.conf_int(), TRUE))
    assert np.all(np.mean(cov_short, axis=0) < 0.8)


def test_morelli_klein_equals_brute_force_double_sum():
    rng = np.random.default_rng(3)
    n, L = 300, 40
    X = manoeuvre(rng, n)
    y = X @ TRUE + ar1(rng, n, 0.9, 0.002)
    fit = fit_linear(y, X, names=NAMES, block=L)
    th, *_ = np.linalg.lstsq(X, y, rcond=None)
    v = y - X @ th
    r = np.array([v[: n - k] @ v[k:] / n for k in range(n)])
    z = np.arange(L + 1) / (L + 1.0)
    w = np.where(z <= 0.5, 1 - 6 * z**2 + 6 * z**3, 2 * (1 - z) ** 3)
    rw = np.zeros(n)
    rw[: L + 1] = r[: L + 1] * w
    T = scipy.linalg.toeplitz(rw)
    A = np.linalg.inv(X.T @ X)
    cov = A @ (X.T @ T @ X) @ A
    rho = rw[1 : L + 1] / rw[0]
    n_eff = np.clip(n / (1 + 2 * rho.sum()), 4, n)
    cov *= n_eff / (n_eff - 3)
    np.testing.assert_allclose(fit.cov, cov, rtol=1e-9)
    np.testing.assert_allclose(fit.n_eff, n_eff, rtol=1e-12)
    np.testing.assert_allclose(residual_autocovariance(v, 10), r[:11], rtol=1e-9, atol=1e-18)


def test_grouped_morelli_klein_equals_brute_force_within_group_double_sum():
    """Pooled records (groups): the double sum takes products within each record only
    (block-diagonal Toeplitz), R_vv pooled within the records, divided by the total N."""
    rng = np.random.default_rng(4)
    sizes, L = (180, 120, 200), 30
    X = np.vstack([manoeuvre(rng, m) for m in sizes])
    y = X @ TRUE + np.concatenate([ar1(rng, m, 0.9, 0.002) for m in sizes])
    groups = np.repeat(["a", "b", "c"], sizes)
    fit = fit_linear(y, X, names=NAMES, block=L, groups=groups)
    n = len(y)
    th, *_ = np.linalg.lstsq(X, y, rcond=None)
    v = y - X @ th
    edges = np.cumsum((0,) + sizes)
    r = np.zeros(L + 1)
    for a, b in zip(edges[:-1], edges[1:]):
        vg = v[a:b]
        r += np.array([vg[: len(vg) - k] @ vg[k:] for k in range(L + 1)])
    r /= n
    z = np.arange(L + 1) / (L + 1.0)
    rw = r * np.where(z <= 0.5, 1 - 6 * z**2 + 6 * z**3, 2 * (1 - z) ** 3)
    T = scipy.linalg.block_diag(*[scipy.linalg.toeplitz(np.r_[rw, np.zeros(m - L - 1)]) for m in sizes])
    A = np.linalg.inv(X.T @ X)
    cov = A @ (X.T @ T @ X) @ A
    n_eff = np.clip(n / (1 + 2 * (rw[1:] / rw[0]).sum()), 4, n)
    np.testing.assert_allclose(fit.cov, cov * n_eff / (n_eff - 3), rtol=1e-9)
    np.testing.assert_allclose(fit.n_eff, n_eff, rtol=1e-12)


def test_grouped_sigma_does_not_depend_on_the_order_of_the_records():
    """Stacking two manoeuvres A,B or B,A is the same data: with groups the corrected
    sigma is the same; treated as one record it is not (the junction's products)."""
    rng = np.random.default_rng(5)
    XA, XB = manoeuvre(rng, 1500), manoeuvre(rng, 1500)
    vA, vB = ar1(rng, 1500, 0.995, 0.003) + 0.004, ar1(rng, 1500, 0.995, 0.003) + 0.004  # both end high
    yA, yB = XA @ TRUE + vA, XB @ TRUE + vB
    ab = dict(y=np.r_[yA, yB], X=np.vstack([XA, XB]), groups=np.repeat(["A", "B"], 1500))
    ba = dict(y=np.r_[yB, yA], X=np.vstack([XB, XA]), groups=np.repeat(["B", "A"], 1500))
    g_ab = fit_linear(ab["y"], ab["X"], names=NAMES, block=300, groups=ab["groups"])
    g_ba = fit_linear(ba["y"], ba["X"], names=NAMES, block=300, groups=ba["groups"])
    np.testing.assert_allclose(g_ab.std_error, g_ba.std_error, rtol=1e-9)
    np.testing.assert_allclose(g_ab.estimate, g_ba.estimate, rtol=1e-9)
    c_ab = fit_linear(ab["y"], ab["X"], names=NAMES, block=300)
    c_ba = fit_linear(ba["y"], ba["X"], names=NAMES, block=300)
    assert np.max(np.abs(c_ab.std_error / c_ba.std_error - 1)) > 1e-3
    # one group is the ungrouped fit, bit for bit; groups must be contiguous
    one = fit_linear(ab["y"], ab["X"], names=NAMES, groups=np.full(3000, "A"))
    plain = fit_linear(ab["y"], ab["X"], names=NAMES)
    np.testing.assert_array_equal(one.cov, plain.cov)
    with pytest.raises(ValueError, match="contiguous"):
        fit_linear(ab["y"], ab["X"], names=NAMES, groups=np.tile(["A", "B"], 1500))


def test_grouped_hac_uses_statsmodels_panel_newey_west():
    rng = np.random.default_rng(6)
    X = np.vstack([manoeuvre(rng, 800), manoeuvre(rng, 600)])
    y = X @ TRUE + np.r_[ar1(rng, 800, 0.9, 0.002), ar1(rng, 600, 0.9, 0.002)]
    g = np.repeat([0, 1], [800, 600])
    fit = fit_linear(y, X, names=NAMES, cov="hac", hac_maxlags=25, groups=g)
    ref = sm.OLS(y, X).fit(cov_type="hac-panel", cov_kwds={"groups": g, "maxlags": 25})
    np.testing.assert_allclose(fit.std_error, ref.bse, rtol=1e-10)


# ----------------------------------------------------------------------------- (c) closed form
def test_estimates_equal_lstsq_and_statsmodels():
    rng = np.random.default_rng(7)
    X = manoeuvre(rng, 3000)
    y = X @ TRUE + ar1(rng, 3000, 0.95, 0.003)
    fit = fit_linear(y, pd.DataFrame(X, columns=NAMES), channel="CN")
    th, *_ = np.linalg.lstsq(X, y, rcond=None)
    np.testing.assert_allclose(fit.estimate, th, rtol=1e-12, atol=0)
    ref = sm.OLS(y, X).fit()
    np.testing.assert_allclose(fit.std_error_ols, ref.bse, rtol=1e-10)
    np.testing.assert_allclose(fit.r2, ref.rsquared, rtol=1e-12)
    np.testing.assert_allclose(fit.r2_adj, ref.rsquared_adj, rtol=1e-12)
    np.testing.assert_allclose(fit.f_stat, ref.fvalue, rtol=1e-9)
    np.testing.assert_allclose(fit.conf_int_ols(), ref.conf_int(), rtol=1e-10)
    np.testing.assert_allclose(fit.residuals, y - X @ th, atol=1e-13)
    # PSE (Morelli): RSS/N + var(y) p / N
    rss = np.sum((y - X @ th) ** 2)
    np.testing.assert_allclose(fit.pse, rss / 3000 + np.var(y) * 3 / 3000, rtol=1e-12)
    # intervals from the corrected sigma with t(dof_eff)
    q = scipy.stats.t.ppf(0.975, fit.dof_eff)
    np.testing.assert_allclose(fit.conf_int()[:, 1], fit.estimate + q * fit.std_error, rtol=1e-14)
    np.testing.assert_allclose(fit.predict(X), X @ th, rtol=1e-12)


def test_hac_uses_statsmodels_newey_west():
    rng = np.random.default_rng(8)
    X = manoeuvre(rng, 2000)
    y = X @ TRUE + ar1(rng, 2000, 0.95, 0.003)
    fit = fit_linear(y, X, names=NAMES, cov="hac", hac_maxlags=50)
    ref = sm.OLS(y, X).fit(cov_type="HAC", cov_kwds={"maxlags": 50, "use_correction": True})
    np.testing.assert_allclose(fit.std_error, ref.bse, rtol=1e-10)
    assert fit.max_lag == 50 and fit.method == "hac"


def test_weights_match_statsmodels_wls():
    rng = np.random.default_rng(9)
    X = manoeuvre(rng, 2000)
    w = rng.uniform(0.5, 2.0, 2000)
    y = X @ TRUE + rng.normal(0, 0.002, 2000) / np.sqrt(w)
    fit = fit_linear(y, X, names=NAMES, weights=w, cov="ols")
    ref = sm.WLS(y, X, weights=w).fit()
    np.testing.assert_allclose(fit.estimate, ref.params, rtol=1e-10)
    np.testing.assert_allclose(fit.std_error_ols, ref.bse, rtol=1e-9)
    np.testing.assert_allclose(fit.r2, ref.rsquared, rtol=1e-10)


def test_nan_rows_dropped_and_intercept_added():
    rng = np.random.default_rng(10)
    X = manoeuvre(rng, 1000)
    y = X @ TRUE + rng.normal(0, 0.002, 1000)
    y[5] = np.nan
    X[17, 1] = np.nan
    df = pd.DataFrame({"CN_alpha": X[:, 1], "CN_delta": X[:, 2]})
    fit = fit_linear(y, df, channel="CN", add_intercept=True)
    assert fit.names == NAMES
    assert fit.n_dropped == 2 and fit.n_obs == 998 and fit.residuals.shape == (998,)
    assert fit.has_intercept


# ----------------------------------------------------------------------------- (d) identifiability
def test_non_identifiable_columns_are_nan_with_warning():
    rng = np.random.default_rng(12)
    X = manoeuvre(rng, 2000)
    y = X @ TRUE + rng.normal(0, 0.002, 2000)
    df = pd.DataFrame(X, columns=NAMES)
    df["CN_q"] = 0.0  # no excitation at all
    df["CN_bias2"] = 2.0  # a second constant besides the intercept
    df["CN_combo"] = 2 * df["CN_alpha"] - df["CN_delta"]  # exact collinearity
    fit = fit_linear(y, df, channel="CN")
    ref = fit_linear(y, X, names=NAMES, channel="CN")
    bad = ["CN_q", "CN_bias2", "CN_combo"]
    for name in bad:
        i = fit.names.index(name)
        assert not fit.identifiable[i]
        assert np.isnan(fit.estimate[i]) and np.isnan(fit.std_error[i]) and np.isnan(fit.std_error_ols[i])
        assert np.all(np.isnan(fit.conf_int()[i]))
        assert any(f"not identifiable: no excitation in {name}" in w for w in fit.warnings), fit.warnings
    np.testing.assert_allclose(fit.estimate[:3], ref.estimate, rtol=1e-12)
    np.testing.assert_allclose(fit.std_error[:3], ref.std_error, rtol=1e-9)
    assert fit.n_params == 3
    assert "not identifiable" in fit.summary()
    rec = {r["coefficient"]: r for r in fit.as_records()}
    assert np.isnan(rec["CN_q"]["estimate"])
    np.testing.assert_allclose(fit.predict(df), ref.fitted, rtol=1e-12)


# ----------------------------------------------------------------------------- (e) collinearity
def test_condition_number_and_vif_warnings():
    rng = np.random.default_rng(13)
    X = manoeuvre(rng, 4000)
    near = X[:, 1] + 1e-4 * rng.normal(size=4000)  # nearly a copy of alpha
    Xc = np.column_stack([X, near])
    y = X @ TRUE + rng.normal(0, 0.002, 4000)
    fit = fit_linear(y, Xc, names=NAMES + ("CN_alpha_copy",))
    assert fit.condition_number > 30
    assert any("condition number" in w for w in fit.warnings)
    assert any("VIF(CN_alpha)" in w for w in fit.warnings)
    assert fit.vif[1] > 10 and np.isnan(fit.vif[0])
    assert all(fit.identifiable)  # near, not exact, collinearity is still estimated
    good = fit_linear(y, X, names=NAMES)
    assert good.condition_number < 30
    assert not any("condition number" in w or "VIF" in w for w in good.warnings)


# ----------------------------------------------------------------------------- (g) summary / records
def test_summary_numbers_warnings_and_records():
    rng = np.random.default_rng(14)
    X = manoeuvre(rng)
    y = X @ TRUE + ar1(rng, N, 0.99, 0.002)
    df = pd.DataFrame(X, columns=NAMES)
    df["CN_dead"] = 0.0
    fit = fit_linear(y, df, channel="CN")
    text = fit.summary()
    assert len(fit.warnings) >= 2  # dead column + coloured residuals
    for i, w in enumerate(fit.warnings, start=1):
        assert f"[{i}] {w}" in text
    assert "Cond. no." in text and "R-squared" in text and "F-statistic" in text and "PSE" in text
    recs = fit.as_records()
    assert [r["coefficient"] for r in recs] == list(df.columns)
    assert set(recs[0]) == {
        "channel", "coefficient", "estimate", "std_error", "std_error_ols",
        "ci_low", "ci_high", "t_value", "p_value",
    }
    assert recs[1]["channel"] == "CN"
    assert recs[1]["ci_low"] < recs[1]["estimate"] < recs[1]["ci_high"]
    pd.DataFrame(recs)  # tabular


def test_result_is_frozen():
    rng = np.random.default_rng(15)
    X = manoeuvre(rng, 500)
    fit = fit_linear(X @ TRUE + rng.normal(0, 0.002, 500), X, names=NAMES)
    assert isinstance(fit, LinearFit)
    with pytest.raises(dataclasses.FrozenInstanceError):
        fit.r2 = 0.0  # type: ignore[misc]
    with pytest.raises(ValueError):
        fit.estimate[0] = 1.0
    assert fit["CN_alpha"] == fit.estimate[1]


def test_bad_arguments():
    X = np.ones((10, 1))
    with pytest.raises(ValueError):
        fit_linear(np.ones(10), X, cov="bogus")
    with pytest.raises(ValueError):
        fit_linear(np.ones(9), X)
    with pytest.raises(ValueError):
        fit_linear(np.ones(10), np.zeros((10, 2)))  # nothing identifiable


def test_linear_combination_uses_the_full_covariance():
    """Two nearly collinear regressors: each coefficient is poorly determined, their sum well
    (the pitch-damping situation, Cm_q + Cm_alpha_dot); the sum's sigma comes from the covariance."""
    rng = np.random.default_rng(3)
    n = 4000
    a = rng.standard_normal(n)
    b = a + 0.05 * rng.standard_normal(n)
    y = -12.0 * a - 5.0 * b + 0.5 * rng.standard_normal(n)
    fit = fit_linear(y, pd.DataFrame({"q": a, "adot": b}), names=["q", "adot"], cov="ols")
    est, se, lo, hi = fit.combination({"q": 1.0, "adot": 1.0})
    assert abs(est - (-17.0)) < 4 * se
    assert se < 0.2 * min(fit.std_error)  # the sum is far better known than either term
    expected = np.sqrt(fit.cov[0, 0] + fit.cov[1, 1] + 2 * fit.cov[0, 1])
    assert se == pytest.approx(expected, rel=1e-12)
    assert lo < est < hi


def test_linear_combination_of_a_non_identifiable_term_is_nan():
    rng = np.random.default_rng(4)
    a = rng.standard_normal(500)
    X = pd.DataFrame({"q": a, "adot": np.zeros(500)})  # no excitation in adot
    fit = fit_linear(2 * a + 0.1 * rng.standard_normal(500), X, names=["q", "adot"], cov="ols")
    assert all(np.isnan(v) for v in fit.combination({"q": 1.0, "adot": 1.0}))
    assert np.isfinite(fit.combination({"q": 1.0})[0])
