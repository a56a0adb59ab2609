"""Filter initialisation (method.md §2-§4): X0/P0, Q and R, each a pure function.

* :func:`parabola_init` - seven-point parabola fit (§2).
* :func:`process_noise_from_spectrum` - white-noise intensity of a triple
  integrator from the signal's spectrum (§3).
* :func:`measurement_noise_from_dispersion` - noise sigma from the high-passed
  signal (§4): a robust MAD estimate, with the seed's (Delta y / 3) rule reported
  alongside.
* :func:`initial_state` - X0, P0 (21 states) from the channel fits.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve

from .findings import true_runs
from .model import CHAIN_START, IX_ACC, IX_ANG, N_STATE, PlantModel, rate_rhs

_MAD_TO_SIGMA = 1.4826022185056018  # 1 / Phi^-1(3/4)


# ----------------------------------------------------------------------------- §2 parabola
@dataclass(frozen=True)
class ParabolaFit:
    """Least-squares parabola y = c0 + c1 tau + c2 tau^2, tau = t - t0_s [s].

    value, rate, accel: y, y', y'' at t0 (= c0, c1, 2 c2) [y units, /s, /s^2];
    var_value, var_rate, var_accel: their variances sigma0^2, sigma1^2, 4 sigma2^2
    (method.md §2 at tau = 0); noise_sigma: the sigma used for the coefficient
    covariance (given, or the residual standard deviation with n - 3 dof);
    indices: which samples were fitted.
    """

    t0_s: float
    value: float
    rate: float
    accel: float
    var_value: float
    var_rate: float
    var_accel: float
    noise_sigma: float
    indices: np.ndarray

    def variances_at(self, tau_s: float) -> tuple[float, float, float]:
        """(sigma_y^2, sigma_ydot^2, sigma_yddot^2) at tau_s [s] after t0 (method.md §2 formulas)."""
        s0, s1, s2 = self.var_value, self.var_rate, self.var_accel / 4.0
        return (s0 + s1 * tau_s**2 + s2 * tau_s**4, s1 + 4.0 * s2 * tau_s**2, 4.0 * s2)

    def summary(self) -> str:
        return "\n".join([
            f"parabola fit of {len(self.indices)} samples, t0 = {self.t0_s:g} s, noise sigma {self.noise_sigma:.4g}",
            f"{'':8}{'estimate':>14}{'sigma':>14}",
            f"{'value':8}{self.value:14.6g}{math.sqrt(self.var_value):14.6g}",
            f"{'rate':8}{self.rate:14.6g}{math.sqrt(self.var_rate):14.6g}",
            f"{'accel':8}{self.accel:14.6g}{math.sqrt(self.var_accel):14.6g}",
        ])


def parabola_init(t_s, y, n: int = 7, valid=None, noise_sigma: float | None = None,
                  t0_s: float | None = None) -> ParabolaFit:
    """Fit a parabola to the first ``n`` valid, finite samples of ``y`` (method.md §2).

    t_s (N,) [s]; y (N,) any unit; valid (N,) bool or None; noise_sigma: known
    noise standard deviation of y (if None, estimated from the fit residuals,
    n - 3 dof); t0_s: time origin [s], default t_s[0].  The coefficient
    covariance is noise_sigma^2 (A'A)^-1 with A = [1, tau, tau^2]; P0 is
    diagonal, so only its diagonal is returned.
    """
    t_s = np.asarray(t_s, dtype=float)
    y = np.asarray(y, dtype=float)
    ok = np.isfinite(y) & np.isfinite(t_s)
    if valid is not None:
        ok &= np.asarray(valid, dtype=bool)
    idx = np.flatnonzero(ok)[:n]
    if idx.size < 3:
        raise ValueError(f"parabola_init needs at least 3 valid samples, found {idx.size}")
    t0 = float(t_s[0] if t0_s is None else t0_s)
    tau = t_s[idx] - t0
    A = np.stack([np.ones_like(tau), tau, tau * tau], axis=1)
    # scale columns for conditioning; the covariance is transformed back
    sc = np.array([1.0, 1.0 / max(np.ptp(tau), 1e-300), 1.0 / max(np.ptp(tau), 1e-300) ** 2])
    As = A * sc
    coef_s, *_ = np.linalg.lstsq(As, y[idx], rcond=None)
    coef = coef_s * sc
    if noise_sigma is None:
        dof = idx.size - 3
        if dof < 1:
            raise ValueError("noise_sigma must be given when only 3 samples are fitted")
        res = y[idx] - A @ coef
        sig = float(np.sqrt(res @ res / dof))
    else:
        sig = float(noise_sigma)
    ata = As.T @ As
    cov_s = solve(ata, np.eye(3), assume_a="pos")
    cov = cov_s * np.outer(sc, sc) * sig**2
    return ParabolaFit(t0, float(coef[0]), float(coef[1]), float(2.0 * coef[2]),
                       float(cov[0, 0]), float(cov[1, 1]), float(4.0 * cov[2, 2]), sig, idx)


# ----------------------------------------------------------------------------- §3 spectrum
@dataclass(frozen=True)
class SpectrumNoise:
    """Process-noise intensity from a spectrum (see :func:`process_noise_from_spectrum`).

    q: white-noise intensity (two-sided PSD) on the ``order``-th derivative of y
    [y units^2 / s^(2 order - 1)]; ms_derivative: mean square of the band-limited
    order-th derivative [y^2/s^(2 order)]; f_max_hz: upper edge of the signal band
    used; noise_floor: expected |Y_k|^2 of the noise; n_bins: signal bins kept.
    """

    q: float
    ms_derivative: float
    f_max_hz: float
    order: int
    noise_floor: float
    n_bins: int

    def summary(self) -> str:
        return (f"spectrum: order {self.order}, band 0-{self.f_max_hz:.3f} Hz ({self.n_bins} signal bins), "
                f"mean square derivative {self.ms_derivative:.4g}, q = {self.q:.4g}")


def process_noise_from_spectrum(y, dt_s: float, f_max_hz: float = 4.0, order: int = 3,
                                noise_sigma: float | None = None, kappa: float = 15.0) -> SpectrumNoise:
    """White-noise intensity q driving the ``order``-th derivative of a uniformly sampled,
    gap-free signal y (method.md §3).

    Rule (documented choice): the signal y is detrended (least-squares line) and
    Hann-windowed; its periodogram P_k = |Y_k|^2 is compared with the noise floor
    (sigma^2 sum w^2 when noise_sigma is given, otherwise the median of P_k above
    f_max_hz divided by ln 2, the median of an exponential variate).  A bin
    0 < f_k <= f_max_hz belongs to the signal when P_k > kappa * floor (a noise
    bin exceeds that with probability exp(-kappa)).  The band-limited derivative's
    mean square is

        ms = 2 / (N sum w^2) * sum_signal_bins (P_k - floor) (2 pi f_k)^(2 order)

    (each harmonic of amplitude A at f contributes (A (2 pi f)^order)^2 / 2), the
    signal band edge f_band is the highest signal bin, and the white noise that
    has this mean square over |f| <= f_band has two-sided PSD

        q = ms / (2 f_band).

    For a chain x1' = x2, x2' = x3, x3' = w with y = x1, use order = 3 (q is the
    intensity of w).  If no bin is significant, the signal is below the noise at
    every frequency: f_band = f_max_hz / 8 (a slowly varying signal, 0.5 Hz at the
    default 4 Hz) and ms the floor-level bound there (one bin at kappa * floor).
    (Placing that bound at f_max_hz, as first written, made q ~1e5-1e6 for a quiet
    channel through the (2 pi f)^6 weight; on short segments the smoother then lost
    precision.  At the lowest bin, 1/T, the smoothed sigma became overconfident:
    54 % of X1 errors within 2 sigma on the reference flight.)
    """
    y = np.asarray(y, dtype=float)
    if not np.all(np.isfinite(y)):
        raise ValueError("process_noise_from_spectrum needs a gap-filled (finite) signal")
    N = y.size
    t = np.arange(N) * dt_s
    yd = y - np.polyval(np.polyfit(t, y, 1), t)
    w = np.hanning(N)
    sw2 = float(w @ w)
    Y = np.fft.rfft(w * yd)
    Pk = (Y.real**2 + Y.imag**2)
    f = np.fft.rfftfreq(N, dt_s)
    if noise_sigma is not None:
        floor = float(noise_sigma) ** 2 * sw2
    else:
        hi = Pk[f > f_max_hz]
        floor = float(np.median(hi) / math.log(2.0)) if hi.size else 0.0
    band = (f > 0) & (f <= f_max_hz)
    sel = band & (Pk > kappa * floor)
    wgt = (2.0 * np.pi * f) ** (2 * order)
    if np.any(sel):
        ms = 2.0 / (N * sw2) * float(np.sum((Pk[sel] - floor) * wgt[sel]))
        f_band = float(f[sel].max())
    else:
        f_band = float(f_max_hz) / 8.0
        ms = 2.0 / (N * sw2) * kappa * floor * (2.0 * np.pi * f_band) ** (2 * order)
    q = ms / (2.0 * f_band)
    return SpectrumNoise(float(q), float(ms), f_band, int(order), floor, int(np.count_nonzero(sel)))


# ----------------------------------------------------------------------------- §4 dispersion
@dataclass(frozen=True)
class NoiseDispersion:
    """Measurement-noise estimate of one channel (see :func:`measurement_noise_from_dispersion`).

    sigma: robust estimate (MAD of the high-passed noise, corrected for the removed
    band) [y units]; sigma_std: the same with the standard deviation instead of
    the MAD; sigma_seed: the seed's rule Delta y / 3; delta_y: largest deviation of
    the noise about its mean; n: number of samples used; f_cut_hz: high-pass edge;
    sigma_floor: the white-noise sigma the top quarter of the band implies (its mean
    power spectral density times the Nyquist frequency) [y units], NaN when fewer than
    64 consecutive valid samples.  For white noise sigma_floor = sigma; a recorded
    signal that was low-pass filtered before recording (anti-aliasing, smoothing) has
    little noise left near Nyquist, and the high-passed part counted as noise is
    signal or coloured noise (``whiteness``).
    """

    sigma: float
    sigma_std: float
    sigma_seed: float
    delta_y: float
    n: int
    f_cut_hz: float
    sigma_floor: float = float("nan")

    @property
    def whiteness(self) -> float:
        """sigma / sigma_floor: about 1 for white noise (simulated flights 0.9-1.06); the
        NASA Twin Otter's low-passed IMU 13-34.  NaN when the floor is unknown or zero."""
        return self.sigma / self.sigma_floor if self.sigma_floor > 0 else float("nan")

    @property
    def variance(self) -> float:
        """R entry: sigma^2."""
        return self.sigma**2

    def summary(self) -> str:
        return (f"noise dispersion over {self.n} samples (high-pass above {self.f_cut_hz:g} Hz): "
                f"sigma robust {self.sigma:.4g}, std {self.sigma_std:.4g}, "
                f"seed rule (dy/3) {self.sigma_seed:.4g} (dy = {self.delta_y:.4g}), "
                f"white floor near Nyquist {self.sigma_floor:.4g}")


