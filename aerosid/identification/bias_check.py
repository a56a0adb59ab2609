"""The estimator's own bias at this flight's noise: a parametric check, counted in the sigma.

Why.  The regressors carry the sensors' noise: the vanes' in alpha and beta (and in alpha-dot,
their derivative), the gyros' in p, q, r and the surfaces' in the controls.  SIMEX
(aerosid.identification.eiv) corrects the angles' and the surfaces' parts (the latter since
2026-11-28, identify's control_eiv) by extrapolating to no noise.  Where the noise is a large share
of a regressor it under-corrects (its quadratic extrapolant saturates), and the rates' part is
corrected only in the channels that read no angle rate (identify's gyro_eiv="auto").  The reported sigma know none of this.  Measured on seven JSBSim aircraft the project had never flown (five seeds each,
bench/results/generalisation_unseen3.md): Boeing314 C_m,delta -13 % with 40 % coverage, the
minisgs model glider C_l,p -11 % with 0 % (its roll mode is so fast that p follows the aileron,
VIF 114, and the surfaces' 0.05 deg of noise alone moves C_l,p by 7 %).

What.  A parametric bootstrap of the whole fit, on the flight itself:

1. the bootstrap world's truth is this flight's own regressors and the SIMEX-corrected estimates:
   its response is X theta + (y - X theta_OLS), the model's part with those coefficients plus
   the flight's own least-squares residual (orthogonal to X); for an instrumental-variable fit
   (turbulent air, aerosid.identification.instrumental) its own residual, i.e. the flight's y;
2. every regressor noise the flight data carry a sigma for is drawn again and added through the
   low-pass the measured signal went through (sensor_noise): the angles' (as SIMEX takes them),
   the gyros' (eiv_sigma_p/q/r_rad_s) and the surfaces' (eiv_sigma_delta_*_rad, the mixed
   controls'); the response keeps the flight's own residual (its noise is not drawn again);
3. the same estimator is run on it (least squares and SIMEX with the same draws), once with +noise
   and once with -noise: the change that is odd in the noise (the draw's own scatter) cancels in
   the pair's mean, the bias is even in it.  The pitch-damping prior and the model-structure
   mixture are left out: the world's coefficients are the estimator's before them, and a prior
   applied again to a world that holds it would count as bias;
4. over PAIRS pairs the mean change b of every estimate is the estimator's bias in that world,
   and the spread s of the pairs' means its Monte-Carlo error.

The bias is NOT subtracted: the bootstrap world's regressors are noisier than the real ones (they
carry the real noise as if it were signal), and on pogo-jsbsim, whose estimates are accurate, the
correction added +6 % to C_m,alpha.  It is counted in the reported (posterior) sigma as a possible
systematic error: the covariance takes b_s b_s^T, b_s = b sqrt(max(1 - s^2 / (PAIRS b^2), 0)) (b^2 less its own
Monte-Carlo variance, so a bias that is only noise adds little).  A flight whose noise is small
next to its excitation gets almost nothing; the warnings name the estimates whose sigma it moves by
more than NAMED_GROWTH (5 %).  Part of what it measures, SIMEX's under-correction of a large
attenuation, is also in SIMEX's own sigma (a share of the correction, eiv.CORRECTION_SHARE, since
2026-11-27): the two add in quadrature, so where both are large the sigma can count that part
up to twice (at most a factor sqrt(2)); kept, as the check does not see the under-correction on
every flight (F4N's C_m_alpha) and the correction's term does not see the gyros' (nor, before
2026-11-28, the surfaces').
Where a prior follows (C_m of an aircraft), counting b in full is conservative: the prior passes
only part of the pre-prior estimator's bias into its posterior.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd

from aerosid.identification.band import segment_keys
from aerosid.identification.eiv import angle_noise, filtered_noise, with_angles_moved
from aerosid.identification.instrumental import METHOD as INSTRUMENTAL
from aerosid.identification.regression import LinearFit, with_added_covariance

#: Seed of the re-draws (the check is reproducible).
SEED = 20261127
#: The flight-data columns whose white noise (the column eiv_sigma_<name>) is drawn again.
NOISY_COLUMNS = ("p_rad_s", "q_rad_s", "r_rad_s", "delta_p_rad", "delta_y_rad", "delta_r_rad")
#: A coefficient whose sigma the check moves by more than this factor is named in the warnings.
NAMED_GROWTH = 1.05


@dataclass(frozen=True)
class EstimatorBias:
    """One channel's check: ``bias`` (k,) the mean change of the estimates over the re-draws,
    ``spread`` (k,) the standard deviation of the pairs' mean changes, ``pairs`` how many."""

    names: tuple[str, ...]
    bias: np.ndarray
    spread: np.ndarray
    pairs: int

    @property
    def counted(self) -> np.ndarray:
        """The part counted in the sigma: the bias less its own Monte-Carlo variance (>= 0)."""
        b = np.nan_to_num(np.asarray(self.bias, float))
        s2 = np.nan_to_num(np.asarray(self.spread, float)) ** 2 / max(self.pairs, 1)
        with np.errstate(divide="ignore", invalid="ignore"):
            keep = np.where(b != 0, np.sqrt(np.clip(1.0 - s2 / b ** 2, 0.0, None)), 0.0)
        return b * keep

    def summary(self, estimate: np.ndarray | None = None) -> str:
        """'Cm_alpha +2.1 % +- 0.4 %, ...': the measured bias b (before its Monte-Carlo variance
        is taken off) and its Monte-Carlo sigma, in % of the estimate when given (else as numbers)."""
        parts = []
        for j, name in enumerate(self.names):
            b, s = float(self.bias[j]), float(self.spread[j]) / np.sqrt(max(self.pairs, 1))
            if estimate is not None and np.isfinite(estimate[j]) and estimate[j] != 0:
                parts.append(f"{name} {100 * b / abs(estimate[j]):+.1f} % +- {100 * s / abs(estimate[j]):.1f} %")
            else:
                parts.append(f"{name} {b:+.3g} +- {s:.2g}")
        return ", ".join(parts)


