"""Look-alikes resolved, not guessed (issue 18 item 1).

Two candidate effects are *look-alikes* on a flight when the parts of their regressors
the model cannot explain correlate by |r| >= ``CONFUSION_R`` (``confused_with``), e.g.
control_alpha (alpha delta_p / 2) and alpha_nonlinearity (alpha |alpha|) in Cm on
seed-rlv (r ~ 0.95: the pitch fin follows alpha through the trim).  Their partial F
values are then close, and ranking by them picks the wrong one on some flights.

:func:`compare` fits each alternative (base + i), and the base with all of them, and
reports what distinguishes them:

* ``delta_evidence`` (the criterion): in the joint fit base + i + j, the corrected t of
  each given the other; ``Delta_ij = t_i|j^2 - t_j|i^2`` is (for equal-sized models) the
  coloured-residual corrected log-likelihood ratio x 2 of "base + i" over "base + j"
  (the J-test's encompassing statistics).  i is *separated* from j when Delta_ij >=
  ``DELTA_MIN`` = 2 ln 19 (Akaike weight >= 95 %) **and** held-out prediction agrees;
* held-out prediction: leave-one-window-out (fit without time block k, predict block k)
  squared error of each alternative, its RMS and the blocks where it is better;
* coefficient shifts: how far each alternative moves the base coefficients, in units
  of their (corrected) sigma in the base fit; a look-alike that is *not* in the data
  has to bend the model's own coefficients to mimic the true term (seen: Cm_alpha
  moved 7-9 sigma by alpha_nonlinearity in control_alpha flights, 2-3 by control_alpha);
* partial residuals (added-variable data): the regressor and the measured coefficient
  each with base + the other alternatives removed; the slope is the joint-fit estimate.

The recommendation is the alternative separated from every other one; else ``None``,
with a message that says so and names the manoeuvre that would separate them (the
signals one term has and the other lacks, varied at two levels of the signals they
share).  When every alternative stays significant given the others (p < P_MAX) they are
not look-alikes but distinct effects: the first is recommended.

:func:`model_lookalikes` runs the same comparison when the *model* already holds one of
a look-alike pair (the re-diagnosis after a fit): base = model without that term,
alternatives = the term and its look-alikes.  If the data prefer the one not in the
model, the recommendation is to swap; if they cannot tell, the loop is not closed.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import scipy.stats

from aerosid.identification.regression import fit_linear

__all__ = ["Alternative", "LookalikeComparison", "compare", "model_lookalikes", "separating_manoeuvre",
           "heldout_sse", "scaled_lstsq", "windows_index", "resolve", "lookalike_message", "DELTA_MIN", "LOOKALIKE_WINDOWS", "MAX_ALTERNATIVES"]

DELTA_MIN = 2.0 * math.log(19.0)
"""Smallest Delta_ij = t_i|j^2 - t_j|i^2 to call i separated from j (Akaike weight >= 95 %)."""
LOOKALIKE_WINDOWS = 16
"""Time blocks of the held-out comparison."""
MAX_ALTERNATIVES = 4
"""At most this many alternatives are compared (the top candidate and its look-alikes)."""
PARTIAL_BINS = 20
"""Quantile bins of the binned partial-residual data in the JSON."""

_SIGNALS = ("alpha_r", "alpha_dot", "alpha", "beta_dot", "beta", "phi_r", "mach", "qbar", "delta_p", "delta_y",
            "delta_r", "p_hat", "q_hat", "r_hat", "p", "q", "r", "V", "t")
_LEVEL_WORDS = {"alpha": "alpha", "beta": "beta", "mach": "Mach", "qbar": "dynamic pressure", "phi_r": "roll angle",
                "alpha_r": "total angle of attack", "delta_p": "pitch-fin deflection",
                "delta_y": "yaw-fin deflection", "delta_r": "roll-fin deflection"}


def scaled_lstsq(A: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least squares with the columns scaled to unit norm (well conditioned for mixed units)."""
    s = np.linalg.norm(A, axis=0)
    s[s == 0] = 1.0
    c, *_ = np.linalg.lstsq(A / s, y, rcond=None)
    return c / s


def heldout_sse(A: np.ndarray, y: np.ndarray, win: np.ndarray) -> np.ndarray:
    """Squared prediction error on each time block of a fit made without it (NaN for a
    block that is empty or the whole record)."""
    out = np.zeros(int(win.max()) + 1)
    for k in range(out.size):
        test = win == k
        if test.all() or not test.any():
            out[k] = np.nan
            continue
        c = scaled_lstsq(A[~test], y[~test])
        e = y[test] - A[test] @ c
        out[k] = float(e @ e)
    return out


