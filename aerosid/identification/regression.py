"""Multiple linear regression of flight-derived coefficients (method.md §11-§12).

One entry point, :func:`fit_linear`, fits ``y = X theta + v`` by ordinary (or
weighted) least squares and returns a frozen :class:`LinearFit` that reports,
beside the plain least-squares numbers, an *honest* standard error corrected for
coloured residuals.  The pitch, yaw and roll models of method.md §11 are all of
this form; the caller builds the regressor columns (``alpha``, ``delta_p/2``,
``cos(4 phi_r)``, ...) and the intercept column (or asks for one with
``add_intercept=True``).

Why a correction at all
-----------------------
Coefficients computed from smoothed Kalman states have residuals that are
correlated over hundreds of samples (smoothing plus model error).  The least
squares covariance ``s^2 (X'X)^-1`` assumes white residuals and is then far too
small (method.md §12: the seed's C_m_alpha,cg is 30 % off at hundreds of its
sigma).  Two corrections are provided:

``cov="morelli_klein"`` (default)
    Morelli & Klein, "Accurate estimation of aerodynamic model parameter
    uncertainties from flight test data with colored residuals" (J. Aircraft
    34(4), 1997) and "Aircraft System Identification" §5.2::

        Cov(theta) = (X'X)^-1 [ sum_i sum_j x_i R_vv(i-j) x_j' ] (X'X)^-1

    with ``R_vv(k) = (1/N) sum_i v_i v_(i+k)`` the (biased) residual
    autocovariance, computed by FFT.  The double sum is evaluated as
    ``X' (T X)`` where ``T`` is the Toeplitz matrix of ``R_vv``; ``T X`` is an
    FFT convolution, so the cost is O(k N log N).

    *Truncation.*  The original full double sum (all N-1 lags) uses the noisy
    large-lag tail of ``R_vv`` and, because the residuals are orthogonal to the
    regressors, is biased low exactly at the regressors' frequencies; in our
    Monte-Carlo (AR(1) phi = 0.99, 0.1-0.3 Hz manoeuvres, N = 8000, 300 seeds)
    it covered only 87-93 % at a nominal 95 % (81-89 % with normal quantiles);
    the windowed version below covers 94-96 %.  We therefore weight ``R_vv(k)`` by a Parzen lag
    window of half-width ``L`` (zero beyond ``L``).  The Parzen window has a
    non-negative spectral window, so the corrected covariance stays positive
    semi-definite.  Automatic rule: ``L = 4 k0`` where ``k0`` is the first lag at
    which the residual autocovariance crosses zero (``L <= N-1``); pass
    ``block=L`` to override.  For white residuals ``k0 = 1``, ``L = 4`` and the
    correction is within a few per cent of the OLS covariance (exactly equal with
    ``block=0``).

    *Small-sample factor.*  The corrected covariance is multiplied by
    ``N_eff / (N_eff - p)`` (p identifiable parameters), the coloured-residual
    analogue of the ``N/(N-p)`` in ``s^2``; with white residuals it reproduces
    ``s^2 (X'X)^-1`` exactly.

``cov="hac"``
    Newey-West (Bartlett kernel) through statsmodels,
    ``OLS.fit(cov_type="HAC", cov_kwds={"maxlags": L, "use_correction": True})``.
    statsmodels' default lag rule ``floor(4 (N/100)^(2/9))`` is 10 lags at
    N = 8000 (0.1 s at 100 Hz), far shorter than residual correlation times of
    ~1 s, and gave ~45 % coverage in the Monte-Carlo.  The default here is
    ``L = 2 k0`` (``k0`` as above), which covered 89-93 % in that Monte-Carlo
    (Bartlett's lag-window bias makes longer windows worse there: 77-85 % at
    ``8 k0``); pass ``hac_maxlags`` to override.  The Morelli-Klein default
    covered 94-96 % on the same data, hence it is the default.

``cov="ols"``
    Plain least squares; the corrected fields then equal the OLS ones.

Several records (``groups``)
----------------------------
Pooled manoeuvres (or flights) are separate records: the residual of one is not
correlated with the next one's across the junction.  With ``groups`` (one label per
row, rows of a group contiguous) the residual autocovariance is the pooled
within-group one, ``R(k) = (1/N) sum_g sum_i v_(g,i) v_(g,i+k)``, and the middle
matrix is ``sum_g X_g' T X_g`` (no product of samples of two groups); the lag
window's rule and N_eff use that R.  Treating the junction as contiguous instead
would add products ``v_i v_j`` of the end of one record and the start of the next,
within L samples of each other: a bias of order L/N_g that depends on the order in
which the records are stacked.  A single group is exactly the ungrouped fit.  HAC
uses statsmodels' ``hac-panel`` with the same groups.

Effective sample size and interval quantiles
--------------------------------------------
``N_eff = N / (1 + 2 sum_{k=1..L} w_k rho_k)`` (``rho`` the residual
autocorrelation, ``w`` the same Parzen window, clipped to ``[p+1, N]``).
Confidence intervals, t and p values of the corrected fit use Student-t
quantiles with ``dof_eff = N_eff - p`` degrees of freedom (for white residuals
that is the usual ``N - p``).  ``conf_int_ols`` uses ``N - p``.

Other choices
-------------
* PSE (Morelli's predicted squared error):
  ``PSE = RSS/N + sigma2_max * p / N`` with ``sigma2_max`` the variance of the
  response about its mean (the fit error variance of the intercept-only model,
  Morelli's a-priori upper bound).  It depends on ``y`` only, so it is the same
  for every candidate model of one response; stepwise passes it explicitly.
* Condition number: 2-norm condition number of the identifiable regressor
  matrix with every column scaled to unit Euclidean length (Belsley, Kuh &
  Welsch; not centred, so a regressor with small excursions about a large mean
  shows up as collinear with the intercept).  Warning above 30 (BKW:
  "moderate to strong" dependencies).
* VIF_j = 1 / (1 - R_j^2), R_j^2 of regressor j on the other regressors
  (centred when an intercept is present, uncentred otherwise); NaN for the
  intercept and for non-identifiable columns.  Warning above 10.
* F statistic: ``f_stat`` is the classical regression F (OLS, all non-intercept
  terms zero), comparable to the seed's figures; ``f_stat_corrected`` is the
  Wald F from the corrected covariance with ``(q, dof_eff)`` dof.
* Non-identifiable columns (all zero, constant besides the intercept, exactly
  collinear with earlier columns) are not fitted: estimate, sigma, t, p and
  intervals are NaN, with a warning "not identifiable: no excitation in <name>";
  ``predict`` treats them as zero.
* Weights (statsmodels convention, proportional to 1/variance): the fit and all
  statistics use the weighted rows ``sqrt(w) y``, ``sqrt(w) X``; ``residuals``
  and ``fitted`` are in the units of ``y``.

The result class is in :mod:`aerosid.identification.linear_fit`, the residual
autocovariance, lag window and Morelli-Klein covariance in
:mod:`aerosid.identification.residual_covariance`; both are importable from here.

Imports numpy, scipy, pandas and statsmodels only.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Sequence

import numpy as np
import pandas as pd
import scipy.stats
import statsmodels.api as sm

from aerosid.identification.linear_fit import LinearFit, _as_readonly, _readonly_bool
from aerosid.identification.residual_covariance import (HAC_LAG_MULTIPLE, LAG_MULTIPLE, _effective_n, _group_slices,
                                                        _morelli_klein, _parzen, _pooled_autocovariance,
                                                        auto_max_lag, residual_autocovariance)

__all__ = [
    "LinearFit",
    "fit_linear",
    "residual_autocovariance",
    "auto_max_lag",
    "COND_WARN",
    "VIF_WARN",
    "LAG_MULTIPLE",
    "HAC_LAG_MULTIPLE",
]

COND_WARN = 30.0
"""Scaled condition number above which a collinearity warning is issued."""
VIF_WARN = 10.0
"""Variance inflation factor above which a collinearity warning is issued."""
_COLLINEAR_TOL = 1e-9  # relative residual norm below which a column is "exactly" collinear
_METHODS = ("morelli_klein", "hac", "ols")


# --------------------------------------------------------------------------- fitting
def _identifiability(X: np.ndarray, names: Sequence[str]):
    """Return (keep mask, intercept index or None, list of warning strings)."""
    n, k = X.shape
    keep = np.ones(k, dtype=bool)
    warns: list[str] = []
    intercept = None
    scale = np.max(np.abs(X), axis=0) if n else np.zeros(k)
    for j in range(k):
        if scale[j] == 0.0:
            keep[j] = False
            warns.append(f"not identifiable: no excitation in {names[j]} (column is all zero); estimate and sigma are NaN")
            continue
        if np.ptp(X[:, j]) <= 1e-12 * scale[j]:
            if intercept is None:
                intercept = j
            else:
                keep[j] = False
                warns.append(
                    f"not identifiable: no excitation in {names[j]} (constant, duplicates the intercept "
                    f"{names[intercept]}); estimate and sigma are NaN"
                )
    # exact collinearity, in column order: a column is dropped when it lies in the
    # span of the columns kept before it.
    kept: list[int] = []
    for j in range(k):
        if not keep[j]:
            continue
        xj = X[:, j] / np.linalg.norm(X[:, j])
        if kept:
            B = X[:, kept] / np.linalg.norm(X[:, kept], axis=0)
            c, *_ = np.linalg.lstsq(B, xj, rcond=None)
            res = np.linalg.norm(xj - B @ c)
            if res < _COLLINEAR_TOL:
                keep[j] = False
                others = [names[kept[i]] for i in np.nonzero(np.abs(c) > 1e-8)[0]]
                warns.append(
                    f"not identifiable: no excitation in {names[j]} independent of "
                    f"{', '.join(others) or 'the other regressors'} (exactly collinear); estimate and sigma are NaN"
                )
                continue
        kept.append(j)
    return keep, intercept, warns


def with_added_covariance(fit: LinearFit, extra_cov: np.ndarray, note: str) -> LinearFit:
    """The same fit with ``extra_cov`` (k, k) added to the coefficients' covariance (a part the
    residuals do not see, e.g. model-structure uncertainty); sigma, t, p and the intervals follow."""
    return with_posterior(fit, fit.estimate, np.asarray(fit.cov, float) + np.asarray(extra_cov, float), note)


def with_posterior(fit: LinearFit, estimate: np.ndarray, cov: np.ndarray, note: str) -> LinearFit:
    """The same fit with the estimate and covariance of a posterior (the fit combined with prior
    information, e.g. aerosid.identification.damping_prior); sigma, t, p and the intervals follow;
    the plain OLS sigma and the residual statistics stay those of the fit.  An empty note adds no
    warning."""
    cov = np.asarray(cov, float)
    est = np.asarray(estimate, float)
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        t = est / se
    p = 2.0 * scipy.stats.t.sf(np.abs(t), fit.dof_eff)
    return dataclasses.replace(fit, estimate=_as_readonly(est), std_error=_as_readonly(se), cov=_as_readonly(cov),
                               t_values=_as_readonly(t), p_values=_as_readonly(p),
                               warnings=tuple(fit.warnings) + ((note,) if note else ()))


def with_corrected_estimate(fit: LinearFit, estimate: np.ndarray, note: str,
                            std_error: np.ndarray | None = None, information: tuple | None = None) -> LinearFit:
    """The same fit with another estimate vector (e.g. corrected for errors in the
    regressors); t, p and the intervals follow it; `std_error` (optional) replaces the
    corrected sigma (the covariance is rescaled to it, correlations kept); the plain OLS
    sigma and the residual statistics stay those of the fit; `note` is added to its warnings;
    `information` (optional): the correction's (naive, noise-free) X^T X (LinearFit.information_eiv)."""
    est = np.asarray(estimate, dtype=float)
    se, cov = fit.std_error, fit.cov
    if std_error is not None:
        se = np.asarray(std_error, dtype=float)
        with np.errstate(invalid="ignore", divide="ignore"):
            k = np.where(fit.std_error > 0, se / fit.std_error, 1.0)
        cov = fit.cov * np.outer(k, k)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = est / se
    p = 2.0 * scipy.stats.t.sf(np.abs(t), fit.dof_eff)
    return dataclasses.replace(fit, estimate=_as_readonly(est), std_error=_as_readonly(se), cov=_as_readonly(cov),
                               t_values=_as_readonly(t), p_values=_as_readonly(p),
                               warnings=tuple(fit.warnings) + (note,),
                               information_eiv=fit.information_eiv if information is None else information)