def sensor_noise(fd: pd.DataFrame, rng: np.random.Generator, angle_sigma, angle_cutoff_hz) -> dict[str, np.ndarray]:
    """One draw of the sensors' known noise, {column: noise}: the angles' (angle_sigma
    (sigma_alpha, sigma_beta) [rad], None: none; through angle_cutoff_hz [Hz], None: white) and,
    where the frame has eiv_sigma_<column> and a finite band_hz, each NOISY_COLUMNS column's
    through the band (as SIMEX draws them, aerosid.identification.eiv)."""
    groups = segment_keys(fd)
    t = fd["t_s"].to_numpy(float)
    out = {}
    if angle_sigma is not None:
        out["alpha_rad"], out["beta_rad"] = angle_noise(rng, groups, t, tuple(angle_sigma), angle_cutoff_hz)
    band = fd["band_hz"].to_numpy(float) if "band_hz" in fd.columns else None
    if band is None or not np.all(np.isfinite(band)):
        return out
    for col in NOISY_COLUMNS:
        sig = f"eiv_sigma_{col}"
        if col in fd.columns and sig in fd.columns:
            sigma = np.nan_to_num(fd[sig].to_numpy(float))
            if np.any(sigma > 0):
                out[col] = filtered_noise(rng, groups, t, sigma, band)
    return out


def with_noise(fd: pd.DataFrame, noise: dict[str, np.ndarray], sign: float = 1.0) -> pd.DataFrame:
    """A copy of the flight data with sign * noise added (alpha_r, phi_r follow the angles)."""
    angles = "alpha_rad" in noise or "beta_rad" in noise
    f = (with_angles_moved(fd, sign * noise.get("alpha_rad", 0.0), sign * noise.get("beta_rad", 0.0)) if angles
         else fd.copy())
    for col, n in noise.items():
        if col not in ("alpha_rad", "beta_rad"):
            f[col] = f[col].to_numpy(float) + sign * n
    return f


