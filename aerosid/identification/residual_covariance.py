"""The coloured-residual covariance of a linear fit (method.md §12): residual
autocovariance (pooled within records), the automatic lag window and the
Morelli-Klein covariance with a Parzen window.  Why and how: the module doc of
:mod:`aerosid.identification.regression`, whose :func:`fit_linear` uses these.

Imports numpy and scipy only.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import scipy.signal

LAG_MULTIPLE = 4
"""Automatic Morelli-Klein lag window: L = LAG_MULTIPLE x (first zero crossing of R_vv)."""
HAC_LAG_MULTIPLE = 2
"""Automatic HAC (Bartlett) truncation: L = HAC_LAG_MULTIPLE x (first zero crossing of R_vv)."""


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


def morelli_klein_middle(X: np.ndarray, v: np.ndarray, max_lag: int,
                         slices: list[slice] | None = None) -> tuple[np.ndarray, float]:
    """The middle matrix sum_i sum_j x_i R_vv(i - j) x_j' of the Morelli-Klein sandwich (Parzen
    lag window, within each group of ``slices``) and N_eff.  X (N, p): the regressors of a
    linear fit, or an output-error fit's output sensitivities; v (N,): its residuals."""
    n, p = X.shape
    r = _pooled_autocovariance(v, slices, max_lag) * _parzen(max_lag)
    n_eff = _effective_n(r, n, p)
    if max_lag == 0:
        return r[0] * (X.T @ X), n_eff
    r_sym = np.concatenate([r[:0:-1], r])  # lags -L..L
    middle = np.zeros((p, p))
    for s in slices or [slice(0, n)]:
        Xg = X[s]
        tx = scipy.signal.fftconvolve(Xg, r_sym[:, None], mode="full", axes=0)[max_lag : max_lag + Xg.shape[0]]
        middle += Xg.T @ tx
    return 0.5 * (middle + middle.T), n_eff


def _morelli_klein(X: np.ndarray, v: np.ndarray, xtx_inv: np.ndarray, max_lag: int,
                   slices: list[slice] | None = None):
    """Morelli-Klein coloured-residual covariance with a Parzen lag window (within each
    group of ``slices`` when given).

    Returns (cov, n_eff) where cov already carries the N_eff/(N_eff - p) factor.
    """
    p = X.shape[1]
    middle, n_eff = morelli_klein_middle(X, v, max_lag, slices)
    cov = xtx_inv @ middle @ xtx_inv
    cov = 0.5 * (cov + cov.T) * (n_eff / max(n_eff - p, 1.0))
    return cov, n_eff
