"""The diagnosis' results: the evidence per candidate, per-window and per-regime residual
statistics, whiteness, the per-channel report and :class:`Diagnosis` with its summary,
message and JSON (aerosid.diagnosis.core computes them)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from aerosid.diagnosis.rule import (FLAG_RATIO, MIN_BIN_SAMPLES, MIN_VARIANCE_SHARE, MIN_WINDOW_CONSISTENCY, P_MAX,
                                    RULE_TEXT, _f)
from aerosid.identification.regression import LinearFit
from aerosid.modelling.model_specs import paste_lines


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


#: The first sentence of a diagnosis of a flight its vehicle file marks as turbulent.
TURBULENT_AIR_CAVEAT = ("Turbulent air ([estimation] turbulent_air = true): the coefficients come from instrumental "
                        "variables, but this diagnosis still fits by least squares, which the gusts' rotation "
                        "biases, so read its verdict below as a hint only.")


def pooled_wording(text: str, n_flights: int) -> str:
    """A diagnosis text about one flight, reworded for `n_flights` pooled flights (unchanged
    for one): what was or was not separable is a property of the data as pooled."""
    if n_flights <= 1:
        return text
    these = f"these {n_flights} pooled flights"
    for one, many in (("on this flight", f"on {these}"), ("by this flight", f"by {these}"),
                      ("This flight could not", f"These {n_flights} pooled flights could not"),
                      ("this flight could not", f"{these} could not")):
        text = text.replace(one, many)
    return text


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
        """Nothing significant is missing (in the catalogue or outside it: no significant
        localisation finding) and no look-alike choice is open or refuted."""
        return self.nothing_significant and not self.localised and not any(
            c.swap or (c.in_model and c.verdict != "separated") for c in self.lookalikes)
    #: channel -> localisation findings (aerosid.diagnosis.localise), best first
    localisation: dict = field(default_factory=dict)
    #: flights pooled in the diagnosed data (`aerosid run A B`): the message speaks of "these N
    #: pooled flights" instead of "this flight"
    n_flights: int = 1
    #: the vehicle file says the flight was turbulent ([estimation] turbulent_air): the diagnosis
    #: still fits by least squares, which the gusts bias, and its message says so first
    turbulent_air: bool = False

    @property
    def significant(self) -> tuple[EffectEvidence, ...]:
        return tuple(e for e in self.effects if e.significant)

    @property
    def nothing_significant(self) -> bool:
        """No catalogue candidate passes the rule (the localisation may still find a term)."""
        return not self.significant

    @property
    def localised(self) -> tuple:
        """The significant localisation findings (terms outside the catalogue)."""
        return tuple(f for fs in self.localisation.values() for f in fs if f.significant)

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

        text = pooled_wording(lookalike_message(self, self._base_message()), self.n_flights)
        return TURBULENT_AIR_CAVEAT + " " + text if self.turbulent_air else text

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
                          + ", ".join(f"{e.name} |{e.coefficient}| {e.detectable_size:.3g}" for e in floors)
                          + " (`aerosid design RUN_DIR --effect NAME --out DIR` proposes a manoeuvre that would).")
        unident = [e.name for e in self.effects if not e.identifiable]
        cannot = (f" Not separable from the model's own terms on this flight (so not tested): "
                  f"{', '.join(unident)}." if unident else "")
        head = ("Nothing significant is missing: no candidate effect passes" if not self.localised else
                "No catalogue effect is missing, but the model is not complete (the localisation below finds a "
                "term outside the catalogue): no candidate effect passes")
        return (f"{head} the rule (corrected p < "
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
            "n_flights": self.n_flights,
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