def windows_index(n: int, n_windows: int) -> np.ndarray:
    k = max(1, min(int(n_windows), n))
    return np.minimum((np.arange(n) * k) // n, k - 1)


@dataclass(frozen=True)
class Alternative:
    """One alternative of a look-alike comparison (base + this term)."""

    name: str
    coefficient: str
    term: str
    spec_term: str | None
    in_model: bool
    estimate: float  # in base + this term
    std_error: float
    estimate_joint: float  # in base + all alternatives
    std_error_joint: float
    t_joint: float
    heldout_rms: float  # leave-one-window-out prediction RMS of base + this term
    heldout_sse: np.ndarray = field(repr=False)
    coefficient_shift_sigma: dict = field(default_factory=dict)  # base coefficient -> shift / base sigma
    partial_x: np.ndarray = field(repr=False, default=None)  # term with base + the others removed
    partial_y: np.ndarray = field(repr=False, default=None)  # measured with base + the others removed
    p_value: float = float("nan")  # corrected p of the term in base + this term

    @property
    def max_shift_sigma(self) -> float:
        v = [abs(x) for x in self.coefficient_shift_sigma.values() if math.isfinite(x)]
        return max(v) if v else float("nan")

    def partial_binned(self, bins: int = PARTIAL_BINS) -> dict:
        """Quantile-binned partial residuals: x centre, mean of y, count (for a plot)."""
        x, y = self.partial_x, self.partial_y
        if x is None or x.size < bins:
            return {"x": [], "y": [], "n": []}
        edges = np.unique(np.quantile(x, np.linspace(0, 1, bins + 1)))
        idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, edges.size - 2)
        xs, ys, ns = [], [], []
        for b in range(edges.size - 1):
            m = idx == b
            if m.any():
                xs.append(float(x[m].mean()))
                ys.append(float(y[m].mean()))
                ns.append(int(m.sum()))
        return {"x": xs, "y": ys, "n": ns}

    def to_dict(self) -> dict:
        f = _f
        return {"name": self.name, "coefficient": self.coefficient, "term": self.term, "spec_term": self.spec_term,
                "in_model": self.in_model, "estimate": f(self.estimate), "std_error": f(self.std_error),
                "estimate_joint": f(self.estimate_joint), "std_error_joint": f(self.std_error_joint),
                "t_joint": f(self.t_joint), "p_value": f(self.p_value), "heldout_rms": f(self.heldout_rms),
                "heldout_sse_per_window": [f(x) for x in self.heldout_sse],
                "coefficient_shift_sigma": {k: f(v) for k, v in self.coefficient_shift_sigma.items()},
                "max_shift_sigma": f(self.max_shift_sigma), "partial_residuals_binned": self.partial_binned()}


@dataclass(frozen=True)
class LookalikeComparison:
    """The comparison of look-alike alternatives in one channel."""

    channel: str
    alternatives: tuple[Alternative, ...]
    correlation: dict  # "a|b" -> |r| of the base-residualised regressors
    delta: dict  # "a>b" -> Delta_ab = t_a|b^2 - t_b|a^2 (joint fit of the pair with the base)
    heldout_windows_better: dict  # "a>b" -> fraction of time blocks where a predicts better than b
    recommended: str | None
    verdict: str  # "separated", "distinct", "unresolved"
    criterion: str
    manoeuvre: str
    message: str
    dof_eff: float = float("nan")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(a.name for a in self.alternatives)

    def alternative(self, name: str) -> Alternative:
        for a in self.alternatives:
            if a.name == name:
                return a
        raise KeyError(name)

    @property
    def in_model(self) -> str | None:
        return next((a.name for a in self.alternatives if a.in_model), None)

    @property
    def swap(self) -> bool:
        """The model holds one alternative and the data prefer another."""
        return (self.verdict == "separated" and self.in_model is not None and self.recommended is not None
                and self.recommended != self.in_model)

    def to_dict(self) -> dict:
        return {"channel": self.channel, "alternatives": [a.to_dict() for a in self.alternatives],
                "correlation": {k: _f(v) for k, v in self.correlation.items()},
                "delta": {k: _f(v) for k, v in self.delta.items()},
                "heldout_windows_better": {k: _f(v) for k, v in self.heldout_windows_better.items()},
                "recommended": self.recommended, "verdict": self.verdict, "in_model": self.in_model,
                "swap": self.swap, "criterion": self.criterion, "separating_manoeuvre": self.manoeuvre,
                "message": self.message, "delta_min": DELTA_MIN}

    def summary(self) -> str:
        lines = [f"Look-alikes in {self.channel}: {', '.join(self.names)} ({self.verdict})",
                 f"  {'alternative':<22}{'estimate':>11}{'sigma':>10}{'t | others':>11}{'held-out RMS':>14}"
                 f"{'max shift of the model coefficients [sigma]':>45}"]
        for a in self.alternatives:
            lines.append(f"  {a.name + (' (in model)' if a.in_model else ''):<22}{a.estimate:>11.4g}"
                         f"{a.std_error:>10.3g}{a.t_joint:>11.2f}{a.heldout_rms:>14.4g}{a.max_shift_sigma:>45.1f}")
        for k, v in self.delta.items():
            lines.append(f"  Delta {k} = {v:.2f} (>= {DELTA_MIN:.2f} to separate); held-out better in "
                         f"{self.heldout_windows_better.get(k, float('nan')):.0%} of the blocks")
        lines.append("  " + self.message)
        return "\n".join(lines)