def measurement_noise_from_dispersion(y, dt_s: float, f_cut_hz: float = 4.0, valid=None) -> NoiseDispersion:
    """Noise sigma of a uniformly sampled channel (method.md §4).

    y (N,) gap-filled signal; valid (N,) bool marks the genuine samples (the
    statistics use only those: interpolated samples carry no noise).  The noise
    is the part of y above f_cut_hz: y minus its band-limited part (FFT brick
    wall after removing the line through the end means, so the periodic
    extension has no jump).  White noise keeps the fraction 1 - f_cut/f_Nyquist
    of its variance, which is divided out.

    Samples within max(1 s, 4/f_cut) of the ends (filter ringing) are left out;
    samples whose high-passed value exceeds 6 sigma are outliers: they are
    replaced by the smooth part and the high-pass is redone, so an outlier's
    ringing does not inflate its neighbours, and they are left out too.

    sigma = 1.4826 * MAD(noise) / sqrt(1 - f_cut/f_Nyquist) is the estimate used:
    the seed's r = (Delta y / 3)^2 takes the largest deviation of N samples for 3
    sigma, but for N Gaussian samples the largest |deviation| is about
    sqrt(2 ln N) sigma (4.1 sigma for N = 8000), so it overestimates sigma by
    ~35 % and is at the mercy of a single outlier.  The seed rule is reported in
    ``sigma_seed`` for comparison.
    """
    y = np.asarray(y, dtype=float)
    N = y.size
    if not np.all(np.isfinite(y)):
        raise ValueError("measurement_noise_from_dispersion needs a gap-filled (finite) signal")
    ok = np.ones(N, dtype=bool) if valid is None else np.asarray(valid, dtype=bool).copy()
    # the brick wall rings near the ends of the record: leave out max(1 s, 4 / f_cut) at each end
    edge = int(min(N // 8, math.ceil(max(1.0, 4.0 / max(f_cut_hz, 1e-9)) / dt_s)))
    inner = ok.copy()
    inner[:edge] = False
    inner[N - edge:] = False
    f_nyq = 0.5 / dt_s
    keep = max(1.0 - f_cut_hz / f_nyq, 1e-6)

    def highpass(sig):
        m = max(1, min(10, N // 10))
        t = np.arange(N, dtype=float)
        a, b = float(np.mean(sig[:m])), float(np.mean(sig[-m:]))
        ta, tb = float(np.mean(t[:m])), float(np.mean(t[-m:]))
        line = a + (b - a) * (t - ta) / (tb - ta if tb > ta else 1.0)
        Y = np.fft.rfft(sig - line)
        Y[np.fft.rfftfreq(N, dt_s) <= f_cut_hz] = 0.0
        return np.fft.irfft(Y, n=N)

    def mad_sigma(n):
        med = np.median(n)
        return _MAD_TO_SIGMA * float(np.median(np.abs(n - med))) / math.sqrt(keep)

    noise1 = highpass(y)
    dy = float(np.max(np.abs(noise1[inner] - np.mean(noise1[inner])))) / math.sqrt(keep)
    # second pass: samples beyond 6 sigma (outliers) replaced by the smooth part, so that
    # the high-pass ringing of an outlier does not inflate its neighbours
    s1 = mad_sigma(noise1[inner])
    out = np.abs(noise1 - np.median(noise1[inner])) > 6.0 * s1 * math.sqrt(keep)
    if np.any(out):
        y2 = np.where(out, y - noise1, y)
        noise = highpass(y2)
        use = inner & ~out
    else:
        noise = noise1
        use = inner
    nz = noise[use]
    sigma = mad_sigma(nz)
    sigma_std = float(np.std(nz)) / math.sqrt(keep)
    floor = white_floor_sigma(noise, dt_s, inner, f_cut_hz)
    return NoiseDispersion(sigma, sigma_std, dy / 3.0, dy, int(nz.size), float(f_cut_hz), floor)


def white_floor_sigma(noise, dt_s: float, valid, f_cut_hz: float, min_samples: int = 64) -> float:
    """The sigma of the white noise whose density equals the mean power spectral density
    of `noise` over the top quarter of the band (above f_cut_hz too) [noise units].

    Welch (Hann, 50 % overlap) on the longest run of `valid` samples, so that an
    interpolated stretch (no noise) does not lower it; NaN when that run is shorter
    than min_samples.  One-sided density S: white noise of variance s^2 has S = s^2 / f_N
    in every bin but DC and Nyquist (scipy does not double those: the Nyquist bin is left out).
    """
    from scipy.signal import welch  # here, not at import: the rest of the module does not need it

    runs = true_runs(valid)
    if not runs:
        return float("nan")
    a, b = max(runs, key=lambda r: r[1] - r[0])
    if b - a < min_samples:
        return float("nan")
    f_nyq = 0.5 / dt_s
    f, P = welch(np.asarray(noise, float)[a:b], fs=1.0 / dt_s, nperseg=min(256, (b - a) // 4))
    top = (f >= max(0.75 * f_nyq, f_cut_hz)) & (f < f_nyq)
    return math.sqrt(float(np.mean(P[top])) * f_nyq) if top.any() else float("nan")



# ----------------------------------------------------------------------------- X0, P0
def initial_state(t_s, z, valid, model: PlantModel, noise_sigma, l3_var=None, n: int = 7):
    """X0 (21,) and P0 (21,21, diagonal) from seven-point parabola fits (method.md §2).

    z (N,6), valid (N,6); noise_sigma (6,) channel noise sigmas [m/s^2, rad/s];
    l3_var (3,) prior variances of L3, M3, N3 [(rad/s^4)^2] (not observable from
    a parabola; default: 100 x the variance implied by the gyro fits over the fit window).

    Rates: gyro fit values.  Angular chains: the Euler equations solved for
    (L1, M1, N1) from the fitted (p', q', r'), and (L2, M2, N2) from (p'', q'', r'')
    through the same input matrix (the gyroscopic terms' derivative neglected);
    variances propagated through the inverse input matrix.  CG chains: accel
    fits with the lever-arm term at t0 removed (its variance, through the
    angular-acceleration variances, added).
    """
    z = np.asarray(z, dtype=float)
    valid = np.asarray(valid, dtype=bool)
    fits = [parabola_init(t_s, z[:, j], n=n, valid=valid[:, j], noise_sigma=noise_sigma[j]) for j in range(6)]
    prm = model.params
    Bm = model.input_matrix
    Binv = solve(Bm, np.eye(3))
    w0 = np.array([fits[3 + i].value for i in range(3)])
    wd = np.array([fits[3 + i].rate for i in range(3)])
    wdd = np.array([fits[3 + i].accel for i in range(3)])
    var_w = np.array([fits[3 + i].var_value for i in range(3)])
    var_wd = np.array([fits[3 + i].var_rate for i in range(3)])
    var_wdd = np.array([fits[3 + i].var_accel for i in range(3)])
    gyro = rate_rhs(w0, np.zeros(3), prm)       # omega' with u = 0: the gyroscopic part
    u1 = Binv @ (wd - gyro)
    u2 = Binv @ wdd
    var_u1 = (Binv**2) @ var_wd
    var_u2 = (Binv**2) @ var_wdd
    if l3_var is None:
        T = float(np.ptp(np.asarray(t_s)[fits[3].indices]))
        l3_var = 100.0 * var_u2 / max(T, 1e-9) ** 2
    x0 = np.zeros(N_STATE)
    P0 = np.zeros(N_STATE)
    x0[0:3] = w0
    P0[0:3] = var_w
    r = prm[9:12]
    E = np.array([[0.0, r[2], -r[1]], [-r[2], 0.0, r[0]], [r[1], -r[0], 0.0]])
    lever = w0 * (w0 @ r) - r * (w0 @ w0) + E @ wd
    var_lever = (E**2) @ var_wd
    for i, s in enumerate(IX_ACC):
        fz = fits[i]
        x0[s:s + 3] = (fz.value - lever[i], fz.rate, fz.accel)
        P0[s:s + 3] = (fz.var_value + var_lever[i], fz.var_rate, fz.var_accel)
    for i, s in enumerate(IX_ANG):
        x0[s:s + 3] = (u1[i], u2[i], 0.0)
        P0[s:s + 3] = (var_u1[i], var_u2[i], float(np.asarray(l3_var)[i]))
    assert tuple(CHAIN_START[3:]) == tuple(IX_ANG)
    return x0, np.diag(P0), fits
