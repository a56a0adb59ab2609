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
from dataclasses import dataclass, field
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
from aerosid.identification.identify import angle_cutoff_hz, mach_window_mask
from aerosid.identification.eiv import with_angle_noise
from aerosid.modelling.model_specs import paste_lines
from aerosid.modelling.models import ChannelModel, default_models, vehicle_signals
from aerosid.identification.regression import LinearFit, fit_linear, residual_autocovariance

__all__ = [
    "diagnose", "Diagnosis", "EffectEvidence", "ChannelReport", "WindowStat", "RegimeBin", "Whiteness",
    "P_MAX", "MIN_WINDOW_CONSISTENCY", "MIN_VARIANCE_SHARE", "FLAG_RATIO", "CONFUSION_R",
    "RULE_TEXT",
]

P_MAX = 1e-3
"""Largest corrected p-value of the added term for a significant finding."""
MIN_WINDOW_CONSISTENCY = 0.7
"""Smallest held-out (leave-one-window-out) consistency for a significant finding."""
MIN_VARIANCE_SHARE = 0.01
"""Smallest share of the residual variance a significant finding must explain."""
SIMEX_REPLICATES = 8
"""Replicates per extra-noise level."""
SIMEX_LAMBDAS = (1.0, 2.0)
"""Extra angle-noise variances (in units of sigma^2) of the SIMEX check; quadratic extrapolation to -1."""
"""Replicates of the extra angle noise in the SIMEX check."""
SIMEX_SEED = 20240613
"""Seed of the SIMEX extra noise (the diagnosis is deterministic)."""
FLAG_RATIO = 1.5
"""A time window or regime bin is flagged when its residual RMS is >= FLAG_RATIO x the channel's."""
MIN_BIN_SAMPLES = 30
"""Regime bins with fewer samples are not flagged (too few to judge)."""
CONFUSION_R = 0.9
"""Candidates whose base-residualised regressors correlate by at least this are reported as confusable."""
REGIME_BINS = 8
"""Quantile bins per regime variable."""
REGIME_VARIABLES = {  # name in the report -> (signal, unit)
    "alpha": ("alpha", "rad"), "beta": ("beta", "rad"), "mach": ("mach", "-"), "qbar": ("qbar", "Pa"),
    "delta_p": ("delta_p", "rad"), "delta_y": ("delta_y", "rad"), "delta_r": ("delta_r", "rad"),
    "phi_r": ("phi_r", "rad"),
}
ACF_LAGS_S = (0.1, 0.5, 1.0, 2.0)
"""Lags [s] at which the residual autocorrelation is reported."""
SPECTRUM_BANDS_HZ = ((0.0, 0.1), (0.1, 0.5), (0.5, 2.0), (2.0, 10.0), (10.0, math.inf))
"""Frequency bands for the residual power shares."""

RULE_TEXT = (f"significant = identifiable and corrected p < {P_MAX:g} (t^2 of the added term with the "
             f"coloured-residual sigma) and held-out window consistency >= {MIN_WINDOW_CONSISTENCY:.0%} "
             f"and explains >= {MIN_VARIANCE_SHARE:.0%} of the residual variance and lowers the PSE and is not an "
             f"errors-in-variables artefact (the SIMEX-corrected estimate also has p < {P_MAX:g}); "
             "ranked significant first, then by the corrected partial F net of the share angle errors could make (SIMEX)")