def _f(x):
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _signals_in(term: str) -> set[str]:
    words = set(re.findall(r"[A-Za-z_][A-Za-z_0-9]*", term))
    return {w for w in words if w in _SIGNALS}


#: Below this Mach number compressibility is negligible: a Mach term fitted there stands for a
#: dependence on airspeed (propeller slipstream, thrust, dynamic pressure), and the manoeuvre
#: that separates it is flown at distinct airspeeds, not Mach levels.
INCOMPRESSIBLE_MACH = 0.3


def separating_manoeuvre(term_a: str, term_b: str, mach: float | None = None) -> str:
    """A manoeuvre that makes the two terms vary independently: the signals one has and the
    other lacks, flown at two distinct levels of the signals they share.  mach: the flight's
    typical Mach number [-]; below INCOMPRESSIBLE_MACH "Mach" is said as airspeed."""
    sa, sb = _signals_in(term_a), _signals_in(term_b)
    only = sorted((sa ^ sb) - {"t"})
    common = sorted(sa & sb)
    low_speed = mach is not None and math.isfinite(mach) and mach < INCOMPRESSIBLE_MACH
    words = dict(_LEVEL_WORDS, mach="airspeed") if low_speed else _LEVEL_WORDS
    word = lambda s: words.get(s, s)  # noqa: E731
    note = (f" (at Mach {mach:.2f} a Mach term stands for a dependence on airspeed: propeller slipstream, thrust, "
            "dynamic pressure; compressibility is negligible below Mach 0.3)"
            if low_speed and "mach" in sa | sb else "")
    return _manoeuvre_text(only, common, word, term_a, term_b) + note


def _manoeuvre_text(only: list, common: list, word, term_a: str, term_b: str) -> str:
    if only and common:
        return (f"fly {' and '.join(word(s) for s in only)} excursions at two (or more) distinct "
                f"{' and '.join(word(s) for s in common)} levels, e.g. pitch doublets at two trim angles"
                if "delta_p" in only and "alpha" in common else
                f"fly {' and '.join(word(s) for s in only)} excursions at two (or more) distinct "
                f"{' and '.join(word(s) for s in common)} levels")
    if only:
        return f"fly a manoeuvre in which {' and '.join(word(s) for s in only)} vary independently of each other"
    return (f"fly a manoeuvre in which `{term_a}` and `{term_b}` vary independently (they use the same signals: "
            "larger excursions of them)")


