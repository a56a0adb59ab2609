"""Model structure determination (method.md §11): stepwise regression and PSE.

:func:`stepwise` is Efroymson's classic stepwise regression: starting from the
``forced`` terms (typically the intercept), each pass

1. *enters* the candidate with the largest partial F if that F exceeds
   ``f_enter``, then
2. *removes*, one at a time, the selected (non-forced) term with the smallest
   partial F while that F is below ``f_remove``,

until no term enters.  :func:`pse_search` is forward selection on Morelli's
predicted squared error (PSE) instead; both record every step (action, term,
partial F, R^2, PSE) and mark the PSE-minimising model on the path.

Partial F, plain and corrected
------------------------------
For one term j added to (or kept in) a model, the classical partial F
``(RSS_without - RSS_with) / s^2_with`` equals ``t_j^2`` with the OLS sigma.
With N ~ 8000 strongly autocorrelated samples that number is inflated roughly by
``N / N_eff`` (hundreds), so nearly every candidate would enter.  The
*corrected* partial F is ``theta_j^2 / sigma_j^2`` with sigma from the
coloured-residual covariance of :func:`aerosid.identification.regression.fit_linear`
(Morelli-Klein by default), i.e. the Wald F(1, dof_eff) statistic.  Decisions
use the corrected partial F by default (``criterion="corrected"``); both values
are recorded in every step.  With ``cov="ols"`` the two coincide.

PSE (``PSE = RSS/N + sigma2_max p / N``) uses one ``sigma2_max`` (variance of
the response about its mean) for every model of the search, as Morelli
prescribes.  Note that its penalty uses the nominal N: on strongly coloured
data PSE is permissive; it is reported, the corrected F decides.

The candidate DataFrame must contain every term, including the intercept
column (ones) which is normally listed in ``forced``.  Rows with NaN in the
response or in any candidate column are dropped once, so every model of a
search is fitted on the same rows.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
import pandas as pd

from aerosid.identification.regression import LinearFit, fit_linear

__all__ = ["Step", "StepwiseResult", "stepwise", "pse_search"]

_CRITERIA = ("corrected", "plain")


@dataclass(frozen=True)
class Step:
    """One step of a structure search.

    ``action`` is ``"start"`` (forced terms only), ``"enter"``, ``"remove"`` or
    ``"stop"`` (no further change; ``term``/partial F then describe the best
    candidate that was *not* entered, if any).  ``partial_f`` is the value the
    decision used.  ``r2``/``pse``/``n_eff`` describe the model after the step.
    """

    index: int
    action: str
    term: str | None
    partial_f: float
    partial_f_plain: float
    partial_f_corrected: float
    r2: float
    pse: float
    n_eff: float
    names: tuple[str, ...]


@dataclass(frozen=True, eq=False)
class StepwiseResult:
    """Outcome of :func:`stepwise` or :func:`pse_search`."""

    method: str  # "stepwise" or "pse"
    steps: tuple[Step, ...]
    selected: tuple[str, ...]
    final: LinearFit
    forced: tuple[str, ...]
    candidates: tuple[str, ...]
    criterion: str
    f_enter: float
    f_remove: float
    pse_best_step: int
    pse_best_names: tuple[str, ...]
    n_dropped: int
    notes: tuple[str, ...] = field(default=())

    @property
    def rejected(self) -> tuple[str, ...]:
        """Candidates not in the selected model."""
        return tuple(c for c in self.candidates if c not in self.selected)

    def summary(self) -> str:
        width = 100
        title = "Stepwise regression (Efroymson)" if self.method == "stepwise" else "PSE forward selection"
        lines = [f"{title}: {self.final.channel or 'y'}".center(width), "=" * width]
        if self.method == "stepwise":
            lines.append(
                f"criterion: {self.criterion} partial F   F-to-enter {self.f_enter:g}   "
                f"F-to-remove {self.f_remove:g}   cov: {self.final.method}"
            )
        else:
            lines.append(f"criterion: minimum PSE   cov: {self.final.method}")
        lines.append(f"forced: {', '.join(self.forced) or '-'}   candidates: {', '.join(self.candidates)}")
        lines.append("-" * width)
        lines.append(
            f"{'step':>4}  {'action':<7}{'term':<18}{'F used':>10}{'F plain':>12}{'F corr.':>10}"
            f"{'R^2':>11}{'PSE':>12}{'N_eff':>8}  {'':<3}"
        )
        lines.append("-" * width)

        def g(x: float, fmt: str) -> str:
            return "-" if not np.isfinite(x) else format(x, fmt)

        for s in self.steps:
            mark = "<- min PSE" if s.index == self.pse_best_step else ""
            lines.append(
                f"{s.index:>4}  {s.action:<7}{(s.term or '-'):<18}{g(s.partial_f, '.4g'):>10}"
                f"{g(s.partial_f_plain, '.4g'):>12}{g(s.partial_f_corrected, '.4g'):>10}"
                f"{g(s.r2, '.6f'):>11}{g(s.pse, '.4g'):>12}{g(s.n_eff, '.1f'):>8}  {mark}"
            )
        lines.append("-" * width)
        lines.append(f"selected: {', '.join(self.selected)}")
        lines.append(f"min-PSE model (step {self.pse_best_step}): {', '.join(self.pse_best_names)}")
        if self.n_dropped:
            lines.append(f"rows dropped (NaN): {self.n_dropped}")
        for i, n in enumerate(self.notes, start=1):
            lines.append(f"[{i}] {n}")
        lines.append("")
        lines.append(self.final.summary())
        return "\n".join(lines)

    def __str__(self) -> str:  # pragma: no cover
        return self.summary()


# --------------------------------------------------------------------------- helpers
def _prepare(y: Any, candidates: pd.DataFrame, forced: Sequence[str]):
    if not isinstance(candidates, pd.DataFrame):
        raise TypeError("candidates must be a pandas DataFrame of named terms")
    cols = [str(c) for c in candidates.columns]
    if len(set(cols)) != len(cols):
        raise ValueError(f"duplicate candidate names: {cols}")
    forced = tuple(str(f) for f in forced)
    missing = [f for f in forced if f not in cols]
    if missing:
        raise KeyError(f"forced terms not among the candidate columns: {missing}")
    yv = np.asarray(y, dtype=float).reshape(-1)
    A = candidates.to_numpy(dtype=float)
    if yv.size != A.shape[0]:
        raise ValueError(f"y has {yv.size} rows, candidates have {A.shape[0]}")
    ok = np.isfinite(yv) & np.all(np.isfinite(A), axis=1)
    data = pd.DataFrame(A[ok], columns=cols)
    yv = yv[ok]
    sigma2_max = float(np.mean((yv - yv.mean()) ** 2))
    free = tuple(c for c in cols if c not in forced)
    return yv, data, forced, free, sigma2_max, int((~ok).sum())


class _Fitter:
    """Caches fits of column subsets (order-independent key, column order as in data)."""

    def __init__(self, y, data, channel, fit_kw, sigma2_max):
        self.y, self.data, self.channel, self.kw, self.s2 = y, data, channel, fit_kw, sigma2_max
        self.order = {c: i for i, c in enumerate(data.columns)}
        self.cache: dict[frozenset, LinearFit] = {}

    def __call__(self, terms) -> LinearFit:
        key = frozenset(terms)
        if key not in self.cache:
            cols = sorted(key, key=self.order.__getitem__)
            self.cache[key] = fit_linear(
                self.y, self.data[cols], channel=self.channel, sigma2_max=self.s2, **self.kw
            )
        return self.cache[key]


def _term_f(fit: LinearFit, term: str) -> tuple[float, float]:
    """(plain, corrected) partial F of one term in a fit; NaN when not identifiable."""
    i = fit.names.index(term)
    if not fit.identifiable[i]:
        return np.nan, np.nan
    th = fit.estimate[i]
    return float((th / fit.std_error_ols[i]) ** 2), float((th / fit.std_error[i]) ** 2)


def _model_stats(fitter: _Fitter, terms) -> tuple[float, float, float]:
    if not terms:
        y = fitter.y
        return 0.0, float(np.mean(y**2)), np.nan  # empty model: residual = y, p = 0
    f = fitter(terms)
    return f.r2, f.pse, f.n_eff


def _pse_best(steps: list[Step]) -> int:
    pses = np.array([s.pse if s.action != "stop" else np.inf for s in steps])
    return int(np.nanargmin(pses))


# --------------------------------------------------------------------------- stepwise
def stepwise(
    y: Any,
    candidates: pd.DataFrame,
    *,
    forced: Sequence[str] = (),
    f_enter: float = 4.0,
    f_remove: float = 3.9,
    max_terms: int | None = None,
    cov: str = "morelli_klein",
    criterion: str = "corrected",
    channel: str = "",
    block: int | None = None,
    hac_maxlags: int | None = None,
    max_steps: int = 200,
) -> StepwiseResult:
    """Efroymson stepwise regression with partial F to enter and to remove.

    Parameters
    ----------
    y : (N,) response.
    candidates : DataFrame of all terms (intercept column included), named.
    forced : terms always in the model (never removed), e.g. the intercept.
    f_enter, f_remove : partial-F thresholds; ``f_remove <= f_enter`` is
        required (otherwise a term could cycle in and out).
    max_terms : maximum number of selected non-forced terms (None: no limit).
    cov : covariance correction passed to :func:`fit_linear`.
    criterion : ``"corrected"`` (default; partial F from the coloured-residual
        sigma) or ``"plain"`` (classical OLS partial F).
    """
    if criterion not in _CRITERIA:
        raise ValueError(f"criterion must be one of {_CRITERIA}")
    if f_remove > f_enter:
        raise ValueError(f"f_remove ({f_remove}) must not exceed f_enter ({f_enter})")
    yv, data, forced, free, s2max, n_drop = _prepare(y, candidates, forced)
    fitter = _Fitter(yv, data, channel, dict(cov=cov, block=block, hac_maxlags=hac_maxlags), s2max)
    pick = 1 if criterion == "corrected" else 0

    model: list[str] = list(forced)
    r2, pse, neff = _model_stats(fitter, model)
    steps = [Step(0, "start", None, np.nan, np.nan, np.nan, r2, pse, neff, tuple(model))]
    notes: list[str] = []
    seen = {frozenset(model)}

    def add_step(action, term, fs):
        r2_, pse_, neff_ = _model_stats(fitter, model)
        steps.append(Step(len(steps), action, term, fs[pick], fs[0], fs[1], r2_, pse_, neff_, tuple(model)))

    while len(steps) < max_steps:
        n_sel = len(model) - len(forced)
        outside = [c for c in free if c not in model]
        best_term, best_fs = None, (np.nan, np.nan)
        for c in outside:
            fs = _term_f(fitter(model + [c]), c)
            if np.isfinite(fs[pick]) and (best_term is None or fs[pick] > best_fs[pick]):
                best_term, best_fs = c, fs
        can_enter = max_terms is None or n_sel < max_terms
        if best_term is None or not can_enter or not best_fs[pick] > f_enter:
            if best_term is not None and can_enter:
                r2_, pse_, neff_ = _model_stats(fitter, model)
                steps.append(Step(len(steps), "stop", best_term, best_fs[pick], best_fs[0], best_fs[1],
                                  r2_, pse_, neff_, tuple(model)))
            elif not can_enter:
                notes.append(f"stopped at max_terms = {max_terms}")
            break
        model.append(best_term)
        add_step("enter", best_term, best_fs)
        # backward elimination
        while len(steps) < max_steps:
            fit = fitter(model)
            scored = []
            for c in model:
                if c in forced:
                    continue
                fs = _term_f(fit, c)
                scored.append((fs[pick] if np.isfinite(fs[pick]) else -np.inf, c, fs))
            if not scored:
                break
            v, worst, worst_fs = min(scored, key=lambda t: t[0])
            if not v < f_remove:
                break
            model.remove(worst)
            add_step("remove", worst, worst_fs)
        state = frozenset(model)
        if state in seen and steps[-1].action == "remove":
            notes.append("stopped: the search returned to a model already visited (cycle)")
            break
        seen.add(state)
    else:
        notes.append(f"stopped after max_steps = {max_steps}")

    final_terms = model if model else list(forced)
    if not final_terms:
        raise ValueError("empty model: no forced term and no candidate entered")
    final = fitter(final_terms)
    best = _pse_best(steps)
    return StepwiseResult(
        method="stepwise",
        steps=tuple(steps),
        selected=final.names,
        final=final,
        forced=forced,
        candidates=free,
        criterion=criterion,
        f_enter=float(f_enter),
        f_remove=float(f_remove),
        pse_best_step=best,
        pse_best_names=steps[best].names,
        n_dropped=n_drop,
        notes=tuple(notes),
    )


# --------------------------------------------------------------------------- PSE
def pse_search(
    y: Any,
    candidates: pd.DataFrame,
    *,
    forced: Sequence[str] = (),
    max_terms: int | None = None,
    cov: str = "morelli_klein",
    channel: str = "",
    block: int | None = None,
    hac_maxlags: int | None = None,
) -> StepwiseResult:
    """Forward selection on Morelli's PSE; the PSE-minimising model is selected.

    Each step enters the candidate that lowers PSE the most; the search runs
    through all candidates (or ``max_terms``) so the whole PSE path is
    recorded, and the model at the PSE minimum is returned as ``final``.
    Partial F (plain and corrected) of each entering term is recorded too.
    """
    yv, data, forced, free, s2max, n_drop = _prepare(y, candidates, forced)
    fitter = _Fitter(yv, data, channel, dict(cov=cov, block=block, hac_maxlags=hac_maxlags), s2max)
    model: list[str] = list(forced)
    r2, pse, neff = _model_stats(fitter, model)
    steps = [Step(0, "start", None, np.nan, np.nan, np.nan, r2, pse, neff, tuple(model))]
    limit = len(free) if max_terms is None else min(max_terms, len(free))
    for _ in range(limit):
        best, best_pse = None, np.inf
        for c in free:
            if c in model:
                continue
            f = fitter(model + [c])
            if f.identifiable[f.names.index(c)] and f.pse < best_pse:
                best, best_pse = c, f.pse
        if best is None:
            break
        model.append(best)
        fs = _term_f(fitter(model), best)
        r2, pse, neff = _model_stats(fitter, model)
        steps.append(Step(len(steps), "enter", best, np.nan, fs[0], fs[1], r2, pse, neff, tuple(model)))
    best_step = _pse_best(steps)
    names = list(steps[best_step].names)
    if not names:
        raise ValueError("the PSE minimum is the empty model; pass the intercept in forced")
    final = fitter(names)
    return StepwiseResult(
        method="pse",
        steps=tuple(steps),
        selected=final.names,
        final=final,
        forced=forced,
        candidates=free,
        criterion="pse",
        f_enter=np.nan,
        f_remove=np.nan,
        pse_best_step=best_step,
        pse_best_names=tuple(names),
        n_dropped=n_drop,
    )
