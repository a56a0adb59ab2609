"""Vectorised per-channel detectors (pure numpy/pandas functions on 1-D arrays).

All functions take a channel's values on the uniform grid (``float64``, NaN where
there is no usable value yet) and return boolean masks or scale estimates of the
same length.  No Python loop runs per sample.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

#: The one-sided spike test (next to a gap or the record edge) uses this multiple
#: of the threshold: it cannot see whether a deviation returns.
ONE_SIDED_FACTOR = 1.5

#: Gaussian consistency factor of the MAD (sigma = MAD_TO_SIGMA * MAD).
MAD_TO_SIGMA = 1.482602218505602

#: A one-sided residual's scale is also at least LOCAL_SCALE_FACTOR times its robust
#: scale over LOCAL_WINDOW * h samples around the sample: where the signal's curvature
#: changes (a fin slewing at 25 noise sigmas per sample up to a gap) one side's
#: extrapolation misses at every neighbour too, and the margin widens with them (the
#: two-sided average cancels a change of curvature, and a local scale there would let a
#: burst of spikes hide itself); on noise alone the local estimate rarely exceeds the
#: long one by 1 / 0.6.
LOCAL_WINDOW = 4
LOCAL_SCALE_FACTOR = 0.6

#: The curvature allowance counts only beyond this many of its own noise standard deviations.
CURVATURE_NOISE_SD = 2.0

#: The two-sided spike test also needs each side's own residual beyond this fraction
#: of the margin (scaled to that residual's noise, sqrt((1 + v) / (1 + v/2)) larger),
#: in the same direction: a step agrees with one side, so it is never a spike; at 0.6
#: the agreeing side's noise passes it with probability ~1e-3 per sample next to a step.
GUARD_FRACTION = 0.6


def prediction_variance(h: int) -> float:
    """Variance of one side's prediction ``(1 + w) L1 - w L2`` in units of the noise
    variance: the median of ``h`` Gaussian samples has variance about ``pi / (2 h)``
    (an upper bound for small ``h``), ``w = c / h`` with ``c = (h + 1) / 2``."""
    h = max(1, int(h))
    w = 0.5 * (h + 1) / h
    return ((1.0 + w) ** 2 + w ** 2) * np.pi / (2.0 * h)


def gaussian_threshold(n: int, false_alarm: float) -> float:
    """Two-sided Gaussian threshold [standard deviations] at which ``n`` independent
    samples give one false detection with probability ``false_alarm``: the
    ``false_alarm / (2 n)`` upper tail (e.g. 5.2 for n = 6000, 1e-3; 5.7 for 1e5)."""
    from scipy.stats import norm

    return float(norm.isf(false_alarm / (2.0 * max(int(n), 1))))


def runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Maximal runs of True in a 1-D bool array: ``(starts, ends)``, ends exclusive."""
    m = np.asarray(mask, dtype=bool)
    if m.size == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty
    d = np.diff(np.concatenate(([0], m.view(np.int8), [0])))
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