# --------------------------------------------------------------------------- results
def _f(x) -> float | None:
    """JSON-safe float (NaN/inf -> None)."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


@dataclass(frozen=True)
class EffectEvidence:
    """The evidence for one candidate effect in one channel."""

    name: str
    channel: str
    coefficient: str
    term: str
    spec_term: str | None
    meaning: str
    catalogue: bool
    identifiable: bool
    significant: bool
    estimate: float
    std_error: float
    std_error_ols: float
    partial_f_corrected: float
    p_value: float
    partial_f_plain: float
    p_value_plain: float
    pse_before: float
    pse_after: float
    pse_drop: float
    variance_share: float
    window_consistency: float
    windows_improved: float
    rms_before: float
    rms_after: float
    rms_drop_fraction: float
    contribution_rms: float  # RMS of estimate x (term minus what the base terms explain of it)
    size_ratio: float  # std(estimate x term) / std(measured channel coefficient)
    collinearity_r2: float  # R^2 of the term on the base regressors
    n_eff: float
    eiv_fraction: float  # (theta(extra angle noise) - theta) / theta: ~1 for an artefact of angle errors
    estimate_simex: float  # SIMEX-corrected estimate (extrapolated to no angle error)
    p_value_simex: float  # corrected p of the SIMEX-corrected estimate (same sigma; 1 when its sign flips)
    confused_with: tuple[str, ...] = ()
    reasons: tuple[str, ...] = ()  # why it is not significant (empty when significant)
    #: smallest |estimate| this flight could call significant at p < P_MAX with this term's
    #: coloured-residual sigma: the detection floor ("if present, it is smaller than this")
    detectable_size: float = float("nan")

    @property
    def score(self) -> float:
        """Ranking score: the corrected partial F times the share of the estimate that errors
        in the recovered angles cannot account for, ``clip(1 - eiv_fraction, 0, 1)^2`` (SIMEX).
        The angle-error check can only lower the evidence, never raise it: a SIMEX
        extrapolation that runs away (a term whose estimate is ~0, or a force channel whose
        angles were inverted from that very channel, where the extra angle noise wrecks the
        fit) would otherwise score thousands and head the list.  The corrected partial F when
        SIMEX is off."""
        f = self.partial_f_corrected
        if not math.isfinite(f):
            return -1.0
        if math.isfinite(self.eiv_fraction):
            return float(f * min(max(1.0 - self.eiv_fraction, 0.0), 1.0) ** 2)
        return float(f)

    def to_dict(self) -> dict:
        d = {
            "name": self.name, "channel": self.channel, "significant": bool(self.significant),
            "coefficient": self.coefficient, "term": self.term, "spec_term": self.spec_term,
            "catalogue": bool(self.catalogue), "identifiable": bool(self.identifiable),
        }
        for k in ("estimate", "std_error", "std_error_ols", "partial_f_corrected", "p_value", "partial_f_plain",
                  "p_value_plain", "pse_before", "pse_after", "pse_drop", "variance_share", "window_consistency",
                  "windows_improved", "rms_before", "rms_after", "rms_drop_fraction", "contribution_rms",
                  "size_ratio", "collinearity_r2", "n_eff", "eiv_fraction", "estimate_simex", "p_value_simex",
                  "detectable_size"):
            d[k] = _f(getattr(self, k))
        d["confused_with"] = list(self.confused_with)
        d["reasons"] = list(self.reasons)
        d["score"] = _f(self.score)
        d["meaning"] = self.meaning
        return d


@dataclass(frozen=True)
class WindowStat:
    """Residual statistics of one channel in one time window."""

    channel: str
    index: int
    flight: str
    t_start_s: float
    t_end_s: float
    n: int
    rms: float
    mean: float
    rms_ratio: float  # rms / channel rms
    flagged: bool
    worst: bool

    def to_dict(self) -> dict:
        return {"channel": self.channel, "window": self.index, "flight": self.flight,
                "t_start_s": _f(self.t_start_s), "t_end_s": _f(self.t_end_s), "n": self.n,
                "rms": _f(self.rms), "mean": _f(self.mean), "rms_ratio": _f(self.rms_ratio),
                "flagged": bool(self.flagged), "worst": bool(self.worst)}


@dataclass(frozen=True)
class RegimeBin:
    """Residual statistics of one channel in one bin of one regime variable."""

    channel: str
    variable: str
    unit: str
    lo: float
    hi: float
    n: int
    rms: float
    mean: float
    rms_ratio: float
    flagged: bool

    def to_dict(self) -> dict:
        return {"channel": self.channel, "variable": self.variable, "unit": self.unit, "lo": _f(self.lo),
                "hi": _f(self.hi), "n": self.n, "rms": _f(self.rms), "mean": _f(self.mean),
                "rms_ratio": _f(self.rms_ratio), "flagged": bool(self.flagged)}


@dataclass(frozen=True)
class Whiteness:
    """Whiteness tests and spectrum of one channel's residuals."""

    channel: str
    acf: dict  # lag [s] -> autocorrelation
    ljung_box_lag: int
    ljung_box_stat: float
    ljung_box_p: float
    white: bool
    correlation_time_s: float  # first zero crossing of the autocorrelation
    n_eff: float
    n: int
    band_share: dict  # "lo-hi Hz" -> share of residual power
    dominant_band: str
    frequency_hz: np.ndarray = field(repr=False)
    psd: np.ndarray = field(repr=False)  # Welch PSD [1/Hz]

    def to_dict(self) -> dict:
        return {"acf": {f"{k:g}s": _f(v) for k, v in self.acf.items()}, "ljung_box_lag": self.ljung_box_lag,
                "ljung_box_stat": _f(self.ljung_box_stat), "ljung_box_p": _f(self.ljung_box_p),
                "white": bool(self.white), "correlation_time_s": _f(self.correlation_time_s),
                "n_eff": _f(self.n_eff), "n": self.n,
                "spectrum_band_share": {k: _f(v) for k, v in self.band_share.items()},
                "dominant_band": self.dominant_band}


