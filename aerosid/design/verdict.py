"""The verdict of ``aerosid design`` (aerosid.design.core): from sigma before (the run) and
after (the design) of one or two target terms, whether the design does what was asked.

One term: DETECTABLE when its size would be found significant (p < 0.001) in POWER of flights,
``|size| >= (t_crit + z_POWER) sigma``; else NO MANOEUVRE WITHIN THE LIMITS, with the sigma the size
needs.  Two terms (``--versus``): SEPARATED when, with both in the model, either present at its
size would be found so (found-from <= |size| for each) and the model's own error on the
manoeuvre (simulators that state their truth) is <= MAX_MODEL_ERROR_PCT.  Either way: NO BETTER
MANOEUVRE WITHIN THE LIMITS when the best candidate identifies the targets no better than the
flown manoeuvre (max sigma/|size| not below the run's): a design never proposes a worse flight.
"""
from __future__ import annotations

import math

from aerosid.design.predict import POWER, Prediction

#: Largest |model error| [%] on the manoeuvre (simulators that state their truth) for two terms to count
#: as separated: beyond it the model cannot fit the shape that separates them.
MAX_MODEL_ERROR_PCT = 10.0


def design_verdict(targets: tuple, sizes: tuple, before: dict, after: dict, after_pred: Prediction,
                   oracle: dict | None, label: str, amplitude_rad: float, worst_limit_use: float,
                   hint=None, time_ratio: float = 1.0) -> tuple[bool, str]:
    """(achievable, verdict text).  before/after: per target {'sigma', 'detectable_size',
    'reliable_size'} (and 'correlation' for two); oracle: the model's error on the manoeuvre per
    target [%] (empty when unknown); label, amplitude_rad, worst_limit_use: the chosen candidate;
    hint: rel_sigma_pct -> text appended to a two-term verdict that fails (e.g. fly power-off);
    time_ratio: the design's time on condition / the run's (the run may be long, or several pooled
    flights: the designs are compared per unit time, sigma x sqrt(time))."""
    a, worst = amplitude_rad, worst_limit_use
    ok = all(after[t]["reliable_size"] <= abs(sz) for t, sz in zip(targets, sizes))
    passes = ok and (len(targets) == 1 or all(abs(v) <= MAX_MODEL_ERROR_PCT for v in (oracle or {}).values()))
    # never propose a manoeuvre that identifies the targets worse than the one flown (per unit
    # time on condition); a design that does what was asked is never called worse
    ratio_before = max(before[t]["sigma"] / abs(sz) for t, sz in zip(targets, sizes))
    ratio_after = max(after[t]["sigma"] / abs(sz) for t, sz in zip(targets, sizes)) * math.sqrt(max(time_ratio, 0.0))
    worse = not passes and not ratio_after < ratio_before
    found = "it would be found" if len(targets) == 1 else "each would be found"
    if worse:
        ok = False
        verdict = (f"NO BETTER MANOEUVRE WITHIN THE LIMITS: the best candidate ({label}, {a:.3g} rad) "
                   "gives " + ", ".join(f"sigma({t}) = {after[t]['sigma']:.3g}" for t in targets)
                   + " against the flown manoeuvre's " + ", ".join(f"{before[t]['sigma']:.3g}" for t in targets)
                   + (f" (on {time_ratio:.2g}x its time on condition)" if abs(time_ratio - 1.0) > 0.05 else "")
                   + ": per second on condition the flown manoeuvre identifies them better; fly it again or longer "
                   f"(sigma falls as 1/sqrt(time on condition)); on the run {found} at {100 * POWER:.0f} % from "
                   + ", ".join(f"{t} {before[t]['reliable_size']:.3g}" for t in targets) + ".")
        rel = {t: 100 * after[t]["sigma"] / abs(sz) for t, sz in zip(targets, sizes)}
        extra = hint(rel) if hint is not None and len(targets) > 1 else ""
        if extra:
            verdict += " " + extra
    elif len(targets) == 1:
        t0, sz = targets[0], sizes[0]
        need = abs(sz) / (after_pred.t_crit() + 1.2816)
        if ok:
            verdict = (f"DETECTABLE: {t0} of size {sz:.4g} has predicted t = {abs(sz) / after[t0]['sigma']:.2f} "
                       f"(t_crit {after_pred.t_crit():.2f} at p = 0.001, dof_eff {after_pred.dof_eff:.0f}); found "
                       f"significant with probability >= {POWER:.0%}.")
        else:
            verdict = (f"NO MANOEUVRE WITHIN THE LIMITS: the best candidate ({label}, "
                       f"{a:.3g} rad, limits used up to {100 * worst:.0f} %) gives sigma({t0}) = "
                       f"{after[t0]['sigma']:.3g}, detectable size {after[t0]['detectable_size']:.3g}, "
                       f"found at {POWER:.0%} from {after[t0]['reliable_size']:.3g}; size {sz:.4g} needs sigma <= "
                       f"{need:.3g}, i.e. {after[t0]['sigma'] / need:.2f}x the excitation the limits allow "
                       f"(or {(after[t0]['sigma'] / need) ** 2:.1f}x the time on condition).")
    else:
        # separated: with both terms in the model, whichever is present at its size is found
        # significant (p < 0.001) in 90 % of flights, and the model can fit the manoeuvre
        rel = {t: 100 * after[t]["sigma"] / abs(sz) for t, sz in zip(targets, sizes)}
        ok = passes
        verdict = (("SEPARATED: " if ok else "NOT SEPARATED WITHIN THE LIMITS: ")
                   + ", ".join(f"sigma({t}) = {after[t]['sigma']:.3g} ({rel[t]:.1f} % of {sz:.4g}; found at "
                               f"{100 * POWER:.0f} % from {after[t]['reliable_size']:.3g}, run "
                               f"{before[t]['reliable_size']:.3g})"
                               for t, sz in zip(targets, sizes))
                   + f"; correlation {after['correlation']:.3f} (run: {before['correlation']:.3f})"
                   + ("; model error on the manoeuvre " + ", ".join(f"{t} {v:+.1f} %" for t, v in oracle.items())
                      if oracle else "")
                   + f"; the aim is each found at {100 * POWER:.0f} % with the other in the model "
                     f"(found-from <= |size|) and |model error| <= {MAX_MODEL_ERROR_PCT:g} %.")
        extra = hint(rel) if hint is not None and not ok else ""
        if extra:
            verdict += " " + extra
    return ok, verdict