def compare(channel: str, y: np.ndarray, base_X: np.ndarray, base_names: Sequence[str], alternatives: Sequence,
            regressors: Sequence[np.ndarray], *, in_model: str | None = None, n_windows: int = LOOKALIKE_WINDOWS,
            cov: str = "morelli_klein", p_distinct: float = 1e-3, mach: float | None = None) -> LookalikeComparison:
    """Compare look-alike alternatives (candidates with name, coefficient, term, spec_term)
    each added alone to the base design, see module doc.  mach: the flight's typical Mach
    number, for the wording of the separating manoeuvre (:func:`separating_manoeuvre`)."""
    y = np.asarray(y, float)
    A = np.asarray(base_X, float)
    X = [np.asarray(x, float) for x in regressors]
    k = len(alternatives)
    nb = A.shape[1]
    win = windows_index(y.size, n_windows)
    base = fit_linear(y, A, names=list(base_names), channel=channel, cov=cov)
    names = [c.name for c in alternatives]
    coefs = [f"{c.coefficient}__{i}" for i, c in enumerate(alternatives)]
    joint = fit_linear(y, np.column_stack([A, *X]), names=list(base_names) + coefs, channel=channel, cov=cov)
    perps = [x - A @ scaled_lstsq(A, x) for x in X]
    corr, delta, better = {}, {}, {}
    sse = [heldout_sse(np.column_stack([A, x]), y, win) for x in X]
    for i in range(k):
        for j in range(k):
            if i == j:
                continue
            if i < j:
                den = float(np.linalg.norm(perps[i]) * np.linalg.norm(perps[j]))
                corr[f"{names[i]}|{names[j]}"] = abs(float(perps[i] @ perps[j])) / den if den > 0 else float("nan")
            pair = fit_linear(y, np.column_stack([A, X[i], X[j]]), names=list(base_names) + ["a", "b"],
                              channel=channel, cov=cov)
            delta[f"{names[i]}>{names[j]}"] = float(pair.t_values[nb] ** 2 - pair.t_values[nb + 1] ** 2)
            d = sse[j] - sse[i]
            d = d[np.isfinite(d)]
            better[f"{names[i]}>{names[j]}"] = float(np.mean(d > 0)) if d.size else float("nan")
    alts = []
    for i, c in enumerate(alternatives):
        fi = fit_linear(y, np.column_stack([A, X[i]]), names=list(base_names) + [coefs[i]], channel=channel, cov=cov)
        shift = {n: float((fi.estimate[m] - base.estimate[m]) / base.std_error[m]) if base.std_error[m] > 0
                 else float("nan") for m, n in enumerate(base_names)}
        others = [X[j] for j in range(k) if j != i]
        R = np.column_stack([A, *others]) if others else A
        px = X[i] - R @ scaled_lstsq(R, X[i])
        py = y - R @ scaled_lstsq(R, y)
        tot = sse[i][np.isfinite(sse[i])]
        alts.append(Alternative(
            c.name, c.coefficient, c.term, getattr(c, "spec_term", None), c.name == in_model,
            float(fi.estimate[nb]), float(fi.std_error[nb]), float(joint.estimate[nb + i]),
            float(joint.std_error[nb + i]), float(joint.t_values[nb + i]),
            float(math.sqrt(tot.sum() / y.size)) if tot.size else float("nan"), sse[i], shift, px, py,
            float(fi.p_values[nb])))
    # the criterion
    t_distinct = float(scipy.stats.t.isf(p_distinct / 2.0, joint.dof_eff))
    criterion = (f"separated = Delta_ij = t_i|j^2 - t_j|i^2 >= {DELTA_MIN:.2f} (2 ln 19: the coloured-residual "
                 "corrected likelihood ratio gives it >= 95 % weight) against every other alternative, and a "
                 f"lower leave-one-window-out prediction error ({n_windows} time blocks); distinct = every "
                 f"alternative keeps p < {p_distinct:g} given the others")
    heldout = {a.name: a.heldout_rms for a in alts}
    winner = None
    for i in range(k):
        if all(delta[f"{names[i]}>{names[j]}"] >= DELTA_MIN and heldout[names[i]] < heldout[names[j]]
               for j in range(k) if j != i):
            winner = names[i]
            break
    distinct = bool(k > 1 and np.all(np.abs(joint.t_values[nb:]) >= t_distinct))
    ref = alternatives[0]
    other = alternatives[1] if k > 1 else alternatives[0]
    manoeuvre = separating_manoeuvre(ref.term, other.term, mach)
    pair_txt = " and ".join(names)
    if distinct:
        verdict = "distinct"
        missing = [n for n in names if n != in_model]
        recommended = missing[0] if missing else names[0]
        add = " and ".join(missing)
        msg = (f"{pair_txt} are {'both' if k == 2 else 'all'} needed in {channel}: each keeps p < {p_distinct:g} "
               f"with the other{'' if k == 2 else 's'} in the model (|t| "
               f"{', '.join(f'{abs(a.t_joint):.1f}' for a in alts)} >= {t_distinct:.1f}); add {add}"
               + (" as well" if in_model else "") + (f" ({recommended} first)." if len(missing) > 1 else "."))
    elif winner is not None:
        verdict = "separated"
        w = next(a for a in alts if a.name == winner)
        losers = [a for a in alts if a.name != winner]
        dmin = min(delta[f"{winner}>{a.name}"] for a in losers)
        msg = (f"{pair_txt} look alike in {channel} (their parts the model cannot explain correlate by "
               f"r = {max(corr.values()):.2f}); the data separate them: {winner} (Delta >= {dmin:.1f} >= "
               f"{DELTA_MIN:.2f}; held-out prediction RMS {w.heldout_rms:.4g} vs "
               + ", ".join(f"{a.heldout_rms:.4g} ({a.name})" for a in losers)
               + f"; it moves the model's coefficients by at most {w.max_shift_sigma:.1f} sigma vs "
               + ", ".join(f"{a.max_shift_sigma:.1f} ({a.name})" for a in losers) + ").")
        recommended = winner
        if in_model and winner != in_model:
            msg += (f" The model holds {in_model}: replace it by {winner} (in the spec: remove = "
                    f"[\"{in_model}\"], add = [\"{w.spec_term or w.coefficient}\"]).")
    else:
        verdict = "unresolved"
        recommended = None
        ds = ", ".join(f"{kk} {v:.1f}" for kk, v in delta.items() if v > 0) or "none positive"
        msg = (f"{pair_txt} cannot be told apart in {channel} on this flight: their parts the model cannot "
               f"explain correlate by r = {max(corr.values()):.2f} and the evidence does not separate them "
               f"(Delta {ds} < {DELTA_MIN:.2f}, or held-out prediction disagrees). No recommendation. "
               f"To separate them: {manoeuvre}"
               + (f" (`aerosid design RUN_DIR --effect {names[0]} --versus {names[1]} --out DIR` proposes one "
                  "within the vehicle's limits; fly it and run both flights together: "
                  "`aerosid run TELEMETRY NEW_TELEMETRY --out DIR`)." if k > 1 else "."))
        if all(not (a.p_value < p_distinct) for a in alts):
            msg += (f" Neither is significant on its own here (p = {', '.join(f'{a.p_value:.2g}' for a in alts)}"
                    f" >= {p_distinct:g})" + (f": the model's {in_model} is not supported by this flight." if in_model
                                              else "."))
        if in_model:
            msg += (f" The model holds {in_model}; this flight cannot confirm it over "
                    f"{', '.join(n for n in names if n != in_model)}: the loop is not closed.")
    return LookalikeComparison(channel, tuple(alts), corr, delta, better, recommended, verdict, criterion,
                               manoeuvre, msg, float(joint.dof_eff))