@dataclass(frozen=True)
class ChannelReport:
    """One channel: base fit, comparison time history, residual breakdown."""

    channel: str
    fit: LinearFit = field(repr=False)
    t_s: np.ndarray = field(repr=False)
    flight: np.ndarray = field(repr=False)
    measured: np.ndarray = field(repr=False)
    model: np.ndarray = field(repr=False)
    windows: tuple[WindowStat, ...]
    regimes: tuple[RegimeBin, ...]
    whiteness: Whiteness

    @property
    def residual(self) -> np.ndarray:
        return self.measured - self.model

    @property
    def worst_window(self) -> WindowStat:
        return max(self.windows, key=lambda w: w.rms_ratio)

    def worst_regimes(self, k: int = 3) -> tuple[RegimeBin, ...]:
        ok = [b for b in self.regimes if b.n >= MIN_BIN_SAMPLES and math.isfinite(b.rms_ratio)]
        return tuple(sorted(ok, key=lambda b: -b.rms_ratio)[:k])

    def comparison(self) -> pd.DataFrame:
        """Measured vs model time history (for plots)."""
        return pd.DataFrame({"t_s": self.t_s, "flight": self.flight, "measured": self.measured,
                             "model": self.model, "residual": self.residual})


@dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose`."""

    effects: tuple[EffectEvidence, ...]  # ranked, best first
    channels: dict  # channel -> ChannelReport
    models: dict  # channel -> ChannelModel (the base)
    n_samples: int
    mach_window: tuple[float, float]
    n_windows: int
    #: channels that are identities by construction (alpha, beta inverted from them): their
    #: residual is numerical, so they are left out of "where it fails"
    identities: tuple[str, ...] = ()
    #: look-alike comparisons (aerosid.diagnosis.lookalikes), the recommendation (None when
    #: nothing is significant or the look-alikes are not separated), per-channel floor
    lookalikes: tuple = ()
    recommended: str | None = None
    floor: dict = field(default_factory=dict)  # channel -> aerosid.diagnosis.floor.ChannelFloor

    @property
    def loop_closed(self) -> bool:
        """Nothing significant is missing and no look-alike choice is open or refuted."""
        return self.nothing_significant and not any(c.swap or (c.in_model and c.verdict != "separated")
                                                    for c in self.lookalikes)
    #: channel -> localisation findings (aerosid.diagnosis.localise), best first
    localisation: dict = field(default_factory=dict)

    @property
    def significant(self) -> tuple[EffectEvidence, ...]:
        return tuple(e for e in self.effects if e.significant)

    @property
    def nothing_significant(self) -> bool:
        return not self.significant

    @property
    def top(self) -> EffectEvidence | None:
        return self.effects[0] if self.effects else None

    def effect(self, name: str, channel: str | None = None) -> EffectEvidence:
        for e in self.effects:
            if e.name == name and (channel is None or e.channel == channel):
                return e
        raise KeyError(f"no candidate {name!r} in this diagnosis")

    def rank_of(self, name: str) -> int | None:
        """1-based rank of a candidate (None when it was not tested, e.g. already in the model)."""
        for i, e in enumerate(self.effects, 1):
            if e.name == name:
                return i
        return None

    def effects_table(self) -> pd.DataFrame:
        return pd.DataFrame([e.to_dict() for e in self.effects])

    def comparison(self, channel: str) -> pd.DataFrame:
        return self.channels[channel].comparison()

    def unidentifiable(self) -> tuple[EffectEvidence, ...]:
        return tuple(e for e in self.effects if not e.identifiable)

    @property
    def message(self) -> str:
        from aerosid.diagnosis.lookalikes import lookalike_message

        return lookalike_message(self, self._base_message())

    def _base_message(self) -> str:
        sig = self.significant
        from aerosid.diagnosis.localise import localisation_hint

        where = self._where_text() + localisation_hint(self.localisation)
        if sig:
            e = sig[0]
            add = ("add it with the lines below in a model spec file SPEC, fit again "
                   "(aerosid fit RUN_DIR --model SPEC) and diagnose again" if e.spec_term else
                   f"its term `{e.term}` needs a signal the model specs do not offer yet")
            others = [s.name for s in sig[1:]]
            tail = (f" The other significant candidates ({', '.join(others)}) may be shadows of it: judge them "
                    "after the refit." if others else "")
            return (f"Most likely missing: {e.name} in {e.channel} ({e.meaning}). It explains "
                    f"{e.variance_share:.1%} of the {e.channel} residual variance (corrected partial F "
                    f"{e.partial_f_corrected:.3g}, p = {e.p_value:.2g}, held-out window consistency "
                    f"{e.window_consistency:.0%}); {add}.{tail} {where}"
                    + (f"\n\n{paste_lines(e.channel, e.spec_term)}" if e.spec_term else ""))
        ident = [e for e in self.effects if e.identifiable]
        best = max(ident, key=lambda e: e.score) if ident else None
        strongest = (f" Strongest candidate: {best.name} in {best.channel} (p = {best.p_value:.2g}, explains "
                     f"{best.variance_share:.2%} of the residual variance, consistency "
                     f"{best.window_consistency:.0%}): not enough." if best else "")
        floors = [e for e in self.effects if e.catalogue and math.isfinite(e.detectable_size)]
        if floors:
            strongest += (" This flight could not have detected effects smaller than: "
                          + ", ".join(f"{e.name} |{e.coefficient}| {e.detectable_size:.3g}" for e in floors) + ".")
        unident = [e.name for e in self.effects if not e.identifiable]
        cannot = (f" Not separable from the model's own terms on this flight (so not tested): "
                  f"{', '.join(unident)}." if unident else "")
        return ("Nothing significant is missing: no candidate effect passes the rule (corrected p < "
                f"{P_MAX:g}, consistency >= {MIN_WINDOW_CONSISTENCY:.0%}, >= {MIN_VARIANCE_SHARE:.0%} of the "
                f"residual variance).{strongest}{cannot} {where}")

    def _where_text(self) -> str:
        parts = []
        for ch, rep in self.channels.items():
            if ch in self.identities:
                continue
            flagged_w = [w for w in rep.windows if w.flagged]
            flagged_r = [b for b in rep.worst_regimes(3) if b.flagged]
            if flagged_w or flagged_r:
                bits = [f"t {w.t_start_s:.1f}-{w.t_end_s:.1f} s (x{w.rms_ratio:.2f})" for w in flagged_w[:2]]
                bits += [f"{b.variable} {b.lo:.4g}..{b.hi:.4g} (x{b.rms_ratio:.2f})" for b in flagged_r[:2]]
                parts.append(f"{ch}: " + ", ".join(bits))
        if not parts:
            return "No time window or regime has a residual RMS above " f"{FLAG_RATIO:g}x its channel's."
        return "Where the model is worst: " + "; ".join(parts) + "."

    # ---- output
    def to_json(self) -> dict:
        regimes, windows, regime_map = [], [], []
        for ch, rep in self.channels.items():
            if ch in self.identities:  # not "where it fails": the residual is numerical
                continue
            regimes += [b.to_dict() for b in rep.worst_regimes(3)]
            windows += [w.to_dict() for w in rep.windows]
            regime_map += [b.to_dict() for b in rep.regimes]
        return {
            "schema": "aerosid.diagnosis/1",
            "nothing_significant": self.nothing_significant,
            "message": self.message,
            "rule": {"text": RULE_TEXT, "p_max": P_MAX, "min_window_consistency": MIN_WINDOW_CONSISTENCY,
                     "min_variance_share": MIN_VARIANCE_SHARE, "flag_ratio": FLAG_RATIO,
                     "n_windows": self.n_windows},
            "n_samples": self.n_samples,
            "mach_window": [_f(self.mach_window[0]), _f(self.mach_window[1])],
            "effects": [e.to_dict() for e in self.effects],
            "identities": list(self.identities),
            "recommended": self.recommended,
            "loop_closed": self.loop_closed,
            "lookalikes": [c.to_dict() for c in self.lookalikes],
            "floor": {ch: f.to_dict() for ch, f in self.floor.items()},
            "regimes": regimes,
            "regime_map": regime_map,
            "time_windows": windows,
            "whiteness": {ch: rep.whiteness.to_dict() for ch, rep in self.channels.items()},
            "localisation": {ch: [f.to_dict() for f in fs] for ch, fs in self.localisation.items()},
            "channels": {ch: {"terms": list(self.models[ch].names), "rms_residual": _f(rep.fit.rms_residual),
                              "r2": _f(rep.fit.r2), "pse": _f(rep.fit.pse), "f_stat": _f(rep.fit.f_stat),
                              "f_stat_corrected": _f(rep.fit.f_stat_corrected), "n_eff": _f(rep.fit.n_eff),
                              "coefficients": {n: {"estimate": _f(rep.fit.estimate[i]),
                                                   "std_error": _f(rep.fit.std_error[i])}
                                               for i, n in enumerate(rep.fit.names)}}
                         for ch, rep in self.channels.items()},
        }

    def summary(self, max_effects: int = 12) -> str:
        lines = [f"Diagnosis on {self.n_samples} samples, Mach {self.mach_window[0]:.2f}..{self.mach_window[1]:.2f}, "
                 f"{self.n_windows} time windows",
                 "", "Model vs measurement (residual of the current model):",
                 f"  {'channel':<8}{'RMS':>11}{'R^2':>10}{'N_eff':>8}{'corr. time':>12}{'Ljung-Box p':>13}"
                 f"  dominant residual band"]
        for ch, rep in self.channels.items():
            w = rep.whiteness
            lines.append(f"  {ch:<8}{rep.fit.rms_residual:>11.3g}{rep.fit.r2:>10.5f}{rep.fit.n_eff:>8.0f}"
                         f"{w.correlation_time_s:>10.2f} s{w.ljung_box_p:>13.2g}  {w.dominant_band}"
                         f"{'' if w.white else ' (coloured)'}")
        if self.floor:
            from aerosid.diagnosis.floor import floor_table

            lines += ["", *floor_table(self.floor)]
        lines += ["", "Where it fails (residual RMS relative to the channel's; * = flagged >= "
                  f"{FLAG_RATIO:g}x):"]
        for ch, rep in self.channels.items():
            if ch in self.identities:
                lines.append(f"  {ch:<4} identity by construction (alpha, beta are inverted from it): left out")
                continue
            ww = rep.worst_window
            regs = ", ".join(f"{b.variable} {b.lo:.4g}..{b.hi:.4g} x{b.rms_ratio:.2f}{'*' if b.flagged else ''}"
                             for b in rep.worst_regimes(2))
            lines.append(f"  {ch:<4} worst window t {ww.t_start_s:.1f}-{ww.t_end_s:.1f} s x{ww.rms_ratio:.2f}"
                         f"{'*' if ww.flagged else ''}; worst regimes: {regs}")
        lines += ["", "Candidate effects (best first; F and p corrected for coloured residuals):",
                  f"  {'#':>2} {'effect':<24}{'ch':<4}{'sig':<5}{'F corr':>9}{'p':>9}{'F plain':>10}"
                  f"{'var.share':>10}{'consist.':>9}{'RMS drop':>9}  note"]
        for i, e in enumerate(self.effects[:max_effects], 1):
            note = "; ".join(e.reasons[:1]) if not e.significant else e.meaning
            if e.confused_with:
                note += f" [confusable with {', '.join(e.confused_with)}]"
            lines.append(f"  {i:>2} {e.name:<24}{e.channel:<4}{'YES' if e.significant else 'no':<5}"
                         f"{_g(e.partial_f_corrected, '9.3g')}{_g(e.p_value, '9.2g')}{_g(e.partial_f_plain, '10.3g')}"
                         f"{_g(100 * e.variance_share, '9.2f')}%{_g(e.window_consistency, '9.2f')}"
                         f"{_g(100 * e.rms_drop_fraction, '8.1f')}%  {note[:70]}")
        if len(self.effects) > max_effects:
            lines.append(f"  ... {len(self.effects) - max_effects} more")
        for c in self.lookalikes:
            lines += ["", c.summary()]
        if self.localisation:
            from aerosid.diagnosis.localise import localisation_text

            lines += ["", localisation_text(self.localisation)]
        lines += ["", f"Rule: {RULE_TEXT}.", "",
                  f"Recommended: {self.recommended or 'none'}", self.message]
        return "\n".join(lines)

    def figure(self, channel: str):
        """A matplotlib figure: measured vs model, and the residual, against time."""
        import matplotlib.pyplot as plt

        rep = self.channels[channel]
        fig, (a1, a2) = plt.subplots(2, 1, sharex=True, figsize=(10, 5))
        a1.plot(rep.t_s, rep.measured, ".", ms=1, label="measured (flight-derived)")
        a1.plot(rep.t_s, rep.model, "-", lw=1, label="model")
        a1.set_ylabel(channel)
        a1.legend(loc="best")
        a2.plot(rep.t_s, rep.residual, "-", lw=0.6)
        for w in rep.windows:
            if w.flagged:
                a2.axvspan(w.t_start_s, w.t_end_s, color="tab:red", alpha=0.15)
        a2.set_ylabel("residual")
        a2.set_xlabel("t [s]")
        return fig


def _g(x: float, fmt: str) -> str:
    width = int(fmt.split(".")[0]) if fmt[0].isdigit() else 0
    return format(x, fmt) if math.isfinite(x) else "nan".rjust(width)


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
    angle_sigma_rad: 1-sigma error of the recovered alpha and beta, for the
    errors-in-variables (SIMEX) check.  Default: median(sigma_CN) / |CN_alpha|
    (alpha and beta come from inverting the force database, so a C_N error maps
    to an angle error through the normal-force slope); 0 switches the check off.
    progress: an optional callback progress("candidates", fraction done) (the CLI's display).
    localisation: also localise where each channel's model fails, as suggested terms
    (:mod:`aerosid.diagnosis.localise`; the ``localisation`` field).
    """
    models = dict(models or default_models(vehicle))
    if candidates is None:
        candidates = default_candidates(vehicle.mach_reference, vehicle.vehicle_class)
    fd = flight_data.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    mask = mach_window_mask(fd["mach"].to_numpy(float), vehicle.mach_reference, mach_half_width)
    fd = fd.loc[mask].reset_index(drop=True)
    n = len(fd)
    if n < max(50, 10 * n_windows):
        raise ValueError(f"only {n} samples inside Mach {vehicle.mach_reference} ± {mach_half_width}: "
                         "too few to diagnose the model")
    groups = (fd["flight"].astype(str) + "/" + fd["segment"].astype(str)).to_numpy()
    signals = derived_signals(vehicle_signals(fd, vehicle), vehicle.length_pitch_m, vehicle.length_lateral_m)
    t = fd["t_s"].to_numpy(float)
    flight = fd["flight"].astype(str).to_numpy()
    dts = np.diff(t)
    dts = dts[dts > 0]
    fs = 1.0 / float(np.median(dts)) if dts.size else 1.0
    win = _windows_index(n, n_windows)
    if angle_sigma_rad is None and vehicle.air_data_source == "vanes":
        angle_sigma_rad = vehicle.vane_noise_rad
    if angle_sigma_rad is None:
        sig_cn = fd["sigma_CN"].to_numpy(float) if "sigma_CN" in fd else np.array([0.0])
        cn_alpha = abs(float(vehicle.preflight.CN_alpha))
        angle_sigma_rad = float(np.nanmedian(sig_cn)) / cn_alpha if cn_alpha > 0 else 0.0
    simex = _simex_signals(fd, vehicle, groups, float(angle_sigma_rad)) if angle_sigma_rad > 0 else []

    reports: dict[str, ChannelReport] = {}
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
            eiv = _simex_fraction(simex, model, c, y, est, simex_cache)
            est_simex = est * (1.0 - eiv) if math.isfinite(eiv) else est
            # one-sided in the estimate's own direction: a SIMEX estimate of the opposite sign
            # (eiv_fraction > 1) says angle errors made the whole term, so p = 1
            p_simex = (float(2.0 * scipy.stats.t.sf(max(math.copysign(1.0, est) * est_simex, 0.0) / se, fa.dof_eff))
                       if se > 0 else float("nan"))
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
                    f"cannot be told from {c.alias_of} on this flight (regressors correlate by >= {CONFUSION_R:g} "
                    f"once the model's terms are removed): reported together as {c.alias_of}, whose estimate is "
                    "then the combined derivative",)
            evidence.append(_evidence(rec, tuple(confused.get(c.name, ()))))

    ranked = sorted(evidence, key=lambda e: (not e.significant, not e.identifiable, -e.score))
    window = (float(fd["mach"].min()), float(fd["mach"].max()))
    from aerosid.diagnosis.floor import angle_floor_parts, floors
    from aerosid.diagnosis.lookalikes import resolve

    looks, recommended = resolve(ranked, models, signals, fd, candidates, confusion_r=CONFUSION_R, p_max=P_MAX,
                                 cov=cov)
    identities = identity_channels(vehicle, models)  # their residual is numerical: no floor to speak of
    floor = floors({ch: rep.residual for ch, rep in reports.items() if ch not in identities}, fd,
                   angle_floor_parts(fd, vehicle, models, reports))
    loc = {}
    if localisation:
        from aerosid.diagnosis.localise import localise

        loc = localise(signals, {ch: fd[ch].to_numpy(float) for ch in models}, models, t, groups, win,
                       vehicle.mach_reference, float(angle_sigma_rad))
    return Diagnosis(tuple(ranked), reports, models, n, window, int(win.max()) + 1,
                     identities, looks, recommended, floor, loc)


def identity_channels(vehicle, channels) -> tuple[str, ...]:
    """The channels that are identities by construction: C_N and C_Y when alpha and beta
    are inverted from them (no vanes), as aerosid.identification.identify reports them."""
    from aerosid.identification.identify import INVERSION_CHANNELS

    if getattr(vehicle, "air_data_source", None) == "vanes":
        return ()
    return tuple(ch for ch in INVERSION_CHANNELS if ch in channels)



def _simex_signals(fd: pd.DataFrame, vehicle, groups: np.ndarray, sigma: float) -> dict:
    """{lambda: [signals]}: extra white noise of variance lambda sigma^2 on alpha and beta
    (alpha_r, phi_r and the derivatives recomputed from them), SIMEX_REPLICATES per
    lambda in SIMEX_LAMBDAS; deterministic (SIMEX_SEED)."""
    rng = np.random.default_rng(SIMEX_SEED)
    cutoff = angle_cutoff_hz(fd, vehicle) if vehicle.air_data_source == "vanes" else None
    out: dict = {}
    for lam in SIMEX_LAMBDAS:
        out[lam] = []
        for _ in range(SIMEX_REPLICATES):
            # noise like the angles' own: white for angles inverted from the database, through
            # the vanes' low-pass for vanes (as aerosid.identification.eiv does)
            f = with_angle_noise(fd, rng, groups, sigma * math.sqrt(lam), cutoff)
            out[lam].append(derived_signals(vehicle_signals(f, vehicle), vehicle.length_pitch_m,
                                            vehicle.length_lateral_m))
    return out


def _simex_fraction(simex: dict, model: ChannelModel, c: Candidate, y: np.ndarray, est: float,
                    cache: dict | None = None) -> float:
    """SIMEX (Cook & Stefanski 1994): refit with extra angle noise of variance lambda sigma^2
    (lambda = 1, 2), extrapolate the estimate quadratically to lambda = -1 (no angle error)
    and return the share of the estimate the angle errors account for, 1 - theta(-1)/theta(0).
    ~1: the term exists only because the angles are noisy; <= 0: a real, attenuated effect."""
    if not simex or not (math.isfinite(est) and est != 0.0):
        return float("nan")
    means = []
    for lam in SIMEX_LAMBDAS:
        th = []
        for i, sig in enumerate(simex[lam]):
            key = (model.channel, lam, i)
            if cache is None or key not in cache:
                base = _regressor_matrix(model, sig)
                if cache is not None:
                    cache[key] = base
            else:
                base = cache[key]
            A = np.column_stack([base, c.regressor(sig)])
            if np.all(np.isfinite(A)):
                th.append(_scaled_lstsq(A, y)[-1])
        if not th:
            return float("nan")
        means.append(float(np.mean(th)))
    lam = np.array((0.0, *SIMEX_LAMBDAS))
    coef = np.polyfit(lam, np.array([est, *means]), 2 if len(SIMEX_LAMBDAS) >= 2 else 1)
    theta_0 = float(np.polyval(coef, -1.0))
    return float(1.0 - theta_0 / est)


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
