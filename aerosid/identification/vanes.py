"""The air-data vanes against the inertial sensors: their timing and their position
(data-compatibility corrections; Klein & Morelli, ch. 10).

Position
--------
A vane at r = (x, y, z) from the CG (body axes) sees the air's velocity relative to that point,
v + omega x r, so for small rate terms it reads

    alpha_vane = alpha + (p y - q x) / V,     beta_vane = beta + (r x - p z) / V

(a boom ahead of the CG, x > 0, reads a lower alpha while the nose pitches up).  The vehicle
file's ``[air_data] vane_position_m`` moves the vane angles to the CG with the gyros
(:func:`angles_at_cg`) before anything reads them; the default [0, 0, 0] is a vane already at
the CG or angles already corrected (SIDPAC's, the simulators').

Timing: why
-----------
Equation-error regression pairs every sample of the flight-derived coefficients (from the
accelerometers and gyros) with the angle of attack read at the same time stamp.  If the
vane's reading reaches the telemetry later than the IMU's (a slower air-data computer, a
filter, a logging skew), the regression pairs C_N(t) with alpha(t - tau) and makes up the
difference with whatever regressor leads alpha: the elevator (C_N,delta), the pitch rate
(C_m,q).  Measured on the NASA Twin Otter's manoeuvre 018 (bench/results/
validate_twin_otter.md, section 4): the vane angle lags the alpha integrated from the IMU by
25 +- 2 ms (on the raw files with the recorded attitude the fit's residual halves at +20 ms on
018 and on 017); with alpha advanced by 25 ms the C_N residual falls from 3.7e-3 to 1.6e-3,
C_N,delta moves from 0.19 to 0.47 and C_m,alpha from -1.468 to -1.539, SIDPAC's own
output-error estimates being 0.409 and -1.543.  An output-error fit, which weights q and
a_z as much as alpha, barely feels such a skew; equation error does.

Timing: what is measured
------------------------
Flight-path kinematics give alpha-dot from the rates, the CG specific forces and the attitude:

    alpha_dot = K + G,   K = q - tan b (p cos a + r sin a) + (cos a a_z - sin a a_x) / (V cos b),
                         G = g (cos a cos th cos ph + sin a sin th) / (V cos b)

(aerosid.modelling.flight_path).  The estimation carries no attitude, so theta and phi are
integrated from the gyros (Euler's kinematic equations), started from the specific force's
direction over the segment's first INITIAL_S seconds (quasi-steady flight: f = (g sin th,
-g cos th sin ph, -g cos th cos ph)).  A wrong start, the gyros' bias, the accelerometers' bias
and the vane's calibration make slow errors of the integrated alpha; an intercept and a slope
per run of samples take them.  On each run

    alpha_vane(t) = c0 + c1 t + gain A(t - tau) ~ c0 + c1 t + gain A(t) - gain tau (K + G)(t),
    A = int (K + G) dt,

is fitted by least squares with the coloured-residual sigma (Morelli & Klein,
aerosid.identification.regression.fit_linear, runs as groups); tau is refined by shifting A by
the estimate and fitting again.  Every signal is the band path's (one low-pass for all), so the
band adds no relative delay.  Measured (seed 0, the default pipeline's flight data): Twin Otter
018 24.9 +- 2.4 ms (gain 0.994); JSBSim flights whose vanes are the true alpha 6.0 +- 1.3 (pa28),
6.1 +- 2.1 (c172p), 13 +- 5.5 ms (T37) -- JSBSim's logged gyro rates lead alpha and the
accelerometers by half an integration step, 5 ms (docs/estimation.md; the same fit on its
noise-free truth: 4.3 ms), so the simulated data themselves are that far from exact
kinematics; with 25 ms added to the vanes the estimate rises by 25.0 (pa28) and 25.3 ms (T37).  A high-pass instead of the attitude (no G, the slow parts
filtered out) gave the same estimates with 2-4 x the sigma on the Twin Otter's 8 s.

Timing: what is done with it
----------------------------
Reported, not applied: a run whose vanes lag (or lead) by at least one sample interval with
p < DELAY_P_MAX is a finding ("airdata_delay") with the estimate (band path only), and the
vehicle file's ``[air_data] delay_s`` advances both vane angles by a known or measured delay
before anything reads them (the band path, the smoother path, ``validate``); beta's own delay
is not estimated (a longitudinal manoeuvre hardly moves it) and is taken as alpha's, one
air-data system.  Another cause looks alike: a vane ahead of the CG whose reading was not
moved to the CG reads alpha - x_v q / V, and in a short period q leads alpha as alpha-dot
does (x_v = 1 m at 50 m/s is about 20 ms); advancing the vanes is the wrong cure for that,
which is why the engineer decides (and why ``vane_position_m`` exists).  The correction is
not automatic: the estimate is a few milliseconds off on simulated data whose aerodynamic
forces are consistent with the vane's sample (JSBSim's half step of the gyros), where an
automatic shift would put that error into the regression; the engineer who knows the air-data
system can say whether the lag is real.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
import scipy.stats

from aerosid.identification.band import finite_runs, white_noise_sigma
from aerosid.identification.regression import fit_linear
from aerosid.modelling.flight_path import gravity_alpha_dot, kinematic_alpha_dot_no_gravity

__all__ = ["VaneDelay", "vane_delay", "advance", "angles_at_cg", "gyro_attitude", "kinematic_alpha_rate",
           "kinematic_mismatch_z", "DELAY_P_MAX", "MIN_RUN_S", "INITIAL_S", "MAX_DELAY_S"]

#: A delay is reported when its two-sided p-value (coloured-residual sigma, normal) is below
#: this, the significance level of the project's other findings (aerosid.diagnosis: P_MAX).
DELAY_P_MAX = 0.001
#: Runs of usable samples shorter than this [s] are left out (an intercept and a slope of
#: their own would take most of what they carry).
MIN_RUN_S = 2.0
#: The initial attitude comes from the mean specific force over this long [s].
INITIAL_S = 0.2
#: Refinement passes (each shifts the integrated kinematic alpha by the current estimate).
PASSES = 3
#: An estimate beyond this [s] is no delay the kinematics can tell (the vane does not follow
#: the kinematic alpha at all): no result (the range of the vehicle file's delay_s).
MAX_DELAY_S = 0.5
#: A vane whose alpha per kinematic alpha (VaneDelay.gain) lies outside this range does not
#: follow the aircraft: dead, floating, miscalibrated, or the wrong column (healthy flights:
#: 0.94..1.005 on c182, f15, sgs233 and the Twin Otter).
GAIN_RANGE = (0.5, 2.0)
G_M_S2 = 9.80665


@dataclass(frozen=True)
class VaneDelay:
    """The vane angle of attack's delay behind the IMU's kinematics on one segment.

    delay_s: tau [s], positive when the vane reads later than the IMU; sigma_s: its
    1-sigma [s] (coloured residuals); gain: the vane's alpha per kinematic alpha (about 1);
    n: samples fitted; sample_s: the segment's sample interval [s]; applied_s: the vehicle
    file's ``[air_data] delay_s`` the vanes were already advanced by (the estimate is what is
    left after it)."""

    delay_s: float
    sigma_s: float
    gain: float
    n: int
    sample_s: float
    applied_s: float = 0.0

    @property
    def p_value(self) -> float:
        if not (self.sigma_s > 0 and math.isfinite(self.delay_s)):
            return float("nan")
        return float(2.0 * scipy.stats.norm.sf(abs(self.delay_s) / self.sigma_s))

    @property
    def detected(self) -> bool:
        """p < DELAY_P_MAX and at least one sample interval: a skew the telemetry resolves."""
        return bool(self.p_value < DELAY_P_MAX and abs(self.delay_s) >= self.sample_s * (1 - 1e-9))

    def summary(self) -> str:
        way = "lags" if self.delay_s >= 0 else "leads"
        already = f" after the vehicle file's delay_s = {self.applied_s:g} s" if self.applied_s else ""
        return (f"air-data timing: the vane alpha {way} the IMU's kinematic alpha by "
                f"{abs(self.delay_s) * 1e3:.1f} +- {self.sigma_s * 1e3:.1f} ms{already} (p = {self.p_value:.2g}; "
                f"gain {self.gain:.3f}, {self.n} samples, sample interval {self.sample_s * 1e3:.3g} ms)")

    @property
    def follows(self) -> bool:
        """The vane alpha follows the IMU's kinematic alpha: a delay within MAX_DELAY_S fits and
        the gain lies in GAIN_RANGE."""
        return bool(math.isfinite(self.delay_s) and GAIN_RANGE[0] <= self.gain <= GAIN_RANGE[1])

    def as_dict(self) -> dict:
        return {**asdict(self), "p_value": self.p_value, "detected": self.detected, "follows": self.follows}


def advance(t_s: np.ndarray, x: np.ndarray, delay_s: float) -> np.ndarray:
    """x read delay_s [s] later: x(t + delay_s), linear interpolation between the finite
    samples of each contiguous run; NaN where t + delay_s leaves its run.  delay_s = 0
    returns x unchanged (a copy)."""
    x = np.asarray(x, float)
    if delay_s == 0.0:
        return x.copy()
    t = np.asarray(t_s, float)
    out = np.full_like(x, np.nan)
    for r in finite_runs(np.isfinite(x)):
        if r.stop - r.start < 2:
            continue
        tr = t[r]
        target = tr + delay_s
        inside = (target >= tr[0] - 1e-9) & (target <= tr[-1] + 1e-9)
        out[r][inside] = np.interp(target[inside], tr, x[r])
    return out


def angles_at_cg(alpha_vane_rad, beta_vane_rad, p_rad_s, q_rad_s, r_rad_s, V_m_s, position_m):
    """(alpha, beta) [rad] at the CG from vanes at position_m = (x, y, z) [m] from the CG (body
    axes), with the body rates [rad/s] and the airspeed [m/s] of the same samples (module doc:
    alpha = alpha_vane - (p y - q x) / V, beta = beta_vane - (r x - p z) / V)."""
    x, y, z = (float(v) for v in position_m)
    V = np.asarray(V_m_s, float)
    p, q, r = (np.asarray(w, float) for w in (p_rad_s, q_rad_s, r_rad_s))
    return (np.asarray(alpha_vane_rad, float) - (p * y - q * x) / V,
            np.asarray(beta_vane_rad, float) - (r * x - p * z) / V)


def gyro_attitude(t_s, p_rad_s, q_rad_s, r_rad_s, f0_m_s2) -> tuple[np.ndarray, np.ndarray]:
    """(theta, phi) [rad]: Euler's kinematic equations integrated from the gyros (forward
    Euler), started where the specific force f0 = (f_x, f_y, f_z) [m/s^2] of quasi-steady
    flight points (theta = asin(f_x / g), phi = atan2(-f_y, -f_z)).  Rates NaN inside the grid
    are bridged linearly; t_s uniform or not."""
    t = np.asarray(t_s, float)
    rates = []
    for w in (p_rad_s, q_rad_s, r_rad_s):
        w = np.asarray(w, float)
        ok = np.isfinite(w)
        rates.append(np.interp(t, t[ok], w[ok]) if ok.any() else np.zeros_like(t))
    p, q, r = rates
    fx, fy, fz = (float(v) for v in f0_m_s2)
    theta, phi = np.empty_like(t), np.empty_like(t)
    theta[0] = math.asin(min(1.0, max(-1.0, fx / G_M_S2)))
    phi[0] = math.atan2(-fy, -fz)
    for i in range(t.size - 1):
        h = t[i + 1] - t[i]
        sp, cp = math.sin(phi[i]), math.cos(phi[i])
        phi[i + 1] = phi[i] + h * (p[i] + math.tan(theta[i]) * (q[i] * sp + r[i] * cp))
        theta[i + 1] = theta[i] + h * (q[i] * cp - r[i] * sp)
    return theta, phi


def kinematic_alpha_rate(t_s, alpha_vane_rad, beta_rad, p_rad_s, q_rad_s, r_rad_s, ax_cg_m_s2, ay_cg_m_s2,
                         az_cg_m_s2, V_m_s) -> tuple[np.ndarray, np.ndarray] | None:
    """(alpha-dot [rad/s] from the flight-path kinematics, K + G, the samples it holds on): the
    rates, the CG specific forces and V, with the attitude integrated from the gyros from the
    first usable sample on (started from the specific force of its first INITIAL_S seconds).
    Arguments as :func:`vane_delay`'s; None when no sample is usable."""
    t = np.asarray(t_s, float)
    a, b = np.asarray(alpha_vane_rad, float), np.asarray(beta_rad, float)
    p, q, r = (np.asarray(x, float) for x in (p_rad_s, q_rad_s, r_rad_s))
    fx, fy, fz = (np.asarray(x, float) for x in (ax_cg_m_s2, ay_cg_m_s2, az_cg_m_s2))
    V = np.asarray(V_m_s, float)
    usable = np.isfinite(a) & np.isfinite(b) & np.isfinite(p) & np.isfinite(q) & np.isfinite(r) \
        & np.isfinite(fx) & np.isfinite(fy) & np.isfinite(fz) & np.isfinite(V) & (V > 0)
    first = np.flatnonzero(usable)
    if first.size == 0:
        return None
    # the attitude from the first usable sample on (the band path's first rows are its filter's edge)
    i0 = int(first[0])
    head = first[t[first] <= t[i0] + INITIAL_S]
    theta, phi = np.full_like(t, np.nan), np.full_like(t, np.nan)
    theta[i0:], phi[i0:] = gyro_attitude(t[i0:], p[i0:], q[i0:], r[i0:],
                                         (fx[head].mean(), fy[head].mean(), fz[head].mean()))
    rate = kinematic_alpha_dot_no_gravity(a, b, p, q, r, fx, fz, V) + gravity_alpha_dot(a, b, theta, phi, V)
    return rate, usable & np.isfinite(rate)


