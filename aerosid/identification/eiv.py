"""Errors in the regressors: SIMEX correction for the noise in the angles, the body rates and the controls.

With alpha and beta read from vanes, the regressors carry the vanes' noise (after the
vane low-pass) and so do the signals derived from them (alpha-dot, beta-dot, alpha_r,
phi_r). Least squares then attenuates the angle terms. The alpha-dot term suffers
most, and what it loses shifts into the terms it correlates with (C_m_alpha). On the
JSBSim c172x flight this moved C_m_alpha by about -6 %.

SIMEX (Cook & Stefanski 1994) measures the attenuation on the data themselves. It
refits with extra noise of variance lambda sigma^2 added to the raw vane angles,
passed through the same low-pass as the vanes, with every derived signal
recomputed. It does so for lambda in LAMBDAS_BY_SOURCE (0.25..1 for vanes, 0.5..2 for inverted
angles), averaging REPLICATES refits each (REPLICATES / 2 draws in antithetic pairs, common to
every lambda: :func:`simex_frames`), then extrapolates each coefficient to lambda = -1, no
noise at all (:func:`extrapolate`).

The corrected estimates replace the naive ones. Their sigma is the coloured-residual
sigma of the naive fit scaled by the correction factor, combined with the extrapolation's
own error (SimexResult.std_error): without them the intervals of the de-attenuated slopes
covered 62 % on seed-rlv (band-limited flight data, angles inverted from the accelerometers).
That error is the larger of the spread between the quadratic and the linear extrapolant and
a share of the correction itself (CORRECTION_SHARE: 1 for vane angles, 0.6 for angles
inverted from the force database): where the noise is a large share of a regressor
(alpha-dot above all) the quadratic takes back only part of the attenuation of the vanes'
angles (from a few % to all of it by flight, bench/results/eiv_extrapolants.md), and leaves or overshoots less
of the inverted angles'. The draws are seeded, so the result is reproducible.

The gyros. The band-limited rates p, q, r (aerosid.identification.band) are the measured gyros
through the common low-pass, so they carry the gyros' white noise through that low-pass, and so
do q_hat, p_hat, r_hat. Replacing only the rates by the band-limited truth moved C_m_alpha by
F4N +6.3 %, OV10 +1.4 %, pa28 +1.1 % (bench/results/attribution_notes.md, finding 3). The same
draws therefore also add noise of variance lambda sigma_g^2 to p, q, r through the same low-pass
(the flight data's band_hz), where sigma_g is the flight data's eiv_sigma_p/q/r_rad_s: the
measurement noise the run's filter used for the gyros (R, from the noise dispersion above the
signal band, aerosid.estimation.init). On the simulators it was within 4.5 % of the noise
actually added, against 9 % for the band module's first-difference estimate. Only the
regressors get the noise; the response is left alone. Its noise (the derivative of the
band-limited gyro noise) has no correlation with the rates' noise at zero lag, and it costs
<= 0.4 % (finding 4). The rates' draws come from their own generator. Without gyro noise
(identify(gyro_eiv=False), or flight data without or with zero eiv_sigma_p/q/r), the result is
bit-identical to the angle-only correction (tested).  identify's default (gyro_eiv="auto") adds
it only to the channels whose model reads no angle rate (eiv_fit.angle_rate_free_channels).

The controls. The mixed controls in the band-limited flight data carry the surfaces' white noise
through the same low-pass (the flight data's eiv_sigma_delta_p/y/r_rad, measured from the fins'
second differences; zero for quantised or held surfaces).  The same draws add noise of variance
lambda sigma_d^2 to them (CONTROL_COLUMNS, their own generator).  A small share of a control's
variance can still bias a fit a lot where the control and a state nearly cancel: on the minisgs
model glider p follows the aileron through a fast roll mode, and the aileron's 0.05 deg noise
(0.4 % of its variance in the band) put C_l_p and C_l_delta 8-15 % low; the true controls in its
place leave 0.4-7.8 %, the correction 2-10 % (2 cached flights; docs/estimation.md, "Errors in the
controls").  identify does it by default (control_eiv).

The information. The same draws average X^T X at each lambda; extrapolated to lambda = -1 by a
line (:func:`noise_free_gram`: exact for columns linear in the noise; the others, found by their
sums moving with lambda, are left out) it is the regressors' noise-free information, and its
ratio to the naive X^T X along a direction (:func:`information_reliability`) says how much of
what the flight seems to know there is noise.  identify uses it for the pitch-damping split
(aerosid.identification.damping_prior), where a noisy alpha_dot_hat makes the split look
determined.

The draws. Every draw, the angles', the rates' and the controls', is a common random number across lambda and
comes in an antithetic pair (:func:`simex_frames`): pair k adds the same noise, times +sqrt(lambda)
and -sqrt(lambda), at every lambda. With independent draws the Monte-Carlo error of 40 replicates
passed for a curvature the quadratic amplified: the rates' part moved OV10's C_m_alpha by -3.8 %
where the gyro noise makes -1.4 %, and the angles' part made the corrected F4N C_n_r depend on the
draws' seed by 14 % (bench/results/simex_mc.md).

Measured on 10 cached JSBSim flights each (bench/results/gyro_simex.md, at the usual levels
0.5..2, before the vanes' 0.25..1; mean error % of the truth). The gyro part moves C_m_alpha
toward the answer with the true rates: the rates-true-minus-flight difference against the
SIMEX move is F4N -4.2 against -1.5 (with the true angles -6.2 against -5.1), OV10 -1.5 against -2.1, pa28 -0.6 against -0.6. The F4N
shortfall with the vane angles comes from the joint extrapolation. The vane noise's saturating
alpha_dot_hat (finding 2) damps the gyro effect at the flight's noise level. Against the truth,
C_m_alpha goes OV10 +3.0 -> +0.9, F4N -4.9 -> -6.5 (its oracle is itself -6.3 %), and pa28
-4.0 -> -4.6. On F4N and pa28 the alpha-dot under-correction had been partly cancelling the
gyro error.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from aerosid.identification.band import segment_keys
from aerosid.identification.derivatives import zero_phase_low_pass
from aerosid.identification.inversion import total_angles

LAMBDAS = (0.5, 1.0, 1.5, 2.0)
#: The extra-noise levels by the angles' source (the vehicle's air_data_source; identify picks
#: them, simex_lambdas).  The usual grid (LAMBDAS, 0.5..2) for angles inverted from the force
#: database; half of it (0.25..1) for vane angles, whose attenuation is larger and more curved
#: in lambda, so a quadratic through lambda <= 2 flattens it and leaves more of it.  Chosen where
#: the answer is known, the controlled test of bench/bench_eiv_extrapolants.py (one known draw of
#: the noise SIMEX assumes added to the clean angles), 2026-11-28: on the vane aircraft the
#: median |shortfall / correction| went 1.45 -> 1.14 (above 1 in 70 -> 53 % of the 60 runs
#: attenuated by >= 3 %; SIMEX's recovery of C_m_alpha's attenuation c172p 56 -> 67 %, J3Cub
#: 37 -> 46 %, pa28 45 -> 55 %, F4N 19 -> 21 %; OV10's C_m_alpha, where the quadratic
#: overshoots a 2 % attenuation, +3.9 -> +4.3 % against +1.9 % clean); on the database angles it
#: halved the recovery of C_l_cos4phi (91 -> 47 %), so they keep the usual grid.
LAMBDAS_BY_SOURCE = {"vanes": (0.25, 0.5, 0.75, 1.0), "database": LAMBDAS}
#: One sigma of the correction's own error, as a share of the correction |corrected - naive|, by
#: the vehicle's air_data_source (where the angles come from).  Measured where the only angle
#: error is one known draw of the noise SIMEX assumes (bench/bench_eiv_extrapolants.py,
#: bench/results/eiv_extrapolants.md), over the runs the noise attenuates by >= 3 %, as
#: |shortfall / correction| = |clean - quadratic| / |quadratic - naive|:
#: "vanes" (10 JSBSim aircraft x 3 seeds, C_m, 60 runs; at the vanes' levels 0.25..1): median 1.14,
#: 68th percentile 1.61, > 1 in 53 % of the runs (1.45 / 2.26 / 70 % at the usual levels 0.5..2;
#: c172x's C_m_alpha: none left, T37's and F4N's: most); "database" (angles
#: inverted from the force database, seed-rlv x 5 seeds, C_m, C_n, C_l, 25 runs): median 0.37,
#: 68th percentile 0.48, > 1 in 8 % (with simex_frames' draws, 2026-11-28; 1.2 / 2.0 and
#: 0.38 / 0.57 with the earlier independent draws, whose Monte-Carlo error inflated the
#: corrections).  The values are round choices inside those ranges (the vanes' 1 below its
#: median: a constant cannot know the flight, and where the quadratic leaves more than about
#: twice its correction a 1.96-sigma interval still falls short -- F4N's C_m_alpha correction
#: is 0.4 % of an 8 % attenuation, which no share of it covers -- there the pitch-damping split's
#: reliability widens sigma instead, information_reliability; the estimator-bias check,
#: bias_check.py, adds its own part).  The exact extrapolant for linear columns (corrected
#: least squares) over-corrects and is unstable where the noise is a large share of alpha-dot, so
#: the estimate stays the quadratic's.
CORRECTION_SHARE = {"vanes": 1.0, "database": 0.6}
REPLICATES = 40  # refits per lambda, in antithetic pairs (even): simex_frames
if REPLICATES % 2:
    raise ValueError(f"eiv.REPLICATES must be even (antithetic pairs), not {REPLICATES}")
SEED = 20261122
#: The body-rate columns the gyro part of the correction adds noise to.
RATE_COLUMNS = ("p_rad_s", "q_rad_s", "r_rad_s")
#: The mixed-control columns the surfaces' part adds noise to (the order of control_sigma).
CONTROL_COLUMNS = ("delta_p_rad", "delta_y_rad", "delta_r_rad")


def filtered_noise(rng: np.random.Generator, groups: np.ndarray, t_s: np.ndarray, sigma,
                   cutoff_hz) -> np.ndarray:
    """White noise of 1-sigma `sigma` (a number or one per sample) through the low-pass the
    angles went through, per flight segment.  cutoff_hz: one corner [Hz] (None: white), or one
    per sample (each segment takes its median: pooled flights keep their own band)."""
    out = np.empty(len(t_s))
    sig = np.broadcast_to(np.asarray(sigma, float), (len(t_s),))
    per_sample = cutoff_hz is not None and np.ndim(cutoff_hz) > 0
    for g in pd.unique(groups):
        idx = np.flatnonzero(groups == g)
        fs = 1.0 / float(np.median(np.diff(t_s[idx]))) if idx.size > 1 else 1.0
        cut = float(np.median(np.asarray(cutoff_hz, float)[idx])) if per_sample else cutoff_hz
        out[idx] = zero_phase_low_pass(sig[idx] * rng.standard_normal(idx.size), fs, cut)
    return out


def angle_noise(rng: np.random.Generator, groups: np.ndarray, t_s: np.ndarray, sigma,
                cutoff_hz: float | None) -> tuple[np.ndarray, np.ndarray]:
    """One draw of noise for (alpha, beta) [rad]: sigma a number, arrays per sample, or a
    tuple (sigma_alpha, sigma_beta) of either; white when cutoff_hz is None (angles inverted
    from the database), else through the vanes' low-pass [Hz] (the vanes' own noise).  alpha's
    noise is drawn first (SIMEX and the estimator-bias check rely on the order)."""
    sig_a, sig_b = sigma if isinstance(sigma, tuple) else (sigma, sigma)

    def draw(sig) -> np.ndarray:
        if cutoff_hz is None:
            return np.asarray(sig, float) * rng.standard_normal(len(t_s))
        return filtered_noise(rng, groups, t_s, sig, cutoff_hz)

    da = draw(sig_a)
    return da, draw(sig_b)


def with_angles_moved(fd: pd.DataFrame, d_alpha, d_beta) -> pd.DataFrame:
    """A copy of the flight data with alpha and beta moved by d_alpha, d_beta [rad] (numbers or
    arrays per sample) and alpha_r, phi_r recomputed from them."""
    f = fd.copy()
    a = f["alpha_rad"].to_numpy(float) + d_alpha
    b = f["beta_rad"].to_numpy(float) + d_beta
    f["alpha_rad"], f["beta_rad"] = a, b
    f["alpha_r_rad"], f["phi_r_rad"] = total_angles(a, b)
    return f


def with_angle_noise(fd: pd.DataFrame, rng: np.random.Generator, groups: np.ndarray, sigma: float,
                     cutoff_hz: float | None) -> pd.DataFrame:
    """A copy of the flight data with extra noise of 1-sigma `sigma` on alpha and beta
    (angle_noise: a number, arrays per sample, or a tuple (sigma_alpha, sigma_beta) of either;
    alpha_r, phi_r recomputed): white when cutoff_hz is None (angles inverted from the
    database), else through the vanes' low-pass (the vanes' own noise)."""
    return with_angles_moved(fd, *angle_noise(rng, groups, fd["t_s"].to_numpy(float), sigma, cutoff_hz))


def column_noise(rng: np.random.Generator, groups: np.ndarray, t_s: np.ndarray, sigma: tuple,
                 cutoff_hz) -> np.ndarray:
    """(N, len(sigma)) noise for band-limited columns: sigma = one white-noise 1-sigma per column
    (numbers or arrays per sample) before the low-pass, e.g. (sigma_p, sigma_q, sigma_r) [rad/s]
    for the gyros, (sigma_delta_p, sigma_delta_y, sigma_delta_r) [rad] for the controls;
    cutoff_hz: the band the columns went through (a number, or one per sample), None: white."""
    return np.column_stack([filtered_noise(rng, groups, t_s, sig, cutoff_hz) for sig in sigma])


def with_column_noise(fd: pd.DataFrame, noise: np.ndarray, copy: bool = True,
                      columns: tuple = RATE_COLUMNS) -> pd.DataFrame:
    """The flight data with `noise` (N, len(columns)) added to ``columns`` (p, q, r; or
    CONTROL_COLUMNS), a copy unless copy=False."""
    f = fd.copy() if copy else fd
    for j, col in enumerate(columns):
        f[col] = f[col].to_numpy(float) + noise[:, j]
    return f


def simex_frames(fd: pd.DataFrame, sigma_rad, cutoff_hz: float | None, rate_sigma: tuple | None = None,
                 rate_cutoff_hz=None, seed: int = SEED, lambdas: tuple = LAMBDAS, replicates: int = REPLICATES,
                 control_sigma: tuple | None = None, control_cutoff_hz=None):
    """The remeasured flight data SIMEX refits: yields (lambda, frame) `replicates` times (even;
    REPLICATES) for each lambda in `lambdas` (LAMBDAS), the frame being ``fd`` with extra noise
    of variance lambda x sigma^2 on the angles (sigma_rad: as angle_noise; None: the angles are
    exact), given rate_sigma, on p, q, r (column_noise; None: the rates are exact) and, given
    control_sigma (sigma_delta_p, sigma_delta_y, sigma_delta_r [rad], the mixed surfaces' white
    noise before the band control_cutoff_hz), on the controls CONTROL_COLUMNS.

    The draws are antithetic common random numbers: pair k draws one unit of noise, from its own
    generator seeded (seed, k) for the angles, (seed, k, 1) for the rates and (seed, k, 2) for
    the controls, and adds
    +sqrt(lambda) and -sqrt(lambda) times it at every lambda.  So the Monte-Carlo error of the
    curve is smooth in lambda (common numbers), and within each pair the terms odd in the noise
    cancel (antithetic): with independent draws at each lambda, 40 replicates left the
    corrected F4N C_n_r depending on the draws' seed by 14 % (1 sd over three seeds), C_m_alpha
    by 0.35-0.9 %; with these 0.16 % and 0.14-0.6 % (bench/results/simex_mc.md; 0.16-0.99 % at the
    vanes' levels 0.25..1).  Without
    rate_sigma the angles' frames are the same whatever the rates' generator would draw.  The
    frames share no arrays with ``fd`` or with each other, except that ``fd`` itself is yielded
    when there is no noise to add: read them, do not write them."""
    if replicates % 2:
        raise ValueError(f"replicates must be even (antithetic pairs), not {replicates}")
    groups = segment_keys(fd)
    t = fd["t_s"].to_numpy(float)
    for k in range(replicates // 2):
        # numpy seeds [seed, k] as [seed, k, 0]: a further noise source takes the suffix 3
        d_angles = (angle_noise(np.random.default_rng([seed, k]), groups, t, sigma_rad, cutoff_hz)
                    if sigma_rad is not None else None)
        d_rates = (column_noise(np.random.default_rng([seed, k, 1]), groups, t, rate_sigma, rate_cutoff_hz)
                   if rate_sigma is not None else None)
        d_controls = (column_noise(np.random.default_rng([seed, k, 2]), groups, t, control_sigma, control_cutoff_hz)
                      if control_sigma is not None else None)
        for lam in lambdas:
            for sign in (1.0, -1.0):
                scale = sign * np.sqrt(lam)
                f = fd
                if d_angles is not None:
                    f = with_angles_moved(f, scale * d_angles[0], scale * d_angles[1])
                if d_rates is not None:
                    f = with_column_noise(f, scale * d_rates, copy=f is fd)
                if d_controls is not None:
                    f = with_column_noise(f, scale * d_controls, copy=f is fd, columns=CONTROL_COLUMNS)
                yield lam, f


def simex_estimates(fd: pd.DataFrame, y_by_channel: dict[str, np.ndarray], design, sigma_rad,
                    cutoff_hz: float | None, rate_sigma: tuple | None = None,
                    rate_cutoff_hz=None, seed: int = SEED, lambdas: tuple = LAMBDAS,
                    control_sigma: tuple | None = None, control_cutoff_hz=None) -> dict[str, "SimexResult"]:
    """Corrected coefficient vectors per channel, with their sigma's ingredients.

    fd: the flight data of the fit (sorted as fitted). y_by_channel: the responses.
    design: fd -> {channel: (n, k) regressor matrix} (the models on that frame's signals).
    sigma_rad: the vanes' raw noise 1-sigma [rad] (or (sigma_alpha, sigma_beta)), None: the
    angles are exact; cutoff_hz: the vane low-pass corner.  rate_sigma: (sigma_p, sigma_q,
    sigma_r) [rad/s] of the gyros' white noise, None: the rates are exact (the angle-only
    correction, bit-identical to it); rate_cutoff_hz: the band the rates went through (a
    number, or one per sample).  control_sigma, control_cutoff_hz: the same for the mixed
    controls (CONTROL_COLUMNS; None: the controls are exact).  Every noise is added in the same
    draws (one lambda scales every variance): :func:`simex_frames`, seeded by ``seed``, at the extra-noise levels
    ``lambdas`` (LAMBDAS; identify: LAMBDAS_BY_SOURCE).
    """
    def fit_all(X: dict) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Per channel: the estimate, X^T X and the columns' sums of the design X."""
        return {ch: (np.linalg.lstsq(X[ch], y, rcond=None)[0], X[ch].T @ X[ch], X[ch].sum(axis=0))
                for ch, y in y_by_channel.items()}

    X0 = design(fd)
    naive = fit_all(X0)
    sums = {lam: {ch: [np.zeros_like(part) for part in parts] for ch, parts in naive.items()} for lam in lambdas}
    for lam, f in simex_frames(fd, sigma_rad, cutoff_hz, rate_sigma, rate_cutoff_hz, seed, lambdas, REPLICATES,
                               control_sigma, control_cutoff_hz):
        for ch, parts in fit_all(design(f)).items():
            for acc, part in zip(sums[lam][ch], parts):
                acc += part
    lams = np.array((0.0, *lambdas))

    def curve(ch: str, i: int) -> np.ndarray:  # part i (estimate, X^T X, column sums) at every lambda
        return np.array([naive[ch][i], *(sums[lam][ch][i] / REPLICATES for lam in lambdas)])

    return {ch: SimexResult.from_curve(lams, curve(ch, 0), curve(ch, 1), curve(ch, 2), np.abs(X0[ch]).sum(axis=0))
            for ch in naive}


@dataclass(frozen=True)
class SimexResult:
    """corrected: the estimates extrapolated to no angle noise; spread: how much the answer
    depends on the extrapolant (:func:`extrapolation_spread`); naive: the uncorrected estimates.
    The extrapolation's 1-sigma is the larger of spread and a share of |corrected - naive|
    (:meth:`std_error`, CORRECTION_SHARE)."""

    corrected: np.ndarray
    spread: np.ndarray
    naive: np.ndarray
    #: X^T X of the naive fit and X^T X extrapolated to no noise (None: not given).
    gram_naive: np.ndarray | None = None
    gram_corrected: np.ndarray | None = None

    @classmethod
    def from_curve(cls, lams: np.ndarray, curve: np.ndarray, grams: np.ndarray | None = None,
                   sums: np.ndarray | None = None, abs_sums: np.ndarray | None = None) -> "SimexResult":
        """From the SIMEX curve: curve[i] the coefficient vector averaged at lams[i] (lams[0] = 0,
        the naive fit), each coefficient extrapolated to lambda = -1 (:func:`extrapolate`).
        grams (optional): X^T X averaged at each lams[i], extrapolated to lambda = -1 by a straight
        line, with the columns' averaged sums and naive sums of absolute values to find the columns
        that are not linear in the noise (:func:`noise_free_gram`)."""
        cols = range(curve.shape[1])
        gn, gc = ((None, None) if grams is None
                  else (np.array(grams[0], float), noise_free_gram(lams, grams, sums, abs_sums)))
        return cls(np.array([extrapolate(lams, curve[:, j]) for j in cols]),
                   np.array([extrapolation_spread(lams, curve[:, j]) for j in cols]), curve[0].copy(), gn, gc)

    def information(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(naive X^T X, X^T X extrapolated to no noise), read-only, or None when not given
        (LinearFit.information_eiv)."""
        if self.gram_naive is None or self.gram_corrected is None:
            return None
        out = (np.array(self.gram_naive, float), np.array(self.gram_corrected, float))
        for a in out:
            a.setflags(write=False)
        return out

    def std_error(self, naive_std_error: np.ndarray, *, correction_share: float) -> np.ndarray:
        """The corrected estimates' sigma: the naive fit's sigma scaled by the correction
        factor |corrected / naive| (kept within [1, 3]: a de-attenuated slope carries its
        relative uncertainty along), combined with the extrapolation's own error: the larger of
        its spread and correction_share x the correction |corrected - naive| (the quadratic
        leaves a part of a large attenuation: CORRECTION_SHARE, by the angles' source)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.clip(np.nan_to_num(np.abs(self.corrected / self.naive), nan=1.0, posinf=3.0), 1.0, 3.0)
        correction = np.abs(np.asarray(self.corrected, float) - np.asarray(self.naive, float))
        own = np.maximum(self.spread, correction_share * np.where(np.isnan(correction), 0.0, correction))
        return np.hypot(np.asarray(naive_std_error, float) * ratio, own)


#: A column whose averaged sum moves with lambda by more than this share of its sum of absolute
#: values is not linear in the noise (abs(beta), alpha_r ...): noise_free_gram leaves it out.
GRAM_LINEARITY_TOL = 1e-9


def noise_free_gram(lams: np.ndarray, grams: np.ndarray, sums: np.ndarray | None = None,
                    abs_sums: np.ndarray | None = None) -> np.ndarray:
    """X^T X extrapolated to lambda = -1 (no noise) by a least-squares line through its
    averages at ``lams`` (lams[0] = 0, grams[0] the naive X^T X).  A column linear in the noise,
    x + s n, averaged over an antithetic pair (s = +-sqrt lambda) has (x + s n)^T (x + s n) =
    x^T x + lambda n^T n, exactly a line in lambda, so its entries are extrapolated without error
    of their own (in expectation over the flight's own noise).  Such a column's pair-averaged sum
    is exactly constant in lambda; given ``sums`` (the columns' sums averaged at each lambda) and
    ``abs_sums`` (the naive columns' sums of absolute values, the rounding scale), a column whose
    sum moves by more than GRAM_LINEARITY_TOL x abs_sums is not linear in the noise (abs(beta)
    near beta = 0) and its row and column are NaN: its noise cannot be taken out by a line, and
    keeping its naive products next to corrected ones can make the matrix indefinite.  The
    information measures below leave such columns out."""
    lams = np.asarray(lams, float)
    g = np.asarray(grams, float)
    k = g.shape[1]
    line = np.vander(lams, 2)
    coef = np.linalg.lstsq(line, g.reshape(len(lams), -1), rcond=None)[0]
    out = (np.array([-1.0, 1.0]) @ coef).reshape(k, k)
    out = 0.5 * (out + out.T)
    if sums is not None and abs_sums is not None:
        sm = np.asarray(sums, float)
        moved = np.abs(sm - sm[0]).max(axis=0)
        bent = moved > GRAM_LINEARITY_TOL * np.maximum(np.asarray(abs_sums, float), np.finfo(float).tiny)
        out[bent, :] = np.nan
        out[:, bent] = np.nan
    return out


def _kept(gram: np.ndarray) -> np.ndarray:
    """The columns of a noise-free Gram matrix with finite entries (noise_free_gram's NaN: left out)."""
    return np.flatnonzero(np.isfinite(np.diag(gram)))


def information_reliability(gram_naive: np.ndarray, gram_corrected: np.ndarray, direction) -> float:
    """The share of the flight's apparent information on the combination ``direction`` . theta
    that is signal, not regressor noise: I_signal / I_naive with I = 1 / (d^T G^-1 d) for the
    naive X^T X and the one extrapolated to no noise (noise adds to X^T X, and along a direction
    where the regressors hardly vary it can supply most of it: alpha_dot_hat read off a noisy
    vane angle, on a flight that barely separates alpha-dot from q and alpha).  Columns the
    noise-free matrix leaves out (NaN: not linear in the noise) are left out of both.  In [0, 1];
    0 when the noise-free information along d is not positive (the noise supplies all of it);
    NaN when it cannot be said (d on a column left out, a singular matrix)."""
    d = np.asarray(direction, float)
    gc = np.asarray(gram_corrected, float)
    keep = _kept(gc)
    if np.any(d[np.setdiff1d(np.arange(d.size), keep)] != 0):
        return float("nan")
    d, gn, gc = d[keep], np.asarray(gram_naive, float)[np.ix_(keep, keep)], gc[np.ix_(keep, keep)]
    try:
        vn = float(d @ np.linalg.solve(gn, d))
        vc = float(d @ np.linalg.solve(gc, d))
    except np.linalg.LinAlgError:
        return float("nan")
    if not (vn > 0 and np.isfinite(vn)) or not np.isfinite(vc):
        return float("nan")
    return 0.0 if vc <= 0 else float(min(vn / vc, 1.0))


#: profile_direction's bound on the other columns' block: smallest eigenvalue of its
#: correlation form, and each column's size against the largest.
PROFILE_CONDITION = 1e-10


def profile_direction(gram: np.ndarray, j: int) -> np.ndarray | None:
    """How the coefficients follow a change of coefficient j when the others refit to keep the
    fit (the columns' Gram matrix ``gram``): 1 at j, -G_oo^-1 G_oj at the others (the
    omitted-variable direction: what the others absorb of a part of column j's effect), 0 at
    columns the matrix leaves out (NaN).  Needs only the other columns' block to be positive
    definite, so it holds where the noise-free information on j itself is gone; None when that
    block is not (PROFILE_CONDITION) or j is left out.  identify uses it for alpha_dot_hat, the
    column the vane noise enters through, so the direction is that coefficient's, not the
    least-favourable one of a combination it is in."""
    g = np.asarray(gram, float)
    keep = _kept(g)
    if j not in keep:
        return None
    others = [i for i in keep if i != j]
    out = np.zeros(g.shape[0])
    out[j] = 1.0
    if not others:
        return out
    block = g[np.ix_(others, others)]
    diag = np.diag(block)
    if np.any(diag <= PROFILE_CONDITION * diag.max()):
        return None
    scale = np.sqrt(diag)
    if np.linalg.eigvalsh(block / np.outer(scale, scale)).min() <= PROFILE_CONDITION:
        return None
    out[others] = -np.linalg.solve(block, g[others, j])
    return out if np.all(np.isfinite(out)) else None


def extrapolate(lams: np.ndarray, est: np.ndarray) -> float:
    """The SIMEX curve est(lambda) extrapolated quadratically to lambda = -1.  (A
    rational-linear extrapolant, exact for one noisy regressor, was tried on the band-limited
    flight data: it moved C_m_delta by +10..16 % on c172x, so the quadratic stays.)"""
    return float(np.polyval(np.polyfit(lams, est, 2), -1.0))


def extrapolation_spread(lams: np.ndarray, est: np.ndarray) -> float:
    """How much the answer depends on the extrapolant: |quadratic - linear| at lambda = -1
    (the usual sensitivity check of SIMEX); the correction's sigma is at least this (SimexResult.std_error)."""
    return float(abs(extrapolate(lams, est) - np.polyval(np.polyfit(lams, est, 1), -1.0)))