def estimator_bias(fd: pd.DataFrame, regressors: Callable[[pd.DataFrame], dict[str, np.ndarray]],
                   fits: dict[str, LinearFit], refit: Callable[[pd.DataFrame], dict[str, LinearFit]],
                   angle_sigma, angle_cutoff_hz, pairs: int, seed: int = SEED) -> dict[str, EstimatorBias]:
    """{channel: EstimatorBias} of the channels in ``fits`` whose estimates, regressors and response
    are all finite (a fit that left rows out is not checked).

    fd: the fit's flight data (sorted and windowed as fitted); regressors: frame -> {channel: (n, k)
    regressor matrix}; fits: the estimator's fits, whose estimates are the world's coefficients;
    refit: frame -> {channel: LinearFit}, the same estimator with the same SIMEX draws (common random numbers: SIMEX's own Monte-Carlo error then
    cancels in the change); angle_sigma, angle_cutoff_hz: the angles' noise as SIMEX takes it
    (None: exact).  Each of the ``pairs`` draws is used twice, as +noise and -noise (antithetic: the
    change that is odd in the noise, the draw's own scatter, cancels in the pair's mean; the bias is
    even in it)."""
    if pairs < 2:
        raise ValueError(f"pairs = {pairs}: at least 2 (the bias's Monte-Carlo error is their spread)")
    X = regressors(fd)
    world = fd.copy()
    chans = [ch for ch, fit in fits.items() if ch in X and np.all(np.isfinite(fit.estimate))
             and np.all(np.isfinite(X[ch])) and np.all(np.isfinite(fd[ch].to_numpy(float)))]
    for ch in chans:
        if getattr(fits[ch], "method", "") == INSTRUMENTAL:  # its own residual: the world is the flight's response itself
            continue
        y = fd[ch].to_numpy(float)
        ols = np.linalg.lstsq(X[ch], y, rcond=None)[0]
        world[ch] = X[ch] @ np.asarray(fits[ch].estimate, float) + (y - X[ch] @ ols)
    changes = {ch: [] for ch in chans}
    for b in range(pairs):
        noise = sensor_noise(world, np.random.default_rng([seed, b]), angle_sigma, angle_cutoff_hz)
        both = [refit(with_noise(world, noise, sign)) for sign in (1.0, -1.0)]
        for ch in chans:
            mean = 0.5 * (np.asarray(both[0][ch].estimate, float) + np.asarray(both[1][ch].estimate, float))
            changes[ch].append(mean - np.asarray(fits[ch].estimate, float))
    out = {}
    for ch in chans:
        D = np.array(changes[ch])
        spread = D.std(axis=0, ddof=1)
        out[ch] = EstimatorBias(tuple(fits[ch].names), D.mean(axis=0), spread, pairs)
    return out


def with_bias_counted(fit: LinearFit, check: EstimatorBias) -> LinearFit:
    """The fit with the check's counted bias added to its covariance (outer product: a combination
    such as C_m,q + C_m,alpha_dot takes the bias of the sum) and, where it moves a sigma by more
    than NAMED_GROWTH, a warning naming those estimates with the measured bias (no warning else:
    the run's parameters record that the check ran)."""
    b = check.counted
    extra = np.outer(b, b)
    se_new = np.sqrt(np.clip(np.diag(np.asarray(fit.cov, float) + extra), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        grown = [j for j in range(len(b)) if se_new[j] > NAMED_GROWTH * fit.std_error[j]]
    if not grown:
        return with_added_covariance(fit, extra, "")
    sub = EstimatorBias(tuple(check.names[j] for j in grown), check.bias[grown], check.spread[grown], check.pairs)
    note = (f"the estimator's own bias at this flight's noise (aerosid.identification.bias_check: the flight's "
            f"regressors taken as the truth, the sensors' known noise drawn again in {check.pairs} +/- pairs, "
            f"the fit repeated): {sub.summary(np.asarray(fit.estimate)[grown])}; counted in sigma, less its "
            "Monte-Carlo variance (a systematic error the residuals do not show: a larger manoeuvre, or less "
            "noisy sensors, shrink it)")
    return with_added_covariance(fit, extra, note)


def with_estimator_bias(fd: pd.DataFrame, vehicle, models: dict, corrected: dict[str, LinearFit],
                        fits: dict[str, LinearFit], refit: Callable[[pd.DataFrame], dict[str, LinearFit]],
                        pairs: int, skip: tuple[str, ...] = ()) -> dict[str, LinearFit]:
    """``fits`` with the check counted (with_bias_counted).  The check runs on the estimator that
    gave ``corrected`` (refit: frame -> the same fits), whose estimates are the world's
    coefficients; ``fits`` are the reported fits built on them (the prior and the model-structure
    mixture, which the check leaves out: a prior applied to a world whose coefficients already hold
    it would count as bias).  Channels in ``skip`` (identities by construction) and channels the
    check cannot run on (estimator_bias) are left as they are."""
    from aerosid.identification.eiv_fit import angle_cutoff_hz, angle_eiv_sigma
    from aerosid.modelling.models import vehicle_signals

    def regressors(frame: pd.DataFrame) -> dict[str, np.ndarray]:
        sig = vehicle_signals(frame, vehicle)
        return {ch: models[ch].regressors(sig).to_numpy(float) for ch in corrected if ch not in skip}

    checks = estimator_bias(fd, regressors, {ch: f for ch, f in corrected.items() if ch not in skip}, refit,
                            angle_eiv_sigma(fd, vehicle), angle_cutoff_hz(fd, vehicle), pairs)
    return {ch: with_bias_counted(f, checks[ch]) if ch in checks else f for ch, f in fits.items()}