def fit_linear(
    y: Any,
    X: Any,
    *,
    names: Sequence[str] | None = None,
    channel: str = "",
    weights: Any = None,
    cov: str = "morelli_klein",
    hac_maxlags: int | None = None,
    block: int | None = None,
    add_intercept: bool = False,
    intercept_name: str | None = None,
    sigma2_max: float | None = None,
    groups: Any = None,
) -> LinearFit:
    """Least-squares fit of ``y`` on the columns of ``X`` with honest uncertainty.

    Parameters
    ----------
    y : (N,) response (e.g. C_N time series).
    X : DataFrame (column names used unless ``names`` given) or (N, k) array.
    names : regressor (coefficient) names, e.g. ``("CN_0", "CN_alpha", "CN_delta")``.
    channel : label of the response, e.g. ``"CN"``.
    weights : optional (N,) weights proportional to 1/variance.
    cov : ``"morelli_klein"`` (default), ``"hac"`` or ``"ols"``; see module doc.
    hac_maxlags : HAC Bartlett lag truncation (default: automatic rule).
    block : Morelli-Klein lag-window half-width L in samples (default: automatic
        rule ``4 x`` first zero crossing of the residual autocovariance).
    add_intercept : prepend a column of ones named ``intercept_name``
        (default ``f"{channel}_0"`` or ``"const"``).
    sigma2_max : PSE a-priori fit-error variance bound (default: variance of y).
    groups : optional (N,) labels of separate records (e.g. pooled manoeuvres), rows
        of a group contiguous: the coloured-residual correction then takes no residual
        products across two records (module doc).  One label = no groups.

    Rows with NaN in y, X or weights are dropped (``n_dropped``).  Data are
    assumed to be one contiguous, equally spaced record (per group).
    """
    if cov not in _METHODS:
        raise ValueError(f"cov must be one of {_METHODS}, got {cov!r}")
    # ---- assemble arrays
    if isinstance(X, pd.DataFrame):
        col_names = [str(c) for c in X.columns]
        A = X.to_numpy(dtype=float)
    elif isinstance(X, pd.Series):
        col_names = [str(X.name) if X.name is not None else "x0"]
        A = X.to_numpy(dtype=float)[:, None]
    else:
        A = np.asarray(X, dtype=float)
        if A.ndim == 1:
            A = A[:, None]
        col_names = [f"x{i}" for i in range(A.shape[1])]
    if names is not None:
        names = [str(n) for n in names]
        if len(names) != A.shape[1]:
            raise ValueError(f"{len(names)} names for {A.shape[1]} regressor columns")
        col_names = names
    if add_intercept:
        iname = intercept_name or (f"{channel}_0" if channel else "const")
        A = np.column_stack([np.ones(A.shape[0]), A])
        col_names = [iname] + col_names
    if len(set(col_names)) != len(col_names):
        raise ValueError(f"duplicate regressor names: {col_names}")
    yv = np.asarray(y, dtype=float).reshape(-1)
    if yv.size != A.shape[0]:
        raise ValueError(f"y has {yv.size} rows, X has {A.shape[0]}")
    ok = np.isfinite(yv) & np.all(np.isfinite(A), axis=1)
    if weights is not None:
        w = np.asarray(weights, dtype=float).reshape(-1)
        if w.size != yv.size:
            raise ValueError("weights must have one value per row")
        ok &= np.isfinite(w)
        if np.any(w[ok] < 0):
            raise ValueError("weights must be non-negative")
    n_dropped = int((~ok).sum())
    if groups is not None:
        groups = np.asarray(groups)
        if groups.shape != yv.shape:
            raise ValueError("groups must have one label per row")
        groups = groups[ok]
    slices = _group_slices(groups)
    yv, A = yv[ok], A[ok]
    sw = np.sqrt(w[ok]) if weights is not None else np.ones(yv.size)
    n, k = A.shape
    names_t = tuple(col_names)

    keep, intercept, warns = _identifiability(A, names_t)
    idx = np.nonzero(keep)[0]
    p = idx.size
    if p == 0:
        raise ValueError("no identifiable regressor")
    if n <= p:
        raise ValueError(f"{n} observations for {p} identifiable parameters")
    Xw = A[:, idx] * sw[:, None]
    yw = yv * sw

    # ---- OLS through statsmodels
    ols = sm.OLS(yw, Xw).fit()
    theta = np.asarray(ols.params, dtype=float)
    vw = yw - Xw @ theta
    xtx_inv = np.linalg.inv(Xw.T @ Xw)
    rss = float(vw @ vw)
    s2 = rss / (n - p)
    cov_ols_k = s2 * xtx_inv

    # ---- coloured-residual correction
    if cov == "ols":
        cov_k, n_eff, max_lag = cov_ols_k, float(n), 0
    elif cov == "morelli_klein":
        max_lag = auto_max_lag(vw, groups=groups) if block is None else int(block)
        if not 0 <= max_lag <= n - 1:
            raise ValueError(f"block must be in [0, {n - 1}], got {max_lag}")
        cov_k, n_eff = _morelli_klein(Xw, vw, xtx_inv, max_lag, slices)
    else:  # hac
        max_lag = auto_max_lag(vw, HAC_LAG_MULTIPLE, groups) if hac_maxlags is None else int(hac_maxlags)
        if not 0 <= max_lag <= n - 1:
            raise ValueError(f"hac_maxlags must be in [0, {n - 1}], got {max_lag}")
        if slices is None:
            hac = sm.OLS(yw, Xw).fit(cov_type="HAC", cov_kwds={"maxlags": max_lag, "use_correction": True})
        else:
            codes = np.concatenate([np.full(s.stop - s.start, i) for i, s in enumerate(slices)])
            hac = sm.OLS(yw, Xw).fit(cov_type="hac-panel", cov_kwds={"groups": codes, "maxlags": max_lag})
        cov_k = np.asarray(hac.cov_params(), dtype=float)
        r = _pooled_autocovariance(vw, slices, max_lag) * _parzen(max_lag)
        n_eff = _effective_n(r, n, p)
    dof_eff = max(n_eff - p, 1.0) if cov != "ols" else float(n - p)

    # ---- expand to all k columns (NaN for non-identifiable)
    def full_vec(v):
        out = np.full(k, np.nan)
        out[idx] = v
        return out

    def full_mat(m):
        out = np.full((k, k), np.nan)
        out[np.ix_(idx, idx)] = m
        return out

    se_k = np.sqrt(np.clip(np.diag(cov_k), 0.0, None))
    se_ols_k = np.sqrt(np.diag(cov_ols_k))
    with np.errstate(divide="ignore", invalid="ignore"):
        t_k = theta / se_k
    p_k = 2.0 * scipy.stats.t.sf(np.abs(t_k), dof_eff)

    # ---- goodness of fit
    has_intercept = intercept is not None and keep[intercept]
    if has_intercept:
        ybar_w = float(np.sum(sw**2 * yv) / np.sum(sw**2))
        tss = float(np.sum((sw * (yv - ybar_w)) ** 2))
        df_model = p - 1
    else:
        tss = float(yw @ yw)
        df_model = p
    r2 = 1.0 - rss / tss if tss > 0 else np.nan
    r2_adj = 1.0 - (1.0 - r2) * (n - (1 if has_intercept else 0)) / (n - p) if tss > 0 else np.nan
    if df_model > 0 and rss > 0:
        f_stat = ((tss - rss) / df_model) / s2
        f_pvalue = float(scipy.stats.f.sf(f_stat, df_model, n - p))
    else:
        f_stat, f_pvalue = np.nan, np.nan
    slope = [i for i in range(p) if not (has_intercept and idx[i] == intercept)]
    if slope:
        th_s = theta[slope]
        c_s = cov_k[np.ix_(slope, slope)]
        try:
            f_corr = float(th_s @ np.linalg.solve(c_s, th_s)) / len(slope)
            f_corr_p = float(scipy.stats.f.sf(f_corr, len(slope), dof_eff))
        except np.linalg.LinAlgError:
            f_corr, f_corr_p = np.nan, np.nan
    else:
        f_corr, f_corr_p = np.nan, np.nan
    if sigma2_max is None:
        ybar_w = float(np.sum(sw**2 * yv) / np.sum(sw**2))
        sigma2_max = float(np.sum((sw * (yv - ybar_w)) ** 2) / n)
    pse = rss / n + float(sigma2_max) * p / n
    rms = float(np.sqrt(rss / n))

    # ---- collinearity diagnostics
    norms = np.linalg.norm(Xw, axis=0)
    cond = float(np.linalg.cond(Xw / norms))
    vif_k = np.full(p, np.nan)
    for i in range(p):
        if has_intercept and idx[i] == intercept:
            continue
        xi = Xw[:, i]
        if has_intercept and p > 1:
            # centre in the weighted metric: remove the projection on sqrt(w) (the intercept column)
            tss_i = float(np.sum((xi - sw * (xi @ sw) / (sw @ sw)) ** 2))
        else:
            tss_i = float(xi @ xi)
        vif_k[i] = tss_i * xtx_inv[i, i] if p > 1 else 1.0
    if cond > COND_WARN:
        warns.append(
            f"condition number {cond:.3g} of the scaled regressor matrix exceeds {COND_WARN:g}: "
            "regressors are nearly collinear, estimates are sensitive and correlated"
        )
    for i in range(p):
        if np.isfinite(vif_k[i]) and vif_k[i] > VIF_WARN:
            warns.append(
                f"collinearity: VIF({names_t[idx[i]]}) = {vif_k[i]:.3g} > {VIF_WARN:g}; "
                "its excitation is largely explained by the other regressors"
            )
    if cov != "ols":
        ratio = se_k / se_ols_k
        if np.nanmax(ratio) > 2.0:
            warns.append(
                f"coloured residuals: N_eff = {n_eff:.1f} of N = {n}; plain OLS sigma understates the "
                f"uncertainty by up to x{np.nanmax(ratio):.3g} (intervals use the corrected sigma)"
            )
        if n_eff < 5 * p:
            warns.append(
                f"few effective samples: N_eff = {n_eff:.1f} for {p} parameters; the corrected sigma is "
                "itself uncertain and the intervals are approximate"
            )

    fitted = A[:, idx] @ theta
    return LinearFit(
        channel=channel,
        names=names_t,
        estimate=_as_readonly(full_vec(theta)),
        std_error=_as_readonly(full_vec(se_k)),
        std_error_ols=_as_readonly(full_vec(se_ols_k)),
        cov=_as_readonly(full_mat(cov_k)),
        cov_ols=_as_readonly(full_mat(cov_ols_k)),
        t_values=_as_readonly(full_vec(t_k)),
        p_values=_as_readonly(full_vec(p_k)),
        r2=float(r2),
        r2_adj=float(r2_adj),
        f_stat=float(f_stat),
        f_pvalue=float(f_pvalue),
        f_stat_corrected=float(f_corr),
        f_pvalue_corrected=float(f_corr_p),
        rms_residual=rms,
        pse=float(pse),
        sigma2_max=float(sigma2_max),
        condition_number=cond,
        vif=_as_readonly(full_vec(vif_k)),
        n_obs=int(n),
        n_dropped=n_dropped,
        n_params=int(p),
        n_eff=float(n_eff),
        dof_eff=float(dof_eff),
        max_lag=int(max_lag),
        residuals=_as_readonly(yv - fitted),
        fitted=_as_readonly(fitted),
        method=cov,
        identifiable=_readonly_bool(keep),
        has_intercept=bool(has_intercept),
        warnings=tuple(warns),
    )
