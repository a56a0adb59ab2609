"""Filtering of measured signals: the zero-phase low-pass of the vanes and the smoothing
derivatives of the model language (alpha-dot, beta-dot)."""
from __future__ import annotations

import functools

import numpy as np
import pandas as pd
import scipy.signal

#: Half-length of the Savitzky-Golay window used to differentiate alpha and beta [s].
DERIVATIVE_HALF_WINDOW_S = 0.25


def zero_phase_low_pass(x: np.ndarray, fs_hz: float, cutoff_hz: float | None) -> np.ndarray:
    """2nd-order Butterworth low-pass run forward and backward (no lag: the filtered angles
    stay aligned with the smoothed rates and accelerations); `x` unchanged when cutoff_hz
    is None, at or above Nyquist, or the record is too short to filter."""
    if cutoff_hz is None or len(x) < 16 or cutoff_hz >= 0.5 * fs_hz:
        return x
    sos = scipy.signal.butter(2, cutoff_hz, fs=fs_hz, output="sos")
    return scipy.signal.sosfiltfilt(sos, x, padlen=min(len(x) - 1, 3 * int(fs_hz / cutoff_hz)))


@functools.lru_cache(maxsize=64)
def _savgol_operators(win: int, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The quadratic Savitzky-Golay first derivative of an odd window `win` at step dt [s] as
    linear operators: the interior kernel, and the two edge maps of scipy's mode="interp" (a
    quadratic fitted to the first / last `win` samples, its slope read at the first / last
    win // 2).  Built once per window (SIMEX differentiates ~160 frames of the same grid)."""
    kernel = scipy.signal.savgol_coeffs(win, 2, deriv=1, delta=dt)
    half = win // 2
    x = np.arange(win, dtype=float) - half  # centred: a well-conditioned fit for long windows too
    fit = np.linalg.pinv(np.vander(x, 3))  # (3, win): the quadratic's coefficients a, b, c
    slope = lambda i: (np.column_stack([2.0 * i, np.ones_like(i), np.zeros_like(i)]) @ fit) / dt  # noqa: E731
    ops = kernel, slope(x[:half]), slope(x[win - half:])
    for op in ops:
        op.flags.writeable = False  # shared by every caller through the cache
    return ops


def _savgol_slope(y: np.ndarray, win: int, dt: float) -> np.ndarray:
    """scipy.signal.savgol_filter(y, win, 2, deriv=1, delta=dt, mode="interp") for len(y) >= win,
    with its operators cached (the same numbers to rounding; scipy refits the edges each call)."""
    kernel, left, right = _savgol_operators(win, float(dt))
    out = np.convolve(y, kernel, mode="same")
    half = win // 2
    out[:half] = left @ y[:win]
    out[-half:] = right @ y[-win:]
    return out


def smooth_derivative(t_s: np.ndarray, y: np.ndarray, groups: np.ndarray | None = None,
                      half_window_s: float | None = DERIVATIVE_HALF_WINDOW_S) -> np.ndarray:
    """dy/dt by a Savitzky-Golay (quadratic) derivative, computed per contiguous group.

    Inside a group the samples are put on a uniform grid (median step; linear
    interpolation over missing rows), differentiated, and read back at the
    original times.  A derivative amplifies noise by ~2 pi f: the window
    (2 x ``half_window_s``) is a low-pass at roughly 1/(2 half_window_s) Hz.
    ``half_window_s=None``: the central difference (for signals already band-limited).
    """
    t_s = np.asarray(t_s, float)
    y = np.asarray(y, float)
    out = np.full_like(y, np.nan)  # a segment too short to differentiate stays NaN (its rows drop out of a fit)
    if groups is None:
        groups = np.zeros(len(t_s), dtype=int)
    for g in pd.unique(groups):
        idx = np.nonzero(groups == g)[0]
        if idx.size < 5:
            continue
        idx = idx[np.argsort(t_s[idx], kind="stable")]
        t, v = t_s[idx], y[idx]
        dt = float(np.median(np.diff(t))) if idx.size > 1 else 1.0
        if not dt > 0:
            continue
        grid = np.arange(t[0], t[-1] + 0.5 * dt, dt)
        vg = np.interp(grid, t, v)
        if half_window_s is None:
            out[idx] = np.interp(t, grid, np.gradient(vg, dt))
            continue
        half = max(2, int(round(half_window_s / dt)))
        win = min(2 * half + 1, grid.size - (1 - grid.size % 2))
        if win < 5:
            out[idx] = np.gradient(v, t)
            continue
        d = _savgol_slope(vg, win, dt)
        out[idx] = np.interp(t, grid, d)
    return out
