"""The result of a linear fit, :class:`LinearFit` (made by
:func:`aerosid.identification.regression.fit_linear`; the meaning of each field: that
module's doc).  Imports numpy, scipy and pandas only.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
import scipy.stats


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
    #: (X^T X of the fit's columns, the same extrapolated to no regressor noise) from the
    #: errors-in-variables correction's draws (aerosid.identification.eiv.SimexResult); None
    #: without one.  Their ratio along a direction is how much of the flight's apparent
    #: information there is signal (eiv.information_reliability).
    information_eiv: tuple | None = None

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
            "instrumental": "2SLS, Morelli-Klein sandwich",  # aerosid.identification.instrumental
        }.get(self.method, self.method)
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