def kinematic_mismatch_z(t_s, alpha_vane_rad, rate_rad_s, usable, band_hz: float, delay_s: float = 0.0,
                         gain: float = 1.0) -> np.ndarray:
    """|d alpha_vane/dt - gain x kinematic alpha-dot(t - delay_s)| per sample, each run's median
    taken out and averaged over one band period, in robust sigma (1.4826 MAD over the segment);
    NaN off the usable runs.  A gyro step b [rad/s] or an a_z step d [m/s^2] shows as b, d/V
    for its duration, which the vane does not follow."""
    t = np.asarray(t_s, float)
    a, rate = np.asarray(alpha_vane_rad, float), np.asarray(rate_rad_s, float)
    z = np.full(t.size, np.nan)
    if t.size < 3 or not band_hz > 0:
        return z
    dt = float(np.median(np.diff(t)))
    w = max(1, int(round(1.0 / (band_hz * dt))))
    for s in finite_runs(np.asarray(usable, bool)):
        if s.stop - s.start < 2 * w:
            continue
        ts = t[s]
        m = np.gradient(a[s], ts) - gain * np.interp(ts - delay_s, ts, rate[s])
        z[s] = np.convolve(m - np.median(m), np.ones(w) / w, mode="same")
    scale = 1.4826 * float(np.nanmedian(np.abs(z - np.nanmedian(z)))) if np.isfinite(z).any() else 0.0
    return np.abs(z - np.nanmedian(z)) / scale if scale > 0 else np.full(t.size, np.nan)