def mark_runs(n: int, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Bool array of length ``n``, True inside the (non-overlapping) runs [start, end)."""
    d = np.zeros(n + 1, dtype=np.int64)
    np.add.at(d, starts, 1)
    np.add.at(d, ends, -1)
    return np.cumsum(d[:-1]) > 0


def quantum(x: np.ndarray) -> float:
    """Smallest non-zero step between consecutive finite samples (0 if none).

    For quantised telemetry this is the least significant bit; for continuous data it
    is tiny and harmless.  Used as a floor of the noise scale.
    """
    d = np.abs(np.diff(x))
    d = d[np.isfinite(d) & (d > 0)]
    return float(d.min()) if d.size else 0.0


def noise_scale(x: np.ndarray, window: int, floor: float) -> tuple[np.ndarray, float]:
    """Local robust noise standard deviation of ``x`` and its whole-record value.

    The noise is seen through the second difference ``e_k = x_k - (x_{k-1}+x_{k+1})/2``
    (variance 1.5 sigma^2 for white noise; a signal below a few Hz at >= 50 Hz barely
    contributes).  sigma = 1.4826 median|e| / sqrt(1.5), the median taken over a
    centred rolling window of ``window`` samples (spikes and steps, a few large
    ``e`` each, do not move it).  Where the window holds too few values the
    whole-record estimate is used.  Both are floored at ``floor``.
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.size
    e = np.full(n, np.nan)
    if n >= 3:
        e[1:-1] = np.abs(x[1:-1] - 0.5 * (x[:-2] + x[2:]))
    factor = MAD_TO_SIGMA / np.sqrt(1.5)
    finite = e[np.isfinite(e)]
    global_sigma = float(np.median(finite)) * factor if finite.size else float("nan")
    if not np.isfinite(global_sigma):
        global_sigma = floor
    global_sigma = max(global_sigma, floor)
    window = max(3, min(int(window), n))
    local = pd.Series(e).rolling(window, center=True, min_periods=max(3, window // 5)).median().to_numpy()
    local = local * factor
    local = np.where(np.isfinite(local), local, global_sigma)
    return np.maximum(local, floor), global_sigma


def spike_mask(x: np.ndarray, half_window: int, sigma: np.ndarray, threshold: float,
               scale_window: int | None = None) -> np.ndarray:
    """Isolated spikes: samples that the neighbourhoods on *both* sides reject.

    With h = ``half_window`` and window medians (NaN skipped)

        L1 = median x[k-h .. k-1],  L2 = median x[k-2h .. k-h-1],  L3 = median x[k-3h .. k-2h-1]
        R1 = median x[k+1 .. k+h],  R2, R3 likewise to the right,

    each side predicts x_k by linear extrapolation of its two nearest medians (window
    centres at distance c = (h+1)/2 and c + h), ``P_L = (1 + w) L1 - w L2`` with
    w = c/h (1.5 L1 - 0.5 L2 for large h), likewise ``P_R`` (exact on a ramp or a
    pull-up; the medians make it blind to other spikes).

    **Decision.**  The residual ``D = x_k - (P_L + P_R) / 2`` must exceed the margin
    ``threshold * s_k`` (+ a curvature allowance, below), and each side's own
    residual ``x_k - P_L``, ``x_k - P_R`` must exceed ``GUARD_FRACTION`` of it (scaled
    to that residual's larger noise) in the same direction.  ``s_k`` is the standard deviation of ``D`` on noise: the larger
    of its robust scale over a centred window of ``scale_window`` samples (1.4826
    median |D|: it includes coloured noise and what the predictions miss of the
    signal) and ``sqrt(1 + v/2) sigma_k`` (white noise of scale ``sigma_k``,
    which carries the floor tied to the channel's resolution; ``v`` =
    :func:`prediction_variance`).  ``threshold`` is in units of ``s_k``; the caller
    sets it from the record's length and a false-alarm probability
    (:func:`gaussian_threshold`).

    * A step (a level change that persists) agrees with one side, so its samples are
      never flagged however large the step: "a spike returns".  Within about 2h
      samples of a step the step itself widens the margin (see below), so a spike
      there may be missed.
    * Runs of up to about h/2 adjacent spikes are caught; a genuine pulse must last
      longer than about h/2 samples.
    * Curvature: on a parabola of curvature kappa both predictions miss by
      -kappa c (c + h) / 2.  The signed estimate of that miss,
      ``A = c (c+h) / (2h (2c+h)) (L2 + R2 - L1 - R1)`` (3/16 (...) for large h;
      one-sided ``c (c+h) / (2 h^2) (L1 - 2 L2 + L3)``), only ever *widens* the
      margin, on the side where the true value may lie beyond the predictions:
      up-margin + max(A, 0), down-margin + max(-A, 0).  It never narrows it, because
      next to a step or a ramp's corner c is unreliable.  ``A`` is an estimate from
      noisy medians: only its part beyond ``CURVATURE_NOISE_SD`` of its own standard
      deviation counts (on pure noise the allowance would otherwise raise the margin
      at random and the false-alarm rate would fall below its design value at the
      cost of missed spikes).
    * A window median needs at least 0.6 h values.  When one side cannot extrapolate
      (record edge, next to a gap) the test is one-sided: it needs the other side's
      three windows at least 80 % filled, uses ``ONE_SIDED_FACTOR`` times the
      threshold (on that side's residual, scaled like ``D`` but also at least
      ``LOCAL_SCALE_FACTOR`` times its robust scale over ``LOCAL_WINDOW * h``
      samples) and that side's own curvature allowance, and the few (>= 3) nearest values on the short side, if
      any, must disagree as well.  In a short island between gaps (no side can
      extrapolate) x must lie beyond both nearest medians (>= 3 values each, no
      extrapolation) by ``ONE_SIDED_FACTOR`` times the threshold.  Otherwise the
      sample is not tested (never flagged).
    * Dynamics much faster than h samples with a large overshoot (e.g. a 10 Hz
      actuator sampled at 100 Hz) look like a short spike burst and can be flagged.
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.size
    if n < 3:
        return np.zeros(n, dtype=bool)
    h = max(1, int(half_window))
    few = min(3, h)
    need = max(few, int(np.ceil(0.6 * h)))
    full = max(need, int(np.ceil(0.8 * h)))
    s = pd.Series(x)
    # roll[j] = median and cnt[j] = number of finite values of x[j-h+1 .. j]
    roll_few = s.rolling(h, min_periods=few).median()
    cnt = s.notna().astype(np.int64).rolling(h, min_periods=1).sum()
    roll = roll_few.where(cnt >= need)

    def med(shift: int, series=roll) -> np.ndarray:
        return series.shift(shift).to_numpy()

    def filled(shift: int) -> np.ndarray:
        return cnt.shift(shift).fillna(0).to_numpy() >= full

    n1_l, n1_r = med(1, roll_few), med(-h, roll_few)  # nearest windows, >= 3 values
    l1, l2, l3 = med(1), med(h + 1), med(2 * h + 1)
    r1, r2, r3 = med(-h), med(-2 * h), med(-3 * h)
    # window centres: nearest at distance c = (h+1)/2 from k, the next at c + h, ...
    c = 0.5 * (h + 1)
    w = c / h                                        # linear extrapolation weight
    k_two = c * (c + h) / (2.0 * h * (2.0 * c + h))  # -> 3/16 for large h
    k_one = c * (c + h) / (2.0 * h * h)              # -> 3/8 for large h
    with np.errstate(invalid="ignore"):
        p_l = (1.0 + w) * l1 - w * l2
        p_r = (1.0 + w) * r1 - w * r2
        corr_two = k_two * (l2 + r2 - l1 - r1)
        corr_l = k_one * (l1 - 2 * l2 + l3)
        corr_r = k_one * (r1 - 2 * r2 + r3)
    ok_l = np.isfinite(p_l)
    ok_r = np.isfinite(p_r)
    two = ok_l & ok_r
    trust_l = ok_l & np.isfinite(corr_l) & filled(1) & filled(h + 1) & filled(2 * h + 1)
    trust_r = ok_r & np.isfinite(corr_r) & filled(-h) & filled(-2 * h) & filled(-3 * h)
    only_l = ~ok_r & trust_l
    only_r = ~ok_l & trust_r
    corr = np.where(two, corr_two, np.where(only_l, corr_l, np.where(only_r, corr_r, 0.0)))
    corr = np.where(np.isfinite(corr), corr, 0.0)

    v = prediction_variance(h)
    sigma = np.broadcast_to(np.asarray(sigma, dtype=np.float64), x.shape)
    # the allowance is itself a noisy estimate: only the part beyond CURVATURE_NOISE_SD
    # of its own noise (sd from the medians' variance v_med = pi / (2h)) counts
    v_med = np.pi / (2.0 * h)
    sd_corr = np.where(two, k_two * np.sqrt(4.0 * v_med), k_one * np.sqrt(6.0 * v_med)) * sigma
    corr = np.sign(corr) * np.maximum(np.abs(corr) - CURVATURE_NOISE_SD * sd_corr, 0.0)
    with np.errstate(invalid="ignore"):
        d_c = np.where(two, x - 0.5 * (p_l + p_r), np.nan)
    scale = np.sqrt(1.0 + 0.5 * v) * sigma
    scale_one = np.sqrt(1.0 + v) * sigma
    if scale_window is not None:
        win = max(3, min(int(scale_window), n))
        near = max(3, min(LOCAL_WINDOW * h, n))

        def robust(r: np.ndarray, local: bool) -> np.ndarray:
            """Rolling robust scale 1.4826 median|r| over ``win`` samples; with ``local``
            at least LOCAL_SCALE_FACTOR times the same over ``near`` (NaN: too few)."""
            if np.isfinite(r).sum() < 3:
                return np.full(n, np.nan)
            a = pd.Series(np.abs(r))
            out = a.rolling(win, center=True, min_periods=max(3, win // 5)).median().to_numpy()
            if local:
                near_scale = a.rolling(near, center=True, min_periods=max(3, near // 2)).median().to_numpy()
                out = np.fmax(out, LOCAL_SCALE_FACTOR * near_scale)
            return MAD_TO_SIGMA * out

        scale = np.fmax(scale, robust(d_c, local=False))
        # one side's extrapolation misses fast dynamics (a change of curvature) that the
        # two-sided average cancels: each side's residual gets its own, local, scale
        with np.errstate(invalid="ignore"):
            scale_one = np.fmax(scale_one, np.where(only_l, robust(x - p_l, True), robust(x - p_r, True)))
    one_sided = ONE_SIDED_FACTOR * threshold * scale_one
    base = np.where(two, threshold * scale, one_sided)
    # The curvature estimate only ever widens the margin, on the side where the true
    # value may lie beyond the prediction (never narrows it: next to a step or a
    # ramp's corner the estimate is unreliable).
    margin_up = base + np.maximum(corr, 0.0)
    margin_dn = base + np.maximum(-corr, 0.0)
    with np.errstate(invalid="ignore"):
        # the guard is on one side's residual, whose noise is larger than D's
        wider = GUARD_FRACTION * np.sqrt((1.0 + v) / (1.0 + 0.5 * v))
        g_up, g_dn = wider * margin_up, wider * margin_dn
        two_up = (d_c > margin_up) & (x - p_l > g_up) & (x - p_r > g_up)
        two_dn = (-d_c > margin_dn) & (p_l - x > g_dn) & (p_r - x > g_dn)
        up_l, dn_l = x - p_l > margin_up, p_l - x > margin_dn
        up_r, dn_r = x - p_r > margin_up, p_r - x > margin_dn
        # one-sided: the other side's few nearest values, if any, must not agree either
        limit = threshold * scale
        gup_r = ~np.isfinite(n1_r) | (x - n1_r > limit)
        gdn_r = ~np.isfinite(n1_r) | (n1_r - x > limit)
        gup_l = ~np.isfinite(n1_l) | (x - n1_l > limit)
        gdn_l = ~np.isfinite(n1_l) | (n1_l - x > limit)
    # a short island between gaps: no side can extrapolate; both nearest medians must
    # disagree, in the same direction, by the one-sided margin
    island = ~two & ~only_l & ~only_r & np.isfinite(n1_l) & np.isfinite(n1_r)
    with np.errstate(invalid="ignore"):
        wide = ONE_SIDED_FACTOR * threshold * scale
        island_out = ((x - n1_l > wide) & (x - n1_r > wide)) | ((n1_l - x > wide) & (n1_r - x > wide))
    out = ((two & (two_up | two_dn))
           | (only_l & ((up_l & gup_r) | (dn_l & gdn_r)))
           | (only_r & ((up_r & gup_l) | (dn_r & gdn_l)))
           | (island & island_out))
    return out & np.isfinite(x)
