"""One band for both sides of the regression: band-limited flight signals.

Why
---
Equation-error regression fits ``C(t) = X(t) theta``.  If the dependent variable
and the regressors reach the fit through *different* filters, the slopes are
biased by the ratio of the two frequency responses over the manoeuvre's band.
That is what happened when the flight-derived moment coefficients came from the
smoother's angular-acceleration chains: their bandwidth is set by the chains'
process noise, which the gyro spectrum cannot tell (it is noise-dominated where
it would matter), so a per-vehicle factor (``q_chain_scale``) had to be
calibrated on the vehicle's own simulated truth -- and on a vehicle nobody
calibrated, the smoothed q-dot had a gain of 0.88-0.95 and C_m_delta, C_m_q came
out 10-20 % low (docs/estimation.md has the measurements).

What this module does instead (documented choice, measured in bench/):

* the angular accelerations are the *exact* derivative (central difference) of
  the measured, preprocessed gyro signals, turned into aerodynamic angular
  accelerations through the Euler equations (method.md §5, inverted);
* the CG specific forces are the measured accelerations moved from the
  accelerometer to the CG with those rates and accelerations (method.md §5's
  lever-arm terms, inverted);
* every signal the regression sees -- these, the rates, the control surfaces and
  the air-data vanes -- goes through the **same** zero-phase low-pass (the rates and
  accelerations are filtered before the derivative and the nonlinear terms), so the
  band is shared by both sides of the equation.  A common linear filter leaves a
  linear model's coefficients unchanged and only removes the noise above the band;
* the band edge comes from the flight itself: the frequency below which 99 % of
  the gyros' signal power lies (signal: the periodogram bins significantly above the
  noise floor, the same test as the process-noise spectrum of method.md §3).  No per-vehicle
  constant is involved; a vehicle file may still override it
  (``[estimation] band_hz``).

The filter runs over contiguous runs of finite samples only: a long gap is not
bridged (a filter across a gap would smear the join over 1/band seconds); runs
shorter than :data:`MIN_RUN_CYCLES` period of the band edge (and 16 samples) are left out.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
import scipy.signal

from aerosid.estimation.findings import true_runs
from aerosid.vehicles.rigid_body import inertia_constants

#: Significance of a signal bin in noise-floor multiples (method.md §3's test; a noise
#: bin exceeds it with probability exp(-15) = 3e-7).
BAND_KAPPA = 15.0
#: A run of finite samples shorter than this many periods of the band edge is left out
#: (the zero-phase filter's start and end transients would be most of it).
MIN_RUN_CYCLES = 0.5
#: Samples at both ends of a run left out of the regression, in band periods (the filter's
#: transients there made the smoothed-vs-measured check fire at every segment edge), and
#: at most EDGE_MAX_S seconds.
EDGE_CYCLES = 0.5
EDGE_MAX_S = 0.5
#: The band edge is kept within [BAND_MIN_HZ, 0.4 x the sample rate].
BAND_MIN_HZ = 0.2
#: Share of the gyros' signal power (above the noise floor) inside the band.
BAND_POWER_FRACTION = 0.99


@dataclass(frozen=True)
class BandLimitedSignals:
    """Per-sample signals on one segment's grid, all through the same low-pass.

    rates_rad_s, ang_accel_rad_s2 (aerodynamic L1, M1, N1: moment / inertia as the
    smoother's states), accel_cg_m_s2 (X1, Y1, Z1): (N, 3), NaN outside the runs used;
    band_hz: the low-pass edge [Hz]; used: (N,) bool, samples inside a run used;
    band_source: "flight" (from the gyro spectrum) or "vehicle file".
    """

    rates_rad_s: np.ndarray
    ang_accel_rad_s2: np.ndarray
    accel_cg_m_s2: np.ndarray
    band_hz: float
    used: np.ndarray
    band_source: str
    accel_noise_m_s2: tuple = (np.nan, np.nan, np.nan)  # white-noise 1-sigma of ax, ay, az [m/s^2]
    rate_noise_rad_s: tuple = (np.nan, np.nan, np.nan)  # white-noise 1-sigma of p, q, r [rad/s]
    filter_runs: tuple = ()  # the (start, stop) runs the low-pass ran over (used is inside them)

    def low_pass(self, x: np.ndarray, fs_hz: float) -> np.ndarray:
        """Another signal of the same grid through the same low-pass, on the same runs."""
        return low_pass_runs(x, fs_hz, self.band_hz, [slice(a, b) for a, b in self.filter_runs])

    def summary(self) -> str:
        return (f"band-limited flight signals: low-pass {self.band_hz:.2f} Hz ({self.band_source}), "
                f"{int(self.used.sum())} of {self.used.size} samples in runs long enough to filter")


def signal_band_edge_hz(x: np.ndarray, dt_s: float, kappa: float = BAND_KAPPA,
                        power_fraction: float = BAND_POWER_FRACTION) -> float:
    """Upper edge of the signal band [Hz] of the columns of x (N, k), gap-free.

    Per column: the Hann-windowed periodogram of the detrended signal; bins above kappa x
    the noise floor (median power above half of Nyquist / ln 2, as method.md §3) are
    signal; the edge is the frequency below which ``power_fraction`` of the signal bins'
    excess power lies.  The largest edge over the columns, clipped to
    [BAND_MIN_HZ, 0.4 / dt_s].  (The highest significant bin, tried first, sits where a
    sharp input's harmonics still clear the floor -- 3.6 Hz on c172x, whose short period
    is near 1 Hz: the wider band let the vanes' noise into alpha-dot and biased
    C_m_alpha by -14 %.)"""
    x = np.atleast_2d(np.asarray(x, float).T).T
    nyq = 0.5 / dt_s
    edges = []
    for j in range(x.shape[1]):
        col = x[:, j]
        if col.size < 32 or not np.all(np.isfinite(col)):
            continue
        n = col.size
        t = np.arange(n) * dt_s
        yd = col - np.polyval(np.polyfit(t, col, 1), t)
        P = np.abs(np.fft.rfft(np.hanning(n) * yd)) ** 2
        f = np.fft.rfftfreq(n, dt_s)
        floor = float(np.median(P[f > 0.5 * nyq]) / np.log(2.0))
        sig = (f > 0) & (P > kappa * floor)
        if not sig.any():
            continue
        excess = np.where(sig, P - floor, 0.0)
        cum = np.cumsum(excess) / excess.sum()
        edges.append(float(f[min(np.searchsorted(cum, power_fraction), f.size - 1)]))
    edge = max(edges) if edges else BAND_MIN_HZ
    return float(np.clip(edge, BAND_MIN_HZ, 0.8 * nyq))


#: A sample whose residual against the smoothed estimate exceeds this many robust sigma is
#: a spike (Gaussian noise passes it with probability 7e-6 per sample: 0.03 per channel in
#: 4000 samples).
SPIKE_SIGMA = 4.5
#: Only runs of at most this many samples are spikes; longer ones are the smoother's lag
#: or a fault (the findings' business), not bridged.
SPIKE_MAX_RUN = 3


def bridge_spikes(x: np.ndarray, residual: np.ndarray) -> np.ndarray:
    """x (N, k) with its spikes replaced by linear interpolation: samples whose residual
    (measurement minus an independent estimate of it, e.g. the smoother's) exceeds
    SPIKE_SIGMA x 1.4826 MAD of that residual, in runs of at most SPIKE_MAX_RUN samples."""
    x = np.array(x, dtype=float, copy=True)
    res = np.atleast_2d(np.asarray(residual, float).T).T
    x2 = np.atleast_2d(x.T).T
    idx = np.arange(x2.shape[0])
    for j in range(x2.shape[1]):
        r = res[:, j]
        ok = np.isfinite(r)
        if ok.sum() < 16:
            continue
        med = np.median(r[ok])
        scale = 1.4826 * np.median(np.abs(r[ok] - med))
        if not scale > 0:
            continue
        with np.errstate(invalid="ignore"):
            hit = ok & (np.abs(r - med) > SPIKE_SIGMA * scale)
        for a, b in true_runs(hit):
            if b - a > SPIKE_MAX_RUN:
                hit[a:b] = False
        good = np.isfinite(x2[:, j]) & ~hit
        if hit.any() and good.sum() >= 2:
            x2[hit, j] = np.interp(idx[hit], idx[good], x2[good, j])
    return x2.reshape(x.shape)


def _band_impulse_response(fs_hz: float, band_hz: float) -> np.ndarray:
    """The impulse response of :func:`low_pass_runs` (long enough for its tails to vanish)."""
    n = int(40 * fs_hz / min(band_hz, 0.5 * fs_hz)) | 1
    x = np.zeros(n)
    x[n // 2] = 1.0
    return low_pass_runs(x, fs_hz, band_hz, [slice(0, n)])


def band_noise_gain(fs_hz: float, band_hz: float) -> float:
    """Standard deviation of unit white noise after :func:`low_pass_runs` (the square root
    of the sum of the squared impulse response of the forward-backward filter)."""
    if band_hz >= 0.5 * fs_hz:
        return 1.0
    h = _band_impulse_response(fs_hz, band_hz)
    return float(np.sqrt(np.sum(h * h)))


def white_noise_sigma(x: np.ndarray, runs: list[slice], order: int = 1) -> float:
    """1-sigma of the white noise on a smooth signal [x units]: 1.4826 MAD of the differences of
    the given order over the runs, over the noise's gain through them (sqrt(2) for first, sqrt(6)
    for second differences).  First differences assume the signal's own change between two
    samples is negligible next to the noise (the sensors at flight-test sample rates); second
    differences also cancel a steady slope (a control surface's own slow motion).  NaN with
    fewer than 8 differences."""
    d = np.concatenate([np.diff(np.asarray(x, float)[r], order) for r in runs] or [np.array([np.nan])])
    d = d[np.isfinite(d)]
    if d.size < 8:
        return float("nan")
    gain = math.sqrt(math.comb(2 * order, order))
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / gain)


def finite_runs(ok: np.ndarray) -> list[slice]:
    """Contiguous runs of True in ok, as slices."""
    return [slice(a, b) for a, b in true_runs(ok)]


def low_pass_runs(x: np.ndarray, fs_hz: float, band_hz: float, runs: list[slice]) -> np.ndarray:
    """x (N,) or (N, k) through a 2nd-order Butterworth run forward and backward (zero phase,
    |H|^2 = 1/(1 + (f/band)^4) overall), separately on every run; NaN outside the runs."""
    x = np.asarray(x, float)
    out = np.full_like(x, np.nan)
    if band_hz >= 0.5 * fs_hz:
        for r in runs:
            out[r] = x[r]
        return out
    sos = scipy.signal.butter(2, band_hz, fs=fs_hz, output="sos")
    for r in runs:
        n = r.stop - r.start
        out[r] = scipy.signal.sosfiltfilt(sos, x[r], axis=0, padlen=min(n - 1, 3 * int(fs_hz / band_hz)))
    return out


def aero_angular_acceleration(rates_rad_s: np.ndarray, rate_dot_rad_s2: np.ndarray,
                              inertia_kg_m2) -> np.ndarray:
    """(L1, M1, N1) [rad/s^2] (N, 3): the Euler equations of method.md §5 solved for the
    aerodynamic angular accelerations, given the body rates and their derivatives."""
    c = inertia_constants(*[float(v) for v in inertia_kg_m2])
    p, q, r = np.asarray(rates_rad_s, float).T
    coupling = np.column_stack([(c.c1 * r + c.c2 * p) * q, c.c5 * p * r - c.c6 * (p * p - r * r),
                                (c.c8 * p - c.c2 * r) * q])
    B = np.array([[c.c3 * c.Ixx, 0.0, c.c4 * c.Izz], [0.0, 1.0, 0.0], [c.c4 * c.Ixx, 0.0, c.c9 * c.Izz]])
    return np.linalg.solve(B, (np.asarray(rate_dot_rad_s2, float) - coupling).T).T


def accel_at_cg(accel_sensor_m_s2: np.ndarray, rates_rad_s: np.ndarray, rate_dot_rad_s2: np.ndarray,
                offset_m) -> np.ndarray:
    """Specific force at the CG [m/s^2] (N, 3) from the accelerometer's at offset_m (body axes,
    from the CG): a_cg = a_sensor - w_dot x r - w x (w x r)."""
    r = np.asarray(offset_m, float)
    w = np.asarray(rates_rad_s, float)
    return (np.asarray(accel_sensor_m_s2, float) - np.cross(np.asarray(rate_dot_rad_s2, float), r)
            - np.cross(w, np.cross(w, r)))


def band_limited_signals(t_s: np.ndarray, rates_rad_s: np.ndarray, accel_m_s2: np.ndarray, inertia_kg_m2,
                         accel_offset_m, band_hz: float | None = None, ok: np.ndarray | None = None
                         ) -> BandLimitedSignals:
    """The regression's rates, aerodynamic angular accelerations and CG specific forces from
    the measured (preprocessed) gyros and accelerometers of one segment on a uniform grid.

    rates_rad_s, accel_m_s2: (N, 3), NaN where unavailable; band_hz: the low-pass edge [Hz]
    (None: :func:`signal_band_edge_hz` of the gyros); ok: extra (N,) mask of usable rows
    (e.g. where the controls and air data exist)."""
    t = np.asarray(t_s, float)
    w = np.asarray(rates_rad_s, float)
    a = np.asarray(accel_m_s2, float)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    fs = 1.0 / dt
    finite = np.all(np.isfinite(w), axis=1) & np.all(np.isfinite(a), axis=1)
    if ok is not None:
        finite &= np.asarray(ok, bool)
    runs = finite_runs(finite)
    source = "vehicle file"
    if band_hz is None:
        longest = max(runs, key=lambda r: r.stop - r.start, default=slice(0, 0))
        band_hz = signal_band_edge_hz(w[longest], dt)
        source = "flight"
    min_len = max(16, int(np.ceil(MIN_RUN_CYCLES * fs / band_hz)))
    runs = [r for r in runs if r.stop - r.start >= min_len]
    # the zero-phase filter's start and end transients: the first and last EDGE_CYCLES band
    # period of every run (at most EDGE_MAX_S) are filtered but not used
    edge = int(np.ceil(min(EDGE_CYCLES / band_hz, EDGE_MAX_S) * fs))
    used = np.zeros(t.size, bool)
    for r in runs:
        if r.stop - r.start > 2 * edge + 16:
            used[r.start + edge:r.stop - edge] = True
    # filter first, then differentiate: the two commute for a linear filter, but a noisy
    # derivative would make the filter's edge padding (odd reflection about the first and
    # last sample) start from a sample with the full differentiated noise
    wf = low_pass_runs(w, fs, band_hz, runs)
    af = low_pass_runs(a, fs, band_hz, runs)
    w_dot = np.full_like(w, np.nan)
    for r in runs:
        w_dot[r] = np.gradient(wf[r], t[r], axis=0)
    ang = aero_angular_acceleration(wf, w_dot, inertia_kg_m2)
    acc = accel_at_cg(af, wf, w_dot, accel_offset_m)
    return BandLimitedSignals(
        rates_rad_s=wf, ang_accel_rad_s2=ang, accel_cg_m_s2=acc,
        band_hz=float(band_hz), used=used, band_source=source,
        accel_noise_m_s2=tuple(white_noise_sigma(a[:, j], runs) for j in range(3)),
        rate_noise_rad_s=tuple(white_noise_sigma(w[:, j], runs) for j in range(3)),
        filter_runs=tuple((r.start, r.stop) for r in runs))


def band_derivative_noise_gain(fs_hz: float, band_hz: float) -> float:
    """Standard deviation [1/s] of the central-difference derivative of unit white noise after
    :func:`low_pass_runs`: the band path's angular-acceleration noise per unit gyro noise (the
    square root of the sum of the squared impulse response of low-pass then np.gradient)."""
    d = np.gradient(_band_impulse_response(fs_hz, band_hz), 1.0 / fs_hz)
    return float(np.sqrt(np.sum(d * d)))


def segment_keys(fd) -> np.ndarray:
    """flight/segment of every row of a flight-data frame (zeros without those columns)."""
    return ((fd["flight"].astype(str) + "/" + fd["segment"].astype(str)).to_numpy()
            if {"flight", "segment"} <= set(fd.columns) else np.zeros(len(fd)))


def segment_rates_and_bands(fd) -> list[tuple[np.ndarray, float, float]]:
    """(rows, sample rate [Hz], band edge [Hz]) of every flight segment of a flight-data frame
    (its t_s and band_hz columns): pooled flights (or segments whose band the flight set) keep
    their own sample rate and band; NaN for a segment without a band (the smoother path) or
    without a time step."""
    t = fd["t_s"].to_numpy(float)
    band = fd["band_hz"].to_numpy(float)
    keys = segment_keys(fd)
    out = []
    for k in pd.unique(keys):
        idx = np.flatnonzero(keys == k)
        dts = np.diff(t[idx])
        dts = dts[dts > 0]
        b = band[idx]
        b = float(np.median(b[np.isfinite(b)])) if np.isfinite(b).any() else float("nan")
        out.append((idx, 1.0 / float(np.median(dts)) if dts.size else float("nan"), b if b > 0 else float("nan")))
    return out
