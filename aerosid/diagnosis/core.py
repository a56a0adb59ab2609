"""Diagnosis of an identified model: where it fails and which effect is missing.

:func:`diagnose` fits each channel's model (the *base*), compares it with the
measured (flight-derived) coefficient, breaks the residuals down by time window
and by flight regime, checks their whiteness and spectrum, and then tests every
candidate effect (:mod:`aerosid.diagnosis.candidates`) by fitting base +
candidate.  See ``docs/modelling-loop.md`` for the rules and their numbers.

Evidence for one candidate (all computed on the samples inside the Mach window)
-----------------------------------------------------------------------------
``partial_f_corrected``, ``p_value``
    t^2 of the added coefficient with its *coloured-residual corrected* sigma
    (Morelli-Klein, :func:`aerosid.identification.regression.fit_linear`), and the two-sided
    Student-t p-value with the effective degrees of freedom.  This is the
    partial F test of one added term that survives coloured residuals.
``partial_f_plain``
    The classical partial F, ``(RSS_base - RSS_aug) / (RSS_aug / (N - p))``;
    it assumes white residuals and is reported for comparison only (it is
    hundreds of times too optimistic on smoothed flight data).
``pse_drop``
    Relative drop of Morelli's predicted squared error, ``1 - PSE_aug/PSE_base``.
``variance_share``
    Share of the base model's residual variance the candidate explains,
    ``1 - RSS_aug/RSS_base``.
``window_consistency``
    Leave-one-window-out check: the flight is cut into ``n_windows`` blocks;
    base and base + candidate are fitted without block k and predict block k.
    ``window_consistency = sum_k max(D_k, 0) / sum_k |D_k|`` with ``D_k`` the
    drop of the held-out squared error in block k (1: better everywhere it
    matters; ~0.5 or below: a fit to noise).  ``windows_improved`` is the plain
    fraction of blocks with ``D_k > 0``.

Decision rule (constants below)
-------------------------------
A candidate is *significant* when it is identifiable and

    p_value < P_MAX (0.001)  AND  window_consistency >= MIN_WINDOW_CONSISTENCY (0.7)
    AND  variance_share >= MIN_VARIANCE_SHARE (1 %)  AND  pse_drop > 0.

Ranking: significant candidates first, then by ``score`` (descending): the
corrected partial F times the squared share of the estimate that errors in the
recovered angles cannot produce (SIMEX; it can lower the evidence, never raise it).  Only the *first* finding should be acted on: add it, refit and
diagnose again, because a strong missing term makes correlated candidates look
significant too (they are listed in ``confused_with`` when their regressors,
after removing what the base model explains, correlate by |r| >= 0.9).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import pandas as pd
import scipy.signal
import scipy.stats
from statsmodels.stats.diagnostic import acorr_ljungbox

from aerosid.diagnosis.candidates import Candidate, default_candidates, derived_signals
from aerosid.diagnosis.lookalikes import heldout_sse as _heldout_sse, scaled_lstsq as _scaled_lstsq
from aerosid.diagnosis.lookalikes import windows_index as _windows_index
from aerosid.modelling.expressions import evaluate
from aerosid.identification.eiv_fit import angle_cutoff_hz, angle_eiv_sigma, correction_share
from aerosid.identification.identify import identity_channels, window_rows
from aerosid.identification.band import segment_keys
from aerosid.identification.eiv import SimexResult, extrapolate, extrapolation_spread, simex_frames
from aerosid.modelling.models import ChannelModel, default_models, vehicle_signals
from aerosid.identification.regression import LinearFit, fit_linear, residual_autocovariance

__all__ = [
    "diagnose", "Diagnosis", "EffectEvidence", "ChannelReport", "WindowStat", "RegimeBin", "Whiteness",
    "P_MAX", "MIN_WINDOW_CONSISTENCY", "MIN_VARIANCE_SHARE", "FLAG_RATIO", "CONFUSION_R",
    "RULE_TEXT",
]

from aerosid.diagnosis.rule import (ACF_LAGS_S, CONFUSION_R, FLAG_RATIO, MIN_BIN_SAMPLES, MIN_VARIANCE_SHARE,
                                    MIN_WINDOW_CONSISTENCY, P_MAX, REGIME_BINS, REGIME_VARIABLES, RULE_TEXT,
                                    SIMEX_LAMBDAS, SIMEX_REPLICATES, SIMEX_SEED, SPECTRUM_BANDS_HZ)
from aerosid.diagnosis.result import ChannelReport, Diagnosis, EffectEvidence, RegimeBin, WindowStat, Whiteness


# --------------------------------------------------------------------------- helpers
def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else float("nan")


def _window_stats(channel: str, resid: np.ndarray, t: np.ndarray, flight: np.ndarray, win: np.ndarray
                  ) -> tuple[WindowStat, ...]:
    total = _rms(resid)
    stats = []
    for k in np.unique(win):
        m = win == k
        r = resid[m]
        ratio = _rms(r) / total if total > 0 else float("nan")
        stats.append([channel, int(k), str(flight[m][0]), float(t[m][0]), float(t[m][-1]), int(m.sum()), _rms(r),
                      float(r.mean()), ratio])
    worst = int(np.nanargmax([s[-1] for s in stats])) if stats else -1
    return tuple(WindowStat(*s, flagged=bool(s[-1] >= FLAG_RATIO), worst=(i == worst)) for i, s in enumerate(stats))


def _regime_bins(channel: str, resid: np.ndarray, signals: dict) -> tuple[RegimeBin, ...]:
    total = _rms(resid)
    out = []
    for var, (sig, unit) in REGIME_VARIABLES.items():
        x = np.asarray(signals[sig], float)
        if not np.all(np.isfinite(x)) or np.ptp(x) <= 0:
            continue
        edges = np.unique(np.quantile(x, np.linspace(0, 1, REGIME_BINS + 1)))
        if edges.size < 2:
            continue
        idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, edges.size - 2)
        for b in range(edges.size - 1):
            m = idx == b
            n = int(m.sum())
            if n == 0:
                continue
            r = resid[m]
            ratio = _rms(r) / total if total > 0 else float("nan")
            out.append(RegimeBin(channel, var, unit, float(edges[b]), float(edges[b + 1]), n, _rms(r), float(r.mean()),
                                 ratio, bool(n >= MIN_BIN_SAMPLES and ratio >= FLAG_RATIO)))
    return tuple(out)


def _whiteness(channel: str, resid: np.ndarray, fs: float, n_eff: float) -> Whiteness:
    n = resid.size
    v = resid - resid.mean()
    r = residual_autocovariance(v)
    rho = r / r[0] if r[0] > 0 else np.zeros_like(r)
    acf = {lag: float(rho[int(round(lag * fs))]) if int(round(lag * fs)) < n else float("nan") for lag in ACF_LAGS_S}
    nonpos = np.nonzero(rho[1:] <= 0)[0]
    corr_time = (int(nonpos[0]) + 1) / fs if nonpos.size else n / fs
    lb_lag = int(np.clip(round(fs), 10, max(10, n // 5)))
    lb_lag = min(lb_lag, n - 2) if n > 12 else max(1, n // 2)
    try:
        lb = acorr_ljungbox(v, lags=[lb_lag], return_df=True)
        lb_stat, lb_p = float(lb["lb_stat"].iloc[0]), float(lb["lb_pvalue"].iloc[0])
    except Exception:  # pragma: no cover - degenerate input
        lb_stat, lb_p = float("nan"), float("nan")
    nper = int(min(n, 2 ** int(np.floor(np.log2(max(16.0, 20.0 * fs))))))
    f, psd = scipy.signal.welch(v, fs=fs, nperseg=max(8, nper))
    total = float(np.sum(psd))
    shares = {}
    for lo, hi in SPECTRUM_BANDS_HZ:
        if lo >= fs / 2:
            continue
        hi_c = min(hi, fs / 2 + 1e-12)
        m = (f >= lo) & (f < hi_c) if hi_c < fs / 2 else (f >= lo)
        label = f"{lo:g}-{hi:g} Hz" if math.isfinite(hi) and hi < fs / 2 else f">{lo:g} Hz"
        shares[label] = float(np.sum(psd[m]) / total) if total > 0 else float("nan")
    dominant = max(shares, key=lambda k: shares[k] if math.isfinite(shares[k]) else -1) if shares else ""
    return Whiteness(channel, acf, lb_lag, lb_stat, lb_p, bool(lb_p > 0.01), corr_time, float(n_eff), n,
                     shares, dominant, f, psd)


def _regressor_matrix(model: ChannelModel, signals: dict) -> np.ndarray:
    n = len(signals["alpha"])
    return np.column_stack([evaluate(t.expression, signals, n) for t in model.terms])


def _already_in(model: ChannelModel, cand: Candidate) -> bool:
    norm = cand.term.replace(" ", "")
    return any(t.coefficient == cand.coefficient or t.effect == cand.name or t.expression.replace(" ", "") == norm
               for t in model.terms)


# --------------------------------------------------------------------------- entry point
def diagnose(flight_data: pd.DataFrame, vehicle, models: dict[str, ChannelModel] | None = None, *,
             mach_half_width: float | None = 0.5, n_windows: int = 8,
             candidates: Sequence[Candidate] | None = None, cov: str = "morelli_klein",
             angle_sigma_rad: float | None = None,
             progress: Callable[[str, float], None] | None = None, localisation: bool = True) -> Diagnosis:
    """Diagnose `models` (default: the method.md §11 models) against the flight data.

    flight_data: a FlightData frame (schemas/flight_data.py); the samples with
    |M - M_ref| <= mach_half_width are used, as in :func:`aerosid.identification.identify.identify`.
    candidates: the effects to test (default :func:`default_candidates`); the ones
    already in a channel's model are skipped.
    angle_sigma_rad: 1-sigma white error of the recovered alpha and beta, for the
    errors-in-variables (SIMEX) check.  Default: the flight data's own (``eiv_sigma_*``, per
    angle and sample, through the band: :func:`_angle_noise`), else median(sigma_CN) /
    |CN_alpha| for inverted angles (a C_N error maps to an angle error through the normal-force
    slope); 0 switches the check off.
    progress: an optional callback progress("candidates", fraction done) (the CLI's display).
    localisation: also localise where each channel's model fails, as suggested terms
    (:mod:`aerosid.diagnosis.localise`; the ``localisation`` field).
    """
    models = dict(models or default_models(vehicle))
    if candidates is None:
        candidates = default_candidates(vehicle.mach_reference, vehicle.vehicle_class)
    fd = flight_data.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    fd = fd.loc[window_rows(fd, vehicle, mach_half_width, models)].reset_index(drop=True)
    n = len(fd)
    if n < max(50, 10 * n_windows):
        raise ValueError(f"only {n} samples inside Mach {vehicle.mach_reference} ± {mach_half_width}: "
                         "too few to diagnose the model")
    groups = segment_keys(fd)
    signals = derived_signals(vehicle_signals(fd, vehicle), vehicle.length_pitch_m, vehicle.length_lateral_m)
    t = fd["t_s"].to_numpy(float)
    flight = fd["flight"].astype(str).to_numpy()
    dts = np.diff(t)
    dts = dts[dts > 0]
    fs = 1.0 / float(np.median(dts)) if dts.size else 1.0
    win = _windows_index(n, n_windows)
    noise = _angle_noise(fd, vehicle, angle_sigma_rad)
    simex = _simex_signals(fd, vehicle, *noise, signals) if noise is not None else SimexDraws({}, 0.0)
    n_flights = max(int(fd["flight"].astype(str).nunique()) if "flight" in fd.columns else 1, 1)
    on_flights = "on this flight" if n_flights == 1 else f"on these {n_flights} pooled flights"

    reports: dict[str, ChannelReport] = {}
    identities = identity_channels(vehicle, models)  # their residual is numerical: no floor to speak of
    simex_cache: dict = {}
    evidence: list[EffectEvidence] = []
    for ch_i, (ch, model) in enumerate(models.items()):
        if progress is not None:
            progress("candidates", ch_i / len(models))
        y = fd[ch].to_numpy(float)
        Xb, notes = model.design(signals)
        base = fit_linear(y, Xb, names=model.names, channel=ch, cov=cov)
        if base.n_dropped:
            raise ValueError(f"{ch}: {base.n_dropped} samples with non-finite values in the data or the terms"
                             + (f" ({'; '.join(notes)}); the diagnosis needs every sample" if notes else ""))
        resid = np.asarray(base.residuals)
        reports[ch] = ChannelReport(
            ch, base, t, flight, y, np.asarray(base.fitted),
            _window_stats(ch, resid, t, flight, win), _regime_bins(ch, resid, signals),
            _whiteness(ch, resid, fs, base.n_eff))

        Ab = Xb.to_numpy(float)
        rss_b = float(resid @ resid)
        sse_b = _heldout_sse(Ab, y, win)
        y_std = float(np.std(y))
        cands = [c for c in candidates if c.channel == ch and not _already_in(model, c)]
        perp_cols: dict[str, np.ndarray] = {}
        chan_ev: list[dict] = []
        for c_i, c in enumerate(cands):
            if progress is not None:
                progress("candidates", (ch_i + c_i / len(cands)) / len(models))
            if ch in identities:  # e.g. a p of 4e-7 for CY's beta*abs(beta) at 50 Hz, which meant nothing
                chan_ev.append(_not_testable(c, f"{ch} is an identity by construction here (alpha and beta are "
                                                "inverted from C_N and C_Y): its residual is numerical, no term "
                                                "can be tested in it", base))
                continue
            x = np.asarray(c.regressor(signals), float)
            if x.shape != y.shape or not np.all(np.isfinite(x)):
                chan_ev.append(_not_testable(c, "the term is not finite on every sample", base))
                continue
            coef = c.coefficient if c.coefficient not in model.names else f"{c.coefficient}__candidate"
            Xa = Xb.copy()
            Xa[coef] = x
            fa = fit_linear(y, Xa, names=list(model.names) + [coef], channel=ch, cov=cov)
            j = len(model.names)
            # part of the term the base terms cannot explain
            perp = x - Ab @ _scaled_lstsq(Ab, x)
            sxx = float(np.sum((x - x.mean()) ** 2))
            r2_col = 1.0 - float(perp @ perp) / sxx if sxx > 0 else 1.0
            if not fa.identifiable[j]:
                why = next((w for w in fa.warnings if coef in w and "not identifiable" in w), "not identifiable")
                why = why.replace("__candidate", "")
                chan_ev.append(_not_testable(c, why, base, r2_col))
                continue
            perp_cols[c.name] = perp
            rss_a = float(np.asarray(fa.residuals) @ np.asarray(fa.residuals))
            p_a = fa.n_params
            f_plain = (rss_b - rss_a) / (rss_a / max(n - p_a, 1)) if rss_a > 0 else float("inf")
            p_plain = float(scipy.stats.f.sf(f_plain, 1, max(n - p_a, 1)))
            est, se = float(fa.estimate[j]), float(fa.std_error[j])
            sse_a = _heldout_sse(Xa.to_numpy(float), y, win)
            eiv, est_simex, p_simex = simex_check(simex, model, c.regressor, y, est, se, fa.dof_eff, simex_cache)
            d = sse_b - sse_a
            d = d[np.isfinite(d)]
            tot = float(np.sum(np.abs(d)))
            consistency = float(np.sum(np.clip(d, 0, None)) / tot) if tot > 0 else 0.0
            improved = float(np.mean(d > 0)) if d.size else 0.0
            share = 1.0 - rss_a / rss_b if rss_b > 0 else 0.0
            pse_drop = 1.0 - fa.pse / base.pse if base.pse > 0 else 0.0
            rms_b, rms_a = base.rms_residual, fa.rms_residual
            chan_ev.append(dict(
                cand=c, identifiable=True, estimate=est, std_error=se, std_error_ols=float(fa.std_error_ols[j]),
                partial_f_corrected=float(fa.t_values[j] ** 2), p_value=float(fa.p_values[j]),
                partial_f_plain=float(f_plain), p_value_plain=p_plain, pse_before=base.pse, pse_after=fa.pse,
                pse_drop=float(pse_drop), variance_share=float(share), window_consistency=consistency,
                windows_improved=improved, rms_before=rms_b, rms_after=rms_a,
                rms_drop_fraction=1.0 - rms_a / rms_b if rms_b > 0 else 0.0,
                contribution_rms=_rms(est * perp), size_ratio=float(np.std(est * x) / y_std) if y_std > 0 else np.nan,
                collinearity_r2=float(r2_col), n_eff=fa.n_eff, eiv_fraction=eiv,
                estimate_simex=est_simex, p_value_simex=p_simex,
                detectable_size=float(scipy.stats.t.isf(P_MAX / 2.0, fa.dof_eff) * se)))
        # confusable candidates: correlated once the base terms are removed
        names = list(perp_cols)
        confused: dict[str, list[str]] = {k: [] for k in names}
        for a_i in range(len(names)):
            for b_i in range(a_i + 1, len(names)):
                u, v = perp_cols[names[a_i]], perp_cols[names[b_i]]
                den = float(np.linalg.norm(u) * np.linalg.norm(v))
                if den > 0 and abs(float(u @ v)) / den >= CONFUSION_R:
                    confused[names[a_i]].append(names[b_i])
                    confused[names[b_i]].append(names[a_i])
        for rec in chan_ev:
            c = rec["cand"]
            if c.alias_of and c.alias_of in confused.get(c.name, ()):
                rec.setdefault("reasons", ())
                rec["reasons"] = tuple(rec["reasons"]) + (
                    f"cannot be told from {c.alias_of} {on_flights} (regressors correlate by >= {CONFUSION_R:g} "
                    f"once the model's terms are removed): reported together as {c.alias_of}, whose estimate is "
                    "then the combined derivative",)
            evidence.append(_evidence(rec, tuple(confused.get(c.name, ()))))

    ranked = sorted(evidence, key=lambda e: (not e.significant, not e.identifiable, -e.score))
    window = (float(fd["mach"].min()), float(fd["mach"].max()))
    from aerosid.diagnosis.floor import angle_floor_rms, floors
    from aerosid.diagnosis.lookalikes import resolve

    looks, recommended = resolve(ranked, models, signals, fd, candidates, confusion_r=CONFUSION_R, p_max=P_MAX,
                                 cov=cov)
    floored = [ch for ch in reports if ch not in identities]
    floor = floors({ch: reports[ch].residual for ch in floored}, fd, angle_floor_rms(fd, vehicle, models, floored),
                   vehicle)
    loc = {}
    if localisation:
        from aerosid.diagnosis.localise import localise

        loc = localise(signals, {ch: fd[ch].to_numpy(float) for ch in models}, models, t, groups, win,
                       vehicle.mach_reference, noise, simex=simex)
    return Diagnosis(tuple(ranked), reports, models, n, window, int(win.max()) + 1,
                     identities, looks, recommended, floor, loc, n_flights,
                     bool(getattr(vehicle, "turbulent_air", False)))


def _angle_noise(fd: pd.DataFrame, vehicle, angle_sigma_rad: float | None) -> tuple | None:
    """(sigma, cutoff_hz) of the recovered angles' noise, as aerosid.identification.eiv.angle_noise
    draws it, for the errors-in-variables checks (SIMEX, the shapes' guard); None: the angles are
    taken as exact.

    Not stated (angle_sigma_rad None): the flight data's own ``eiv_sigma_*`` per angle and sample
    through the band (aerosid.identification.eiv_fit.angle_eiv_sigma, angle_cutoff_hz), as the
    identification's SIMEX and the floor draw it.  Before, angles inverted from the database got
    white noise of median(sigma_CN) / |CN_alpha| here: on seed-rlv flights a fifth to a third of
    the inversion's noise the flight data measure (0.0027 against 0.0077 rad for beta at 50 Hz),
    and with its band-limited part so small, the check passed a beta|beta| in Cn that the
    inverted beta's own errors made (recommended on 2 of 10 no-effect flights at 50 Hz).  That
    estimate remains for flight data without the columns (the smoother's path, older files).
    Stated: white of that 1-sigma for inverted angles, through the vanes' low-pass for vanes."""
    vanes = vehicle.air_data_source == "vanes"
    if angle_sigma_rad is None:
        measured = angle_eiv_sigma(fd, vehicle)
        if measured is not None:
            return tuple(measured), angle_cutoff_hz(fd, vehicle)
        if vanes:
            return None
        sig_cn = fd["sigma_CN"].to_numpy(float) if "sigma_CN" in fd else np.array([0.0])
        cn_alpha = abs(float(vehicle.preflight.CN_alpha))
        angle_sigma_rad = float(np.nanmedian(sig_cn)) / cn_alpha if cn_alpha > 0 else 0.0
    if not (angle_sigma_rad > 0):
        return None
    return float(angle_sigma_rad), (angle_cutoff_hz(fd, vehicle) if vanes else None)


@dataclass(frozen=True)
class SimexDraws:
    """The diagnosis' SIMEX draws of the signals, {lambda: [signals]}, and the share of a SIMEX
    correction counted as its own 1-sigma (aerosid.identification.eiv_fit.correction_share: by the
    angles' source, as the identification counts it).  False when there are none."""

    frames: dict
    correction_share: float

    def __bool__(self) -> bool:
        return bool(self.frames)


def _simex_signals(fd: pd.DataFrame, vehicle, sigma, cutoff: float | None, signals: dict) -> SimexDraws:
    """Extra noise of variance lambda sigma^2 on alpha and beta (alpha_r, phi_r and the derivatives
    recomputed from them), SIMEX_REPLICATES per lambda in SIMEX_LAMBDAS, drawn as the
    identification's SIMEX draws them (aerosid.identification.eiv.simex_frames: antithetic pairs of
    common random numbers; deterministic, SIMEX_SEED); sigma, cutoff: as :func:`_angle_noise` gives
    them.  signals: fd's own (their band order serves every noisy copy)."""
    out: dict = {lam: [] for lam in SIMEX_LAMBDAS}
    for lam, f in simex_frames(fd, sigma, cutoff, seed=SIMEX_SEED, lambdas=SIMEX_LAMBDAS,
                               replicates=SIMEX_REPLICATES):
        out[lam].append(derived_signals(vehicle_signals(f, vehicle, like=signals), vehicle.length_pitch_m,
                                        vehicle.length_lateral_m))
    return SimexDraws(out, correction_share(vehicle))


def simex_check(simex: SimexDraws, model: ChannelModel, regressor, y: np.ndarray, est: float, se: float,
                dof: float, cache: dict | None = None) -> tuple[float, float, float]:
    """The errors-in-variables check of one added term (the candidates' and the localisation's):
    (eiv_fraction, SIMEX-corrected estimate, its p) from the SIMEX curve (:func:`simex_curve`),
    with the identification's sigma for a corrected estimate (:func:`simex_corrected`)."""
    curve = simex_curve(simex, model, regressor, y, est, cache)
    eiv = simex_fraction(curve)
    est_simex, p = simex_corrected(est, se, eiv, dof, spread=simex_spread(curve), share=simex.correction_share)
    return eiv, est_simex, p


def simex_corrected(est: float, se: float, eiv_fraction: float, dof: float, *, spread: float = 0.0,
                    share: float = 0.0) -> tuple[float, float]:
    """(estimate corrected for the angle errors, its two-sided p): one-sided in the estimate's own
    direction, so a SIMEX estimate of the opposite sign (eiv_fraction > 1: angle errors made the
    whole term) has p = 1.  Its sigma is the identification's for a SIMEX-corrected estimate
    (aerosid.identification.eiv.SimexResult.std_error): se scaled by the correction, combined with
    the extrapolation's own error, the larger of `spread` (|quadratic - linear| extrapolant,
    :func:`simex_spread`) and `share` x the correction.  spread = share = 0: se alone."""
    est_simex = est * (1.0 - eiv_fraction) if math.isfinite(eiv_fraction) else est
    sigma = float(SimexResult(np.array([est_simex]), np.array([spread]), np.array([est]))
                  .std_error(np.array([se]), correction_share=share)[0])
    p = (float(2.0 * scipy.stats.t.sf(max(math.copysign(1.0, est) * est_simex, 0.0) / sigma, dof))
         if sigma > 0 else float("nan"))
    return est_simex, p


def simex_fraction(curve: tuple[float, ...]) -> float:
    """The share of the estimate the angle errors account for, 1 - theta(-1)/theta(0): the SIMEX
    curve (:func:`simex_curve`) extrapolated quadratically to lambda = -1, no angle error
    (aerosid.identification.eiv.extrapolate).  ~1: the term exists only because the angles are
    noisy; <= 0: a real, attenuated effect; NaN without a curve."""
    if not curve:
        return float("nan")
    return float(1.0 - extrapolate(np.array((0.0, *SIMEX_LAMBDAS)), np.asarray(curve, float)) / curve[0])


def simex_spread(curve: tuple[float, ...]) -> float:
    """How much the corrected estimate depends on the extrapolant: |quadratic - linear| at
    lambda = -1 (aerosid.identification.eiv.extrapolation_spread); 0 without a curve."""
    return extrapolation_spread(np.array((0.0, *SIMEX_LAMBDAS)), np.asarray(curve, float)) if curve else 0.0


def simex_curve(simex: SimexDraws, model: ChannelModel, regressor, y: np.ndarray, est: float,
                cache: dict | None = None) -> tuple[float, ...]:
    """SIMEX (Cook & Stefanski 1994): the added term refitted with extra angle noise of variance
    lambda sigma^2, (theta(0) = est, mean theta(lambda) for lambda in SIMEX_LAMBDAS); () when it
    cannot be computed.  regressor: signals -> the added column."""
    if not simex or not (math.isfinite(est) and est != 0.0):
        return ()
    means = []
    for lam in SIMEX_LAMBDAS:
        th = []
        for i, sig in enumerate(simex.frames[lam]):
            key = (model.channel, lam, i)
            if cache is None or key not in cache:
                base = _regressor_matrix(model, sig)
                if cache is not None:
                    cache[key] = base
            else:
                base = cache[key]
            A = np.column_stack([base, regressor(sig)])
            th.append(_scaled_lstsq(A, y)[-1] if np.all(np.isfinite(A)) else math.nan)
        # the draws come in antithetic pairs (i, i + 1): a pair with a non-finite design is
        # dropped whole, so the terms odd in the noise still cancel in the rest
        pairs = [(a_, b_) for a_, b_ in zip(th[0::2], th[1::2]) if math.isfinite(a_) and math.isfinite(b_)]
        if not pairs:
            return ()
        means.append(float(np.mean(pairs)))
    return (float(est), *means)


def _not_testable(c: Candidate, why: str, base: LinearFit, r2_col: float = float("nan")) -> dict:
    nan = float("nan")
    return dict(cand=c, identifiable=False, reasons=(why,), estimate=nan, std_error=nan, std_error_ols=nan,
                partial_f_corrected=nan, p_value=nan, partial_f_plain=nan, p_value_plain=nan,
                pse_before=base.pse, pse_after=nan, pse_drop=nan, variance_share=nan, window_consistency=nan,
                windows_improved=nan, rms_before=base.rms_residual, rms_after=nan, rms_drop_fraction=nan,
                contribution_rms=nan, size_ratio=nan, collinearity_r2=r2_col, n_eff=base.n_eff, eiv_fraction=nan,
                estimate_simex=nan, p_value_simex=nan)


def _evidence(rec: dict, confused: tuple[str, ...]) -> EffectEvidence:
    c: Candidate = rec.pop("cand")
    reasons = list(rec.pop("reasons", ()))
    if rec["identifiable"]:
        if not rec["p_value"] < P_MAX:
            reasons.append(f"corrected p = {rec['p_value']:.2g} >= {P_MAX:g}")
        if not rec["window_consistency"] >= MIN_WINDOW_CONSISTENCY:
            reasons.append(f"held-out window consistency {rec['window_consistency']:.0%} < "
                           f"{MIN_WINDOW_CONSISTENCY:.0%}")
        if not rec["variance_share"] >= MIN_VARIANCE_SHARE:
            reasons.append(f"explains {rec['variance_share']:.2%} < {MIN_VARIANCE_SHARE:.0%} of the residual variance")
        if not rec["pse_drop"] > 0:
            reasons.append("does not lower the PSE")
        elif math.isfinite(rec["p_value_simex"]) and not rec["p_value_simex"] < P_MAX:
            reasons.append(f"errors in the recovered angles could make it: {rec['eiv_fraction']:.0%} of the estimate "
                           f"(SIMEX), corrected estimate p = {rec['p_value_simex']:.2g}")
    return EffectEvidence(name=c.name, channel=c.channel, coefficient=c.coefficient, term=c.term,
                          spec_term=c.spec_term, meaning=c.meaning, catalogue=c.catalogue,
                          significant=bool(rec["identifiable"] and not reasons), confused_with=confused,
                          reasons=tuple(reasons), **rec)
