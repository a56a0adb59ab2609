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

Imports numpy, scipy, pandas and statsmodels only.
"""
from __future__ import annotations

import dataclasses

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
import pandas as pd
import scipy.signal
import scipy.stats
import statsmodels.api as sm

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
LAG_MULTIPLE = 4
"""Automatic Morelli-Klein lag window: L = LAG_MULTIPLE x (first zero crossing of R_vv)."""
HAC_LAG_MULTIPLE = 2
"""Automatic HAC (Bartlett) truncation: L = HAC_LAG_MULTIPLE x (first zero crossing of R_vv)."""
_COLLINEAR_TOL = 1e-9  # relative residual norm below which a column is "exactly" collinear
_METHODS = ("morelli_klein", "hac", "ols")


# --------------------------------------------------------------------------- helpers
def residual_autocovariance(v: np.ndarray, max_lag: int | None = None) -> np.ndarray:
    """Biased autocovariance ``R(k) = (1/N) sum_i v_i v_(i+k)``, k = 0..max_lag (FFT)."""
    v = np.asarray(v, dtype=float)
    n = v.size
    if max_lag is None:
        max_lag = n - 1
    nfft = 1 << (2 * n - 1).bit_length()
    f = np.fft.rfft(v, nfft)
    r = np.fft.irfft(f * np.conj(f), nfft)[: max_lag + 1] / n
    return r


def _group_slices(groups: Any) -> list[slice] | None:
    """Row ranges of the contiguous groups; None for a single group (or no groups)."""
    if groups is None:
        return None
    g = np.asarray(groups)
    change = np.flatnonzero(g[1:] != g[:-1]) + 1
    if change.size == 0:
        return None
    bounds = np.concatenate([[0], change, [g.size]])
    labels = g[bounds[:-1]].tolist()
    if len(set(labels)) < len(labels):
        raise ValueError("groups must be contiguous: sort the rows by group (e.g. flight) first")
    return [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]


def _pooled_autocovariance(v: np.ndarray, slices: list[slice] | None, max_lag: int | None = None) -> np.ndarray:
    """``residual_autocovariance`` pooled within groups: (1/N) sum over groups of the
    lagged products inside each group (lags longer than a group get nothing from it)."""
    if slices is None:
        return residual_autocovariance(v, max_lag)
    n = v.size
    max_lag = n - 1 if max_lag is None else max_lag
    r = np.zeros(max_lag + 1)
    for s in slices:
        vg = v[s]
        rg = residual_autocovariance(vg, min(max_lag, vg.size - 1)) * vg.size
        r[: rg.size] += rg
    return r / n


def auto_max_lag(v: np.ndarray, multiple: int | None = None, groups: Any = None) -> int:
    """Automatic lag-window half-width: ``multiple`` (default ``LAG_MULTIPLE``) x first
    zero crossing of R_vv (pooled within ``groups``, see the module doc), at most N - 1."""
    if multiple is None:
        multiple = LAG_MULTIPLE
    r = _pooled_autocovariance(np.asarray(v, dtype=float), _group_slices(groups))
    n = r.size
    nonpos = np.nonzero(r[1:] <= 0.0)[0]
    k0 = int(nonpos[0]) + 1 if nonpos.size else n - 1
    return int(min(multiple * k0, n - 1))


def _parzen(max_lag: int) -> np.ndarray:
    """Parzen lag window w_k, k = 0..max_lag (w = 0 from lag max_lag+1 on)."""
    z = np.arange(max_lag + 1) / (max_lag + 1.0)
    return np.where(z <= 0.5, 1.0 - 6.0 * z**2 + 6.0 * z**3, 2.0 * (1.0 - z) ** 3)


def _effective_n(r_windowed: np.ndarray, n: int, p: int) -> float:
    if r_windowed[0] <= 0.0:
        return float(n)
    s = 1.0 + 2.0 * float(np.sum(r_windowed[1:])) / r_windowed[0]
    n_eff = n / s if s > 0 else float(n)
    return float(np.clip(n_eff, p + 1.0, n))


def _morelli_klein(X: np.ndarray, v: np.ndarray, xtx_inv: np.ndarray, max_lag: int,
                   slices: list[slice] | None = None):
    """Morelli-Klein coloured-residual covariance with a Parzen lag window (within each
    group of ``slices`` when given).

    Returns (cov, n_eff) where cov already carries the N_eff/(N_eff - p) factor.
    """
    n, p = X.shape
    r = _pooled_autocovariance(v, slices, max_lag) * _parzen(max_lag)
    n_eff = _effective_n(r, n, p)
    if max_lag == 0:
        middle = r[0] * (X.T @ X)
    else:
        r_sym = np.concatenate([r[:0:-1], r])  # lags -L..L
        middle = np.zeros((p, p))
        for s in slices or [slice(0, n)]:
            Xg = X[s]
            tx = scipy.signal.fftconvolve(Xg, r_sym[:, None], mode="full", axes=0)[max_lag : max_lag + Xg.shape[0]]
            middle += Xg.T @ tx
        middle = 0.5 * (middle + middle.T)
    cov = xtx_inv @ middle @ xtx_inv
    cov = 0.5 * (cov + cov.T) * (n_eff / max(n_eff - p, 1.0))
    return cov, n_eff


def _as_readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a


def _readonly_bool(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=bool, copy=True)
    a.setflags(write=False)
    return a


# --------------------------------------------------------------------------- result
@dataclass(frozen=True, eq=False)
class LinearFit:
    """Result of :func:`fit_linear` (arrays are read-only; order follows ``names``).

    ``std_error``/``cov``/``t_values``/``p_values``/``conf_int`` use the
    coloured-residual correction named in ``method``; the ``*_ols`` fields are
    the plain least-squares values reported beside them.
    """

    channel: str
    names: tuple[str, ...]
    estimate: np.ndarray
    std_error: np.ndarray
    std_error_ols: np.ndarray
    cov: np.ndarray
    cov_ols: np.ndarray
    t_values: np.ndarray
    p_values: np.ndarray
    r2: float
    r2_adj: float
    f_stat: float
    f_pvalue: float
    f_stat_corrected: float
    f_pvalue_corrected: float
    rms_residual: float
    pse: float
    sigma2_max: float
    condition_number: float
    vif: np.ndarray
    n_obs: int
    n_dropped: int
    n_params: int
    n_eff: float
    dof_eff: float
    max_lag: int
    residuals: np.ndarray
    fitted: np.ndarray
    method: str
    identifiable: np.ndarray
    has_intercept: bool
    warnings: tuple[str, ...] = field(default=())

    # ---- statsmodels-flavoured aliases
    @property
    def params(self) -> pd.Series:
        return pd.Series(self.estimate, index=list(self.names), name=self.channel or None)

    @property
    def bse(self) -> pd.Series:
        return pd.Series(self.std_error, index=list(self.names))

    @property
    def bse_ols(self) -> pd.Series:
        return pd.Series(self.std_error_ols, index=list(self.names))

    @property
    def tvalues(self) -> pd.Series:
        return pd.Series(self.t_values, index=list(self.names))

    @property
    def pvalues(self) -> pd.Series:
        return pd.Series(self.p_values, index=list(self.names))

    @property
    def rsquared(self) -> float:
        return self.r2

    @property
    def rsquared_adj(self) -> float:
        return self.r2_adj

    @property
    def fvalue(self) -> float:
        return self.f_stat

    @property
    def nobs(self) -> int:
        return self.n_obs

    @property
    def resid(self) -> np.ndarray:
        return self.residuals

    @property
    def fittedvalues(self) -> np.ndarray:
        return self.fitted

    @property
    def dof_resid(self) -> int:
        """Plain residual degrees of freedom N - p."""
        return self.n_obs - self.n_params

    @property
    def t_values_ols(self) -> np.ndarray:
        return self.estimate / self.std_error_ols

    @property
    def sigma_ratio(self) -> np.ndarray:
        """Corrected over plain standard error, per coefficient."""
        return self.std_error / self.std_error_ols

    def __getitem__(self, name: str) -> float:
        """Estimate of one coefficient by name."""
        return float(self.estimate[self.names.index(name)])

    def combination(self, weights: dict[str, float], alpha: float = 0.05) -> tuple[float, float, float, float]:
        """A linear combination sum(w_i * theta_i) of coefficients (e.g. the combined pitch
        damping Cm_q + Cm_alpha_dot, which a short-period manoeuvre determines far better than
        either term): (estimate, corrected sigma from the full covariance, interval low, high)."""
        w = np.zeros(len(self.names))
        for name, v in weights.items():
            w[self.names.index(name)] = float(v)
        used = w != 0
        if not (np.all(np.isfinite(self.estimate[used])) and np.all(np.isfinite(self.cov[np.ix_(used, used)]))):
            nan = float("nan")  # a term the data cannot tell: so is any sum that holds it
            return nan, nan, nan, nan
        est = float(w @ np.nan_to_num(self.estimate))
        se = float(np.sqrt(max(float(w @ np.nan_to_num(self.cov) @ w), 0.0)))
        q = scipy.stats.t.ppf(1.0 - alpha / 2.0, self.dof_eff)
        return est, se, est - q * se, est + q * se

    # ---- intervals and prediction
    def conf_int(self, alpha: float = 0.05) -> np.ndarray:
        """(k, 2) two-sided 1-alpha intervals from the corrected sigma, t(dof_eff) quantiles."""
        q = scipy.stats.t.ppf(1.0 - alpha / 2.0, self.dof_eff)
        return np.column_stack([self.estimate - q * self.std_error, self.estimate + q * self.std_error])

    def conf_int_ols(self, alpha: float = 0.05) -> np.ndarray:
        """(k, 2) plain least-squares intervals, t(N - p) quantiles."""
        q = scipy.stats.t.ppf(1.0 - alpha / 2.0, max(self.dof_resid, 1))
        return np.column_stack(
            [self.estimate - q * self.std_error_ols, self.estimate + q * self.std_error_ols]
        )

    def predict(self, X: Any) -> np.ndarray:
        """Model output for regressors X (DataFrame with these column names, or (n, k) array).

        Non-identifiable coefficients count as zero.
        """
        if isinstance(X, pd.DataFrame):
            missing = [n for n in self.names if n not in X.columns]
            if missing:
                raise KeyError(f"predict: regressor columns missing: {missing}")
            A = X.loc[:, list(self.names)].to_numpy(dtype=float)
        else:
            A = np.asarray(X, dtype=float)
            if A.ndim == 1:
                A = A[:, None]
            if A.shape[1] != len(self.names):
                raise ValueError(f"predict: expected {len(self.names)} columns, got {A.shape[1]}")
        return A @ np.nan_to_num(self.estimate, nan=0.0)

    def as_records(self, alpha: float = 0.05) -> list[dict]:
        """One dict per coefficient, ready for a coefficients.parquet table."""
        ci = self.conf_int(alpha)
        return [
            {
                "channel": self.channel,
                "coefficient": name,
                "estimate": float(self.estimate[i]),
                "std_error": float(self.std_error[i]),
                "std_error_ols": float(self.std_error_ols[i]),
                "ci_low": float(ci[i, 0]),
                "ci_high": float(ci[i, 1]),
                "t_value": float(self.t_values[i]),
                "p_value": float(self.p_values[i]),
            }
            for i, name in enumerate(self.names)
        ]

    # ---- report
    def summary(self, alpha: float = 0.05) -> str:
        """Text report in the style of statsmodels' RegressionResults.summary()."""
        width = 96
        ci = self.conf_int(alpha)
        lo, hi = f"[{alpha / 2:.3g}", f"{1 - alpha / 2:.3g}]"

        def g(x: float, fmt: str = ".4g") -> str:
            return "nan" if not np.isfinite(x) else format(x, fmt)

        method_txt = {
            "morelli_klein": f"Morelli-Klein, Parzen L={self.max_lag}",
            "hac": f"HAC Newey-West, L={self.max_lag}",
            "ols": "OLS (white residuals)",
        }[self.method]
        left = [
            ("Channel:", self.channel or "-"),
            ("Cov. type:", method_txt),
            ("No. observations:", str(self.n_obs)),
            ("Dropped (NaN):", str(self.n_dropped)),
            ("Parameters:", f"{self.n_params} of {len(self.names)}"),
            ("N_eff / dof_eff:", f"{g(self.n_eff, '.1f')} / {g(self.dof_eff, '.1f')}"),
            ("Cond. no. (scaled):", g(self.condition_number, '.3g')),
        ]
        right = [
            ("R-squared:", g(self.r2, ".6f")),
            ("Adj. R-squared:", g(self.r2_adj, ".6f")),
            ("F-statistic (OLS):", g(self.f_stat, ".6g")),
            ("Prob (F, OLS):", g(self.f_pvalue, ".3g")),
            ("F (corrected):", f"{g(self.f_stat_corrected, '.4g')} (p={g(self.f_pvalue_corrected, '.3g')})"),
            ("RMS residual:", g(self.rms_residual, ".4g")),
            ("PSE:", g(self.pse, ".4g")),
        ]
        lines = [f"LinearFit results: {self.channel or 'y'}".center(width), "=" * width]
        for (a, b), (c, d) in zip(left, right):
            lines.append(f"{a:<20}{b:>28}  {c:<20}{d:>26}")
        lines.append("=" * width)
        nw = max(12, max(len(n) for n in self.names) + 1)
        head = (
            f"{'':<{nw}}{'coef':>11}{'std err':>11}{'std OLS':>11}{'ratio':>7}"
            f"{'t':>9}{'P>|t|':>8}{lo:>12}{hi:>12}{'VIF':>7}"
        )
        lines.append(head)
        lines.append("-" * max(width, len(head)))
        for i, name in enumerate(self.names):
            if not self.identifiable[i]:
                lines.append(f"{name:<{nw}}{'not identifiable (no excitation)':>60}")
                continue
            ratio = self.std_error[i] / self.std_error_ols[i] if self.std_error_ols[i] > 0 else np.nan
            lines.append(
                f"{name:<{nw}}{g(self.estimate[i], '11.4g'):>11}{g(self.std_error[i], '.3g'):>11}"
                f"{g(self.std_error_ols[i], '.3g'):>11}{g(ratio, '.2f'):>7}{g(self.t_values[i], '.3g'):>9}"
                f"{g(self.p_values[i], '.3f'):>8}{g(ci[i, 0], '.4g'):>12}{g(ci[i, 1], '.4g'):>12}"
                f"{g(self.vif[i], '.3g'):>7}"
            )
        lines.append("=" * max(width, len(head)))
        lines.append("Notes:")
        lines.append(
            "std err, t, P and the interval use the corrected covariance with Student-t(dof_eff);"
        )
        lines.append("std OLS assumes white residuals; ratio = std err / std OLS.")
        if self.warnings:
            lines.append("Warnings:")
            for i, w in enumerate(self.warnings, start=1):
                lines.append(f"[{i}] {w}")
        return "\n".join(lines)

    def __str__(self) -> str:  # pragma: no cover - convenience
        return self.summary()


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


def with_corrected_estimate(fit: LinearFit, estimate: np.ndarray, note: str,
                            std_error: np.ndarray | None = None) -> LinearFit:
    """The same fit with another estimate vector (e.g. corrected for errors in the
    regressors); t, p and the intervals follow it; `std_error` (optional) replaces the
    corrected sigma (the covariance is rescaled to it, correlations kept); the plain OLS
    sigma and the residual statistics stay those of the fit; `note` is added to its warnings."""
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
                               warnings=tuple(fit.warnings) + (note,))


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