def vane_delay(t_s, alpha_vane_rad, beta_rad, p_rad_s, q_rad_s, r_rad_s, ax_cg_m_s2, ay_cg_m_s2, az_cg_m_s2,
               V_m_s, *, applied_s: float = 0.0) -> VaneDelay | None:
    """Estimate the vane alpha's delay behind the IMU's kinematics (module doc).

    Every argument is on one segment's grid, NaN where unusable, and through the band path's
    common low-pass: alpha_vane_rad (the vane angle less its bias), beta_rad, the rates
    [rad/s], the CG specific forces [m/s^2], V [m/s]; applied_s: the delay the vanes were
    already advanced by (reported only).  None when no run of MIN_RUN_S is left."""
    t = np.asarray(t_s, float)
    if t.size < 16:
        return None
    kin = kinematic_alpha_rate(t, alpha_vane_rad, beta_rad, p_rad_s, q_rad_s, r_rad_s, ax_cg_m_s2, ay_cg_m_s2,
                               az_cg_m_s2, V_m_s)
    if kin is None:
        return None
    rate, usable = kin
    a = np.asarray(alpha_vane_rad, float)
    dt = float(np.median(np.diff(t)))
    runs = [s for s in finite_runs(usable) if t[s.stop - 1] - t[s.start] >= MIN_RUN_S]
    if not runs:
        return None
    tau, fit, n = 0.0, None, 0
    for _ in range(PASSES):
        ys, blocks, groups = [], [], []
        for i, s in enumerate(runs):
            ts, k = t[s], rate[s]
            integral = np.concatenate([[0.0], np.cumsum(0.5 * (k[1:] + k[:-1]) * np.diff(ts))])
            keep = (ts - tau >= ts[0]) & (ts - tau <= ts[-1])  # the shifted kinematics exist there
            trend = np.zeros((int(keep.sum()), 2 * len(runs)))
            trend[:, 2 * i] = 1.0
            trend[:, 2 * i + 1] = (ts[keep] - ts.mean()) / max(ts[-1] - ts[0], dt)
            ys.append(a[s][keep])
            blocks.append(np.column_stack([trend, np.interp(ts[keep] - tau, ts, integral),
                                           np.interp(ts[keep] - tau, ts, k)]))
            groups.append(np.full(int(keep.sum()), i))
        y, X = np.concatenate(ys), np.vstack(blocks)
        n = int(y.size)
        fit = fit_linear(y, X, channel="alpha_vane", groups=np.concatenate(groups) if len(runs) > 1 else None)
        g, m = (float(v) for v in fit.estimate[-2:])
        if not (math.isfinite(g) and abs(g) > 1e-6):
            return VaneDelay(math.nan, math.nan, g if math.isfinite(g) else 0.0, n, dt, float(applied_s))
        tau += -m / g
        if not abs(tau) <= MAX_DELAY_S:  # no delay the kinematics can tell: the vane does not follow them
            return VaneDelay(math.nan, math.nan, g, n, dt, float(applied_s))
    g, m = (float(v) for v in fit.estimate[-2:])
    C = np.asarray(fit.cov, float)[-2:, -2:]
    J = np.array([m / g ** 2, -1.0 / g])  # d(-m/g)/d(g, m)
    sigma = float(math.sqrt(max(float(J @ C @ J), 0.0)))
    return VaneDelay(delay_s=float(tau), sigma_s=sigma, gain=g, n=n, sample_s=dt, applied_s=float(applied_s))


#: Order of the differences the vanes' white noise is measured with: the angle's own change cancels
#: (at 100 Hz its third difference is ~1e-6 rad against the JSBSim vanes' 0.15 deg noise).
VANE_NOISE_ORDER = 3


def vane_white_noise_rad(x: np.ndarray) -> float:
    """1-sigma [rad] of a vane column's white noise (robust: 1.4826 MAD of its third differences
    over its finite runs, aerosid.identification.band.white_noise_sigma); NaN with too few samples.
    Vanes low-passed before recording hide part of it (the differences see the high frequencies)."""
    x = np.asarray(x, float)
    return white_noise_sigma(x, finite_runs(np.isfinite(x)), VANE_NOISE_ORDER)
