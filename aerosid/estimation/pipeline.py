"""smooth_flight: initialisation, EKF + MBF smoother, automatic tuning, typed result.

NIS definitions (documented choices):

* Filter: NIS_k = v_k' S_k^-1 v_k over the channels used at k (dof_k of them),
  NaN where no channel was used.  Under a correct model E[NIS_k] = dof_k.
* Smoother: NIS_k = sum_j e_j^2 / Var(e_j), e = z_k - h(x(k|N)) the smoothed
  residual of each used channel and Var(e_j) = (R D_k R)_jj = R_jj - (H P(k|N) H')_jj
  its variance (D_k = S^-1 + K' Lambda~_k K from the MBF recursion; de Jong's
  smoothed-disturbance variance).  Each term is a standardised residual, so
  E[NIS_k] = dof_k under a correct model, like the filter's.  Why this and not
  e' R^-1 e: the smoothed residual is smaller than the noise (its covariance is
  R - H P(k|N) H'), so e' R^-1 e sits below dof by tr(R^-1 H P(k|N) H') and
  would read as "good" even for a filter that is not; normalising by the
  residual's own variance makes 6 the target for both.  The seed's numbers
  (EKF 12.16, smoother 6.35) are what a too-small Q gives with the seed's
  definition; the R-normalised value is reported too (``mean_residual_r``).
* Band for the mean over the n samples with an update: mean(dof) +- 1.96
  sqrt(2 sum dof_k) / n, i.e. 6 +- 1.96 sqrt(12/n) with all six channels.  For
  the smoother the samples are not independent, so its band is indicative.

Automatic tuning (``EBMOptions.auto_tune``): the chain intensities are scaled by
one factor q_scale, found by a safeguarded secant search in log-log space so that
the filter's mean NIS equals mean(dof); with ``tune_r`` the per-channel R is
re-estimated between steps by the EM update R_jj = mean(e_j^2 + Var(eps_j | all))
from the smoother.  Every iteration is recorded (``tuning_history``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from .core_run import CoreRun, chain_shares, run_filter_smoother  # noqa: F401  (re-exported)
from .init import initial_state, measurement_noise_from_dispersion, process_noise_from_spectrum
from .model import (MEAS_NAMES, MEAS_UNITS, N_MEAS, STATE_NAMES, PlantModel, discrete_process_noise,
                    measure_many)


@dataclass(frozen=True)
class EBMOptions:
    """Options of :func:`smooth_flight`.

    f_max_hz: cap of the signal band [Hz] (Q from the spectrum, R high-pass edge);
    gate_probability: per-channel false-alarm probability of the innovation gate
    (chi-square, 1 dof, on the conditional innovation; None disables the gate);
    auto_tune: scale Q until the filter NIS is in its band; tune_r: EM re-estimate
    of R during tuning; max_tuning_iterations; nis_tolerance: stop when
    |mean NIS - target| <= nis_tolerance * half band width;
    use_numba: compiled kernel (False: the plain-numpy reference, slow);
    segment_length: samples between covariance checkpoints of the compiled
    smoother (memory vs recomputation); spectrum_kappa: significance of a signal
    bin (noise-floor multiples); divergence_window_s [s] and
    divergence_probability: windowed NIS test flagging samples; the segment
    counts as diverged when the flagged samples form a run of at least
    divergence_min_s [s] or exceed divergence_max_fraction of the samples (a
    short NIS excursion at a sharp manoeuvre is reported, not fatal);
    q_scale_bounds: the range auto-tuning may move Q within, relative to its
    spectral estimate (mean NIS is set mostly by R; letting Q wander far to
    hit a tight band trades lag for NIS and biases the smoothed derivatives);
    q_chain_scale: multipliers of the spectral intensities of the X, Y, Z, L, M,
    N chains.  The angular-acceleration chains are estimated from the gyros'
    fourth-derivative spectrum, which is noise-dominated above ~1 Hz, so their
    spectral intensity comes out too small and the smoothed L, M, N are
    attenuated (on seed-rlv: M1 gain 0.93, L1 0.73-0.84, biasing C_m and C_l
    slopes by -5 % and -20 %).  A vehicle file may set its own (seed-rlv:
    (1, 1, 1, 1000, 3, 3), calibrated on simulated flights, docs/estimation.md);
    q_scale, r_scale: initial scalings (r_scale: one factor or one per channel);
    gyro_gate_hold_s [s]: the longest run of consecutive samples the gate may hold a
    gyro (p, q, r) out; the next sample is taken without the test (None: no limit).
    A gyro measures its state directly and nothing else in the plant does: gated, the
    rate is the moment chain's extrapolation, the accelerometers' lever-arm terms pull
    that chain along, and within tenths of a second in a manoeuvre the state has left
    for good (unseen pa28 seed 0, a +0.03 rad/s pitch-gyro step at q = 0.16 rad/s: M1 to
    5 rad/s^2, q to 1.45 rad/s 0.34 s after the gate shut, q then gated to the end of
    the flight, a_x and p after it, the segment lost).  The gate stays for spikes; a gyro
    step the filter then follows is the kinematic_mismatch finding's to report
    (aerosid.identification.airdata_findings).
    """

    f_max_hz: float = 4.0
    gate_probability: float | None = 1e-6
    auto_tune: bool = True
    tune_r: bool = True
    max_tuning_iterations: int = 12
    nis_tolerance: float = 0.5
    use_numba: bool = True
    segment_length: int = 64
    spectrum_kappa: float = 15.0
    divergence_window_s: float = 1.0
    divergence_probability: float = 1e-6
    divergence_min_s: float = 3.0
    divergence_max_fraction: float = 0.10
    q_scale_bounds: tuple = (0.5, 2.0)
    q_chain_scale: tuple = (1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    q_scale: float = 1.0
    r_scale: float = 1.0
    gyro_gate_hold_s: float | None = 0.1


@dataclass(frozen=True)
class TuningRecord:
    """One tuning iteration: scalings used and the resulting mean NIS."""

    iteration: int
    q_scale: float
    r_scale: tuple
    mean_nis_filter: float
    mean_nis_smoother: float


def chi2_band(dof: np.ndarray) -> tuple[float, float, float]:
    """(target, low, high) for the mean NIS over the samples with dof > 0 (95 % band)."""
    d = np.asarray(dof)
    d = d[d > 0]
    if d.size == 0:
        return (float("nan"),) * 3
    target = float(d.mean())
    half = 1.96 * math.sqrt(2.0 * float(d.sum())) / d.size
    return target, target - half, target + half


def longest_run(flags: np.ndarray) -> int:
    """Length of the longest run of True in a boolean array."""
    if not flags.any():
        return 0
    edges = np.diff(np.concatenate([[0], flags.astype(np.int8), [0]]))
    return int(np.max(np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)))


def _diverged(dflag: np.ndarray, run, dt: float, opt) -> bool:
    if not (np.all(np.isfinite(run.x_smooth)) and np.all(np.isfinite(run.sigma_smooth))):
        return True
    return bool(longest_run(dflag) * dt >= opt.divergence_min_s or dflag.mean() > opt.divergence_max_fraction)


def divergence_flags(nis: np.ndarray, dof: np.ndarray, window: int, prob: float) -> np.ndarray:
    """Samples whose centred window of ``window`` samples has a NIS sum beyond the
    chi-square(sum dof) upper 1-prob quantile."""
    N = nis.size
    x = np.where(np.isfinite(nis), nis, 0.0)
    d = np.where(np.isfinite(nis), dof, 0).astype(float)
    w = max(1, min(int(window), N))
    cs = np.concatenate([[0.0], np.cumsum(x)])
    cd = np.concatenate([[0.0], np.cumsum(d)])
    lo = np.clip(np.arange(N) - w // 2, 0, N - w)
    sx = cs[lo + w] - cs[lo]
    sd = cd[lo + w] - cd[lo]
    lim = np.where(sd > 0, chi2.isf(prob, np.maximum(sd, 1.0)), np.inf)
    return sx > lim


@dataclass(frozen=True)
class EBMResult:
    """Result of :func:`smooth_flight` (SI units, radians; state order STATE_NAMES).

    t_s (N,) [s]; x_smooth, sigma_smooth, x_filter, sigma_filter (N,21);
    nis_filter, nis_smoother (N,) (NaN where no update), nis_dof (N,) channels
    used; mean_nis_filter, mean_nis_smoother; nis_band (low, high) for the mean
    (module doc); mean_residual_r: mean of e' R^-1 e of the smoothed residuals
    (the seed-style smoother statistic, below dof by construction).
    R_sigma (6,): noise sigma used in the final pass [m/s^2, rad/s];
    R_sigma_dispersion, R_sigma_seed_rule (6,): robust dispersion estimate and the
    seed's (Delta y / 3) rule; R_sigma_white_floor (6,): the white-noise sigma near
    Nyquist (aerosid.estimation.init.NoiseDispersion.sigma_floor: far below the
    dispersion when the recorded signal was low-pass filtered).  q_chain (6,): chain white-noise intensities used
    (X, Y, Z [m^2/s^9], L, M, N [rad^2/s^9]); Q_diag (21,): diagonal of the
    discrete Q; f_band_hz (6,): signal band edges found per chain; x0, P0_diag.
    gate_flags, used (N,6) bool; chan_nis_filter, chan_nis_smoother (6,) per
    channel mean of the standardised (conditional / smoothed) residual squares.
    tuning_history: tuple of TuningRecord; diverged, divergence_samples.
    angacc, angacc_sigma (N,3): smoothed p', q', r' [rad/s^2] and sigma.
    """

    t_s: np.ndarray
    x_smooth: np.ndarray
    sigma_smooth: np.ndarray
    x_filter: np.ndarray
    sigma_filter: np.ndarray
    nis_filter: np.ndarray
    nis_smoother: np.ndarray
    nis_dof: np.ndarray
    mean_nis_filter: float
    mean_nis_smoother: float
    nis_band: tuple
    mean_residual_r: float
    R_sigma: np.ndarray
    R_sigma_dispersion: np.ndarray
    R_sigma_seed_rule: np.ndarray
    q_chain: np.ndarray
    Q_diag: np.ndarray
    f_band_hz: np.ndarray
    x0: np.ndarray
    P0_diag: np.ndarray
    gate_flags: np.ndarray
    used: np.ndarray
    chan_nis_filter: np.ndarray
    chan_nis_smoother: np.ndarray
    tuning_history: tuple
    diverged: bool
    divergence_samples: np.ndarray
    angacc: np.ndarray
    angacc_sigma: np.ndarray
    state_names: tuple = field(default=STATE_NAMES)
    innovation_sq: np.ndarray | None = None  # (N,6) filter v^2/s per channel tested (gated too), NaN if not
    q_local: np.ndarray | None = None  # (N,6) the chains' local process-noise multipliers (None: stationary)
    meas_names: tuple = field(default=MEAS_NAMES)
    R_sigma_white_floor: np.ndarray | None = None

    def whiteness(self) -> np.ndarray:
        """(6,) dispersion sigma / white floor per channel: about 1 for white noise, NaN if unknown."""
        if self.R_sigma_white_floor is None:
            return np.full(len(self.meas_names), np.nan)
        floor = np.asarray(self.R_sigma_white_floor, float)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(floor > 0, np.asarray(self.R_sigma_dispersion, float) / floor, np.nan)

    def angular_acceleration(self) -> tuple[np.ndarray, np.ndarray]:
        """(p', q', r') [rad/s^2] (N,3) at the smoothed state through the Euler
        equations, and their 1-sigma (N,3) from the smoothed covariance (linearised)."""
        return self.angacc, self.angacc_sigma

    def summary(self) -> str:
        lo, hi = self.nis_band
        lines = ["EBM filter + MBF smoother",
                 f"samples {self.t_s.size}, updates {int(np.count_nonzero(self.nis_dof))}, "
                 f"gated channel-samples {int(self.gate_flags.sum())}, diverged {self.diverged}",
                 "",
                 f"{'channel':<8}{'unit':<7}{'sigma used':>11}{'dispersion':>11}{'seed dy/3':>11}"
                 f"{'white floor':>12}{'NIS EKF':>9}{'NIS smoother':>13}"]
        floor = (np.full(len(MEAS_NAMES), np.nan) if self.R_sigma_white_floor is None
                 else self.R_sigma_white_floor)
        for j, name in enumerate(MEAS_NAMES):
            lines.append(f"{name:<8}{MEAS_UNITS[j]:<7}{self.R_sigma[j]:11.4g}{self.R_sigma_dispersion[j]:11.4g}"
                         f"{self.R_sigma_seed_rule[j]:11.4g}{floor[j]:12.4g}{self.chan_nis_filter[j]:9.3f}"
                         f"{self.chan_nis_smoother[j]:13.3f}")
        lines += [f"{'total':<8}{'':<7}{'':>11}{'':>11}{'':>11}{'':>12}{self.mean_nis_filter:9.3f}"
                  f"{self.mean_nis_smoother:13.3f}",
                  f"chi-square band for the mean NIS: [{lo:.3f}, {hi:.3f}]; smoother e'R^-1e mean "
                  f"{self.mean_residual_r:.3f}",
                  "",
                  f"{'iter':>4}{'q_scale':>12}{'r_scale (per channel)':>40}{'NIS EKF':>9}{'NIS smoother':>13}"]
        for rec in self.tuning_history:
            rs = " ".join(f"{v:.3f}" for v in rec.r_scale)
            lines.append(f"{rec.iteration:4d}{rec.q_scale:12.4g}{rs:>40}{rec.mean_nis_filter:9.3f}"
                         f"{rec.mean_nis_smoother:13.3f}")
        lines += ["", f"{'state':<6}{'q chain':>12}{'median sigma filter':>21}{'median sigma smoother':>23}"]
        for i, name in enumerate(STATE_NAMES):
            qs = f"{self.q_chain[(i - 3) // 3]:12.4g}" if i >= 3 and (i - 3) % 3 == 0 else f"{'':12}"
            lines.append(f"{name:<6}{qs}{np.median(self.sigma_filter[:, i]):21.4g}"
                         f"{np.median(self.sigma_smooth[:, i]):23.4g}")
        return "\n".join(lines)


def _fill(t, y, ok):
    out = y.copy()
    if ok.all():
        return out
    if not ok.any():
        raise ValueError("a channel has no valid sample")
    out[~ok] = np.interp(t[~ok], t[ok], y[ok])
    return out


def check_noise_band(dt_s: float, f_max_hz: float) -> None:
    """ValueError unless the record's Nyquist frequency 0.5/dt_s [Hz] is above f_max_hz [Hz],
    the frequency above which each channel's noise is measured (method.md §4): at 5 Hz the band
    is empty, R came out zero and the filter broke down."""
    if f_max_hz >= 0.5 / dt_s:
        raise ValueError(
            f"the record's Nyquist frequency {0.5 / dt_s:.3g} Hz ({1 / dt_s:.3g} Hz sampling) is not above "
            f"[estimation] f_max_hz = {f_max_hz:g} Hz, above which each channel's noise is measured (method.md §4): "
            "at this rate there is no band to measure it in, and the filter would take the sensors as noiseless. A "
            "faster record is the remedy; a lower f_max_hz lets the filter run but counts the vehicle's motion as "
            "noise (c182 at 5 Hz with 1.5 Hz: C_m,delta -28 %, C_n,beta -61 %, outside their intervals)")


def smooth_flight(t_s, z, valid, inertia_kg_m2, sensor_offset_m, z_filled=None,
                  options: EBMOptions | None = None, q_local=None, gate_off=None) -> EBMResult:
    """Estimation Before Modeling state estimation of one flight segment.

    t_s (N,) uniform time grid [s]; z (N,6) measurements ax, ay, az [m/s^2],
    p, q, r [rad/s] (NaN allowed where invalid); valid (N,6) bool (False: the
    channel is not used at that sample; the filter predicts through and updates
    with the valid subset); inertia_kg_m2 (Ixx, Iyy, Izz, Ixz) [kg m^2];
    sensor_offset_m accelerometer position relative to the CG [m, body axes];
    z_filled: optional gap-filled copy for the spectra (default: linear
    interpolation over the valid samples); options: EBMOptions; q_local: None or (N,6)
    multipliers of the chains' intensities per sample (time-varying process noise,
    aerosid.estimation.local_q; all ones is the stationary filter bit for bit); gate_off:
    None or (N,) bool, samples where the innovation gate is lifted (local_q: the spans of
    manoeuvres the model could not follow).
    """
    opt = options or EBMOptions()
    t_s = np.asarray(t_s, dtype=float)
    z = np.asarray(z, dtype=float)
    valid = np.asarray(valid, dtype=bool)
    N = t_s.size
    if z.shape != (N, N_MEAS) or valid.shape != (N, N_MEAS):
        raise ValueError(f"z and valid must be ({N}, 6), got {z.shape} and {valid.shape}")
    if N < 16:
        raise ValueError("smooth_flight needs at least 16 samples")
    d = np.diff(t_s)
    dt = float(np.median(d))
    if not (dt > 0 and np.allclose(d, dt, rtol=1e-6, atol=1e-9 * dt)):
        raise ValueError("t_s must be a uniform, increasing grid")
    check_noise_band(dt, opt.f_max_hz)
    cand = valid & np.isfinite(z)
    model = PlantModel(tuple(float(v) for v in inertia_kg_m2), tuple(float(v) for v in sensor_offset_m), dt)
    if z_filled is None:
        zf = np.column_stack([_fill(t_s, z[:, j], cand[:, j]) for j in range(N_MEAS)])
    else:
        zf = np.asarray(z_filled, dtype=float)

    # R from dispersion (§4)
    disp = [measurement_noise_from_dispersion(zf[:, j], dt, opt.f_max_hz, valid=cand[:, j]) for j in range(N_MEAS)]
    sig_disp = np.array([dd.sigma for dd in disp])
    sig_seed = np.array([dd.sigma_seed for dd in disp])
    sig_floor = np.array([dd.sigma_floor for dd in disp])
    R0 = sig_disp**2

    # Q from the spectrum (§3)
    Binv = np.linalg.solve(model.input_matrix, np.eye(3))
    q_chain0 = np.zeros(6)
    fband = np.zeros(6)
    ms3 = np.zeros(3)
    for i in range(3):
        sp = process_noise_from_spectrum(zf[:, i], dt, opt.f_max_hz, 3, sig_disp[i], opt.spectrum_kappa)
        q_chain0[i], fband[i] = sp.q, sp.f_max_hz
    spg = [process_noise_from_spectrum(zf[:, 3 + i], dt, opt.f_max_hz, 4, sig_disp[3 + i], opt.spectrum_kappa)
           for i in range(3)]
    for i in range(3):
        # L''' = (B^-1 omega'''')_i, the rates' spectra taken as uncorrelated
        q_chain0[3 + i] = float(sum(Binv[i, j] ** 2 * spg[j].q for j in range(3)))
        ms3[i] = float(sum(Binv[i, j] ** 2 * spg[j].ms_derivative for j in range(3)))
        fband[3 + i] = spg[i].f_max_hz
    q_chain0 = q_chain0 * np.asarray(opt.q_chain_scale, dtype=float)
    x0, P0, _ = initial_state(t_s, z, cand, model, sig_disp, l3_var=ms3)

    gate = chi2.isf(opt.gate_probability, 1) if opt.gate_probability else np.inf
    n_hold = 0 if opt.gyro_gate_hold_s is None else max(1, int(round(opt.gyro_gate_hold_s / dt)))
    hold = np.array([0, 0, 0, n_hold, n_hold, n_hold], np.int64)  # accelerometers: no limit
    q_scale = float(opt.q_scale)
    r_fac = np.broadcast_to(np.asarray(opt.r_scale, dtype=float), (N_MEAS,)).copy()  # one, or per channel
    history = []
    prev = None
    lo_q, hi_q = 0.0, np.inf

    def one(qs, rf):
        Qd = discrete_process_noise(q_chain0 * qs, model)
        shares = None if q_local is None else chain_shares(q_chain0 * qs, model)
        return run_filter_smoother(z, cand, x0, P0, model, Qd, R0 * rf, gate, opt.use_numba,
                                   opt.segment_length, q_local, shares, gate_off, hold), Qd

    n_iter = max(1, int(opt.max_tuning_iterations)) if opt.auto_tune else 1
    good = None  # the last iteration whose smoother output is finite
    for it in range(n_iter):
        run, Qd = one(q_scale, r_fac)
        target, lo, hi = chi2_band(run.dof)
        mf = float(np.nanmean(run.nis_filter))
        ms = float(np.nanmean(run.nis_smoother))
        history.append(TuningRecord(it, q_scale, tuple(float(v) for v in r_fac), mf, ms))
        finite = math.isfinite(mf) and math.isfinite(ms) and bool(np.all(np.isfinite(run.x_smooth)))
        if not finite and good is not None:
            # a tuning step drove the smoother to a numerical failure: keep the last finite iteration
            run, Qd, q_scale, r_fac = good
            break
        good = (run, Qd, q_scale, r_fac)
        if not opt.auto_tune or not finite:
            break
        tol = opt.nis_tolerance * (hi - lo) / 2.0
        r_new = r_fac
        if opt.tune_r:
            em = np.where(np.isfinite(run.em_R) & (run.em_R > 0), run.em_R / R0, r_fac)
            r_new = np.clip(em, 0.25, 4.0)
        r_change = float(np.max(np.abs(r_new / r_fac - 1.0)))
        if abs(mf - target) <= tol and r_change < 0.01:
            break
        if it == n_iter - 1:
            break
        # NIS decreases with q_scale: keep a bracket, secant in log-log
        err = math.log(mf / target)
        if err > 0:
            lo_q = max(lo_q, q_scale)
        else:
            hi_q = min(hi_q, q_scale)
        slope = -0.5
        if prev is not None and prev[0] != q_scale and r_change < 0.01:
            s = (err - prev[1]) / (math.log(q_scale) - math.log(prev[0]))
            if s < -1e-3:
                slope = s
        prev = (q_scale, err)
        step = math.exp(float(np.clip(-err / slope, -math.log(100.0), math.log(100.0))))
        q_new = q_scale * step
        if lo_q > 0 and hi_q < np.inf and not (lo_q < q_new < hi_q):
            q_new = math.sqrt(lo_q * hi_q)
        q_new = float(np.clip(q_new, *opt.q_scale_bounds))
        if q_new == q_scale and r_change < 0.01:  # Q at a bound and R settled: stop
            break
        q_scale = q_new
        r_fac = r_new

    target, lo, hi = chi2_band(run.dof)
    R_used = R0 * r_fac
    win = int(round(opt.divergence_window_s / dt))
    dflag = divergence_flags(run.nis_filter, run.dof, win, opt.divergence_probability)
    div_idx = np.flatnonzero(dflag)
    with np.errstate(invalid="ignore", divide="ignore"):
        cnt = run.chan_count
        cf = run.chan_nis_filter / cnt
        cs = run.chan_nis_smoother / cnt
    # seed-style e' R^-1 e of the smoothed residuals
    zz = np.where(run.used, z, 0.0)
    hs = measure_many(run.x_smooth, model)
    res_r = np.where(run.used, (zz - hs) ** 2 / R_used, 0.0).sum(axis=1)
    has = run.dof > 0
    return EBMResult(
        t_s=t_s, x_smooth=run.x_smooth, sigma_smooth=run.sigma_smooth, x_filter=run.x_filter,
        sigma_filter=run.sigma_filter, nis_filter=run.nis_filter, nis_smoother=run.nis_smoother,
        nis_dof=run.dof, mean_nis_filter=float(np.nanmean(run.nis_filter)),
        mean_nis_smoother=float(np.nanmean(run.nis_smoother)), nis_band=(lo, hi),
        mean_residual_r=float(res_r[has].mean()) if has.any() else float("nan"),
        R_sigma=np.sqrt(R_used), R_sigma_dispersion=sig_disp, R_sigma_seed_rule=sig_seed,
        q_chain=q_chain0 * q_scale, Q_diag=np.diag(Qd).copy(), f_band_hz=fband, x0=x0,
        P0_diag=np.diag(P0).copy(), gate_flags=run.gated, used=run.used, chan_nis_filter=cf,
        chan_nis_smoother=cs, tuning_history=tuple(history),
        diverged=_diverged(dflag, run, dt, opt), divergence_samples=div_idx,
        angacc=run.angacc, angacc_sigma=run.angacc_sigma, innovation_sq=run.innovation_sq,
        q_local=None if q_local is None else np.asarray(q_local, float), R_sigma_white_floor=sig_floor)