def model_lookalikes(channel: str, y: np.ndarray, model, signals: dict, candidates: Sequence, *,
                     confusion_r: float, p_max: float, cov: str = "morelli_klein"
                     ) -> list[LookalikeComparison]:
    """For each term of `model` that is a candidate effect (same effect name or expression),
    compare it with the candidates not in the model whose regressors, with the rest of the
    model removed, correlate with it by >= confusion_r.  Whether or not the term is
    significant in the model: a term the data do not support, with a look-alike the data
    support as little, is not a confirmed choice either (the loop stays open)."""
    out = []
    Xm, _ = model.design(signals)
    Am = Xm.to_numpy(float)
    by_name = {c.name: c for c in candidates if c.channel == channel}
    norm = lambda s: s.replace(" ", "")  # noqa: E731
    for m, t in enumerate(model.terms):
        cand = by_name.get(t.effect or "") or next((c for c in by_name.values()
                                                     if norm(c.term) == norm(t.expression)), None)
        if cand is None:
            continue
        keep = [i for i in range(Am.shape[1]) if i != m]
        A = Am[:, keep]
        x_in = Am[:, m]
        p_in = x_in - A @ scaled_lstsq(A, x_in)
        alts, regs = [cand], [x_in]
        for c in by_name.values():
            if c.name == cand.name or c.alias_of == cand.name or cand.alias_of == c.name or any(tt.effect == c.name or norm(tt.expression) == norm(c.term)
                                          or tt.coefficient == c.coefficient for tt in model.terms):
                continue
            x = np.asarray(c.regressor(signals), float)
            if x.shape != y.shape or not np.all(np.isfinite(x)):
                continue
            p = x - A @ scaled_lstsq(A, x)
            den = float(np.linalg.norm(p) * np.linalg.norm(p_in))
            if den > 0 and abs(float(p @ p_in)) / den >= confusion_r:
                alts.append(c)
                regs.append(x)
        if len(alts) > 1:
            alts, regs = alts[:MAX_ALTERNATIVES], regs[:MAX_ALTERNATIVES]
            out.append(compare(channel, y, A, [n for i, n in enumerate(model.names) if i != m], alts, regs,
                               in_model=cand.name, cov=cov, p_distinct=p_max, mach=_typical_mach(signals)))
    return out


