"""Predicted standard errors of a manoeuvre not yet flown (issue 20, item 2).

The pipeline reports, for a coefficient of a channel model ``y = X theta + v``, the
Morelli-Klein coloured-residual covariance (``aerosid.identification.regression``)::

    Cov = (X'X)^-1 [X' T X] (X'X)^-1 * N_eff / (N_eff - p)

with ``T`` the Toeplitz matrix of the residual autocovariance weighted by a Parzen lag
window of half-width L, and ``N_eff = N / (1 + 2 sum_k w_k rho_k)``.  A manoeuvre
changes ``X`` (the regressors it excites) but, to first order, not the residual: on
these flights the residual is the estimation error of the flight-derived coefficient
(the gyro noise through the smoother, docs/modelling-loop.md section 5), a property of
the sensors, the smoother and the flight condition.  The prediction therefore takes the
*run's* windowed residual autocovariance (:class:`ResidualModel`) and the *candidate's*
regressors, and evaluates the very same formula; the detectable size is the
diagnosis's: ``t(p = 0.001 two-sided, dof_eff) * sigma``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.signal
import scipy.stats

from aerosid.identification.residual_covariance import _group_slices, _parzen, _pooled_autocovariance
from aerosid.identification.regression import auto_max_lag

#: the diagnosis's significance level (aerosid.diagnosis.core.P_MAX)
P_MAX = 0.001
#: the design aims at detection with this probability (not just at the 50 % of t = t_crit)
POWER = 0.9


@dataclass(frozen=True)
class ResidualModel:
    """The windowed residual autocovariance of a channel fit: ``r_windowed[k]`` for
    k = 0..max_lag (the Parzen weights applied), from ``n`` samples."""

    r_windowed: np.ndarray
    max_lag: int
    n: int
    fs_hz: float

    @classmethod
    def from_residual(cls, v: np.ndarray, fs_hz: float, groups=None, max_lag: int | None = None) -> "ResidualModel":
        v = np.asarray(v, dtype=float)
        if max_lag is None:
            max_lag = auto_max_lag(v, groups=groups)
        r = _pooled_autocovariance(v, _group_slices(groups), max_lag) * _parzen(max_lag)
        return cls(np.asarray(r, float), int(max_lag), int(v.size), float(fs_hz))

    @property
    def variance(self) -> float:
        return float(self.r_windowed[0])

    @property
    def inflation(self) -> float:
        """N / N_eff = 1 + 2 sum_k w_k rho_k."""
        return float(1.0 + 2.0 * np.sum(self.r_windowed[1:]) / self.r_windowed[0])

    def n_eff(self, n: int, p: int) -> float:
        s = self.inflation
        return float(np.clip(n / s if s > 0 else n, p + 1.0, n))

    def scaled(self, factor: float) -> "ResidualModel":
        """The same correlation with the residual std multiplied by `factor`."""
        return ResidualModel(self.r_windowed * factor**2, self.max_lag, self.n, self.fs_hz)


@dataclass(frozen=True)
class Prediction:
    """Predicted covariance of a fit with regressors ``names`` under a residual model."""

    names: tuple[str, ...]
    cov: np.ndarray
    n: int
    n_eff: float
    dof_eff: float

    def sigma(self, name: str) -> float:
        i = self.names.index(name)
        return float(np.sqrt(self.cov[i, i]))

    def t_crit(self) -> float:
        return float(scipy.stats.t.isf(P_MAX / 2.0, self.dof_eff))

    def detectable_size(self, name: str) -> float:
        """The diagnosis's detectable size: t(p = 0.001, dof_eff) x sigma."""
        return self.t_crit() * self.sigma(name)

    def reliable_size(self, name: str, power: float = POWER) -> float:
        """The size found significant with probability `power` (t_crit + z_power) x sigma."""
        return (self.t_crit() + float(scipy.stats.norm.ppf(power))) * self.sigma(name)

    def correlation(self, a: str, b: str) -> float:
        i, j = self.names.index(a), self.names.index(b)
        return float(self.cov[i, j] / np.sqrt(self.cov[i, i] * self.cov[j, j]))


def predict_covariance(X: np.ndarray, names, residual: ResidualModel) -> Prediction:
    """The Morelli-Klein covariance the pipeline would report for regressors X (N, p)
    if the residual had the autocovariance of `residual` (module doc)."""
    X = np.asarray(X, dtype=float)
    n, p = X.shape
    if not np.all(np.isfinite(X)):
        raise ValueError("the candidate's regressors are not finite on every sample")
    scale = np.sqrt(np.sum(X * X, axis=0))
    scale[scale == 0] = 1.0
    Xs = X / scale
    xtx_inv = np.linalg.pinv(Xs.T @ Xs)
    L = min(residual.max_lag, n - 1)
    r = residual.r_windowed[: L + 1]
    r_sym = np.concatenate([r[:0:-1], r])
    tx = scipy.signal.fftconvolve(Xs, r_sym[:, None], mode="full", axes=0)[L: L + n]
    middle = Xs.T @ tx
    middle = 0.5 * (middle + middle.T)
    n_eff = residual.n_eff(n, p)
    cov = xtx_inv @ middle @ xtx_inv * (n_eff / max(n_eff - p, 1.0))
    cov = 0.5 * (cov + cov.T) / np.outer(scale, scale)
    return Prediction(tuple(names), cov, n, n_eff, max(n_eff - p, 1.0))