def _typical_mach(signals: dict) -> float | None:
    """The median Mach number of the fitted samples, or None without a finite one."""
    m = np.asarray(signals.get("mach", ()), float)
    m = m[np.isfinite(m)]
    return float(np.median(m)) if m.size else None


def resolve(ranked: Sequence, models: dict, signals: dict, fd, candidates: Sequence, *, confusion_r: float,
            p_max: float, cov: str = "morelli_klein") -> tuple[tuple[LookalikeComparison, ...], str | None]:
    """The look-alike comparisons of a diagnosis and its recommendation (module doc).

    ranked: the EffectEvidence list, best first.  Compares (1) the top significant
    candidate with its look-alikes (``confused_with``) and the other significant
    candidates of its channel, (2) every significant model term that is a candidate with
    its look-alikes outside the model.  recommended: a swap the data support first, then
    the top group's winner (the top candidate when it has no look-alike), else None."""
    comps: list[LookalikeComparison] = []
    for ch, model in models.items():
        y = fd[ch].to_numpy(float)
        comps += model_lookalikes(ch, y, model, signals, candidates, confusion_r=confusion_r, p_max=p_max, cov=cov)
    sig = [e for e in ranked if e.significant]
    recommended = None
    top_comp = None
    if sig:
        top = sig[0]
        group = [top.name] + [n for n in top.confused_with] + [e.name for e in sig[1:] if e.channel == top.channel]
        seen, names = set(), []
        for n in group:
            if n not in seen:
                seen.add(n)
                names.append(n)
        by_name = {c.name: c for c in candidates if c.channel == top.channel}
        ev = {e.name: e for e in ranked if e.channel == top.channel}
        # an alias (alpha_dot under pitch_damping) is one derivative reported together, not a look-alike
        names = [n for n in names if n in by_name and ev.get(n) is not None and ev[n].identifiable
                 and (n == top.name or (by_name[n].alias_of != top.name
                                        and by_name[top.name].alias_of != n))][:MAX_ALTERNATIVES]
        if len(names) > 1:
            model = models[top.channel]
            Xb, _ = model.design(signals)
            y = fd[top.channel].to_numpy(float)
            top_comp = compare(top.channel, y, Xb.to_numpy(float), list(model.names), [by_name[n] for n in names],
                               [np.asarray(by_name[n].regressor(signals), float) for n in names], cov=cov,
                               p_distinct=p_max, mach=_typical_mach(signals))
            comps.insert(0, top_comp)
            recommended = top_comp.recommended
        else:
            recommended = top.name
    swaps = [c for c in comps if c.swap]
    if swaps:
        recommended = swaps[0].recommended
    return tuple(comps), recommended


def lookalike_message(diagnosis, base_message: str) -> str:
    """The diagnosis message with the look-alike verdicts: a guessed 'most likely missing'
    is replaced when the look-alikes are unresolved, and 'nothing significant is missing'
    is not said while the model's own choice among look-alikes is unconfirmed or refuted."""
    comps = diagnosis.lookalikes
    if not comps:
        return base_message
    texts = [c.message for c in comps]
    open_in_model = [c for c in comps if c.in_model and c.verdict != "separated" or c.swap]
    msg = base_message
    if msg.startswith("Nothing significant is missing") and open_in_model:
        msg = ("No further candidate passes the rule, but the loop is not closed: the model's choice among "
               "look-alikes is " + ("refuted by the data" if any(c.swap for c in open_in_model) else
                                    "not confirmed by this flight") + "." + msg[len("Nothing significant is missing"):])
    top = comps[0] if comps and comps[0].in_model is None else None
    if top is not None and top.verdict == "unresolved" and msg.startswith("Most likely missing"):
        msg = (f"Something is missing in {top.channel}, but the candidates that explain it are look-alikes "
               f"({', '.join(top.names)}): no recommendation." + msg[msg.find(" Where the model") if
                                                                       " Where the model" in msg else len(msg):]
               .split("\n\n[", 1)[0])  # no spec lines to paste: they were the guess's
    return " ".join(texts) + " " + msg
