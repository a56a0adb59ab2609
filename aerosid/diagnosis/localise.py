"""Localisation: where a channel's model fails, as a term one can add (issue 18, item 2).

The catalogue test (:mod:`aerosid.diagnosis.core`) can only name effects it knows.
This module looks at the residual of each channel's model without a catalogue and
turns a clear pattern into a suggested expression for the model spec:

``shape``
    The partial residual (residual + the term's own part) against every signal the
    model reads and against Mach, q-bar and time: a low-order shape is added to the
    model (x**2, abs(x - k) with the kink k scanned, x*abs(x), x**3 for a regressor; the 2nd
    and 4th harmonics for phi_r; a line and a parabola for Mach, q-bar and t) and the best shape
    per signal is kept.
    "residual bends as alpha**3 in Cm" -> ``Cm_alpha3 = alpha**3``.
``trend``
    Each coefficient against time, Mach and q-bar: the term times the variable is added
    (``alpha*t``: Cm_alpha changing linearly with time); the coefficient is also fitted
    per time window and its estimates regressed on the window time (evidence).
    "Cm_alpha drifts +5 %/min" -> ``Cm_alpha_t = alpha*t``.  Also against alpha, as a finding
    of its own (a derivative scheduled on the angle of attack): ``Cn_beta_alpha = beta*(alpha - 0.04)``.
``lag``
    Each control the model reads, shifted by tau: the refit's residual over
    tau = -200 ... +200 ms (the scan's optimum) and, to first order,
    u(t - tau) = u(t) - tau u_dot: the fin rate's term is added and
    tau = -b_dot / b_u.  "control lag ~ 40 ms" -> ``Cm_delta_p_dot = delta_p_dot/2``.
    (Trends and lags: :mod:`aerosid.diagnosis.trends`.)

Every test is the catalogue's test (the same rule, coloured-residual honest): the
added column's t with the Morelli-Klein sigma (``fit_linear(cov="morelli_klein")``,
Student-t with the effective degrees of freedom), the held-out (leave-one-window-out)
consistency and the share of residual variance, thresholds
:data:`aerosid.diagnosis.core.P_MAX` etc.  Findings whose columns correlate by
|r| >= CONFUSION_R once the model's terms are removed are listed as indistinguishable
(``confused_with``): on seed-rlv Mach falls monotonically with time, so a drift in time
and a Mach dependence cannot be told apart there, and the finding says so.

Channels whose residual is below 1e-3 of their variation (C_N and C_Y when alpha and
beta are inverted from them: identities by construction) are not localised.
"""
from __future__ import annotations

import math
import re

import numpy as np
import scipy.stats

from aerosid.diagnosis.finding import Finding, localisation_hint, localisation_text
from aerosid.diagnosis.rule import CONFUSION_R, MIN_VARIANCE_SHARE, MIN_WINDOW_CONSISTENCY, P_MAX
from aerosid.modelling.expressions import evaluate, signal_names
from aerosid.identification.regression import fit_linear

__all__ = ["Finding", "localise", "localisation_text", "localisation_hint", "LAG_SCAN_S", "IDENTITY_RATIO",
           "MAX_PER_CHANNEL"]

#: Shift range of the lag scan [s].
LAG_SCAN_S = 0.2
#: A channel whose residual RMS is below this fraction of its std is an identity (not localised).
IDENTITY_RATIO = 1e-3
#: Findings kept per channel: every significant one, and the strongest non-significant ones up to this.
MAX_PER_CHANNEL = 3
#: A shape of a variable SIMEX cannot check (SIMEX_CHECKED) whose column gets more than this
#: share of its variance from the recovered angles' own errors is not significant: errors in
#: the variable bend its partial residual by themselves.  A shape of alpha or beta is checked
#: by SIMEX whenever the angles carry errors (the catalogue's check): drawn as the flight data
#: measure them (through the band), beta's error made 3.5 % of beta*abs(beta)'s variance on
#: seed-rlv and a significant beta*abs(beta) in Cn on 2 of 10 flights without it.
MAX_ERROR_VARIANCE_SHARE = 0.05
#: The recorded angles, whose shapes may pass that guard by the SIMEX check.  Not alpha_r and
#: phi_r: functions of both angles that are singular at alpha_r = 0, where SIMEX's extrapolation
#: does not hold and the band's low-pass bends their harmonics by itself (on the no-effect
#: seed-rlv flights sin(2 phi_r) in C_l passed SIMEX in 4/10).
SIMEX_CHECKED = ("alpha", "beta")
#: Kink positions tried for an abs(x) shape (aerosid.diagnosis.localise._kink_scan).
KINK_SCAN_POINTS = 81
CONTROLS = ("delta_p", "delta_y", "delta_r")
SLOW = ("mach", "qbar", "t")  # the flight-condition variables
#: What a coefficient may be scheduled on besides the flight condition (a trend of its own).
SCHEDULES = ("alpha",)
_UNITS = {"mach": "unit Mach", "qbar": "Pa", "t": "s", "alpha": "rad"}


# --------------------------------------------------------------------------- helpers
def _wrap(expr: str) -> str:
    return expr if re.fullmatch(r"[\w.*/]+|\w+\(.*\)", expr) else f"({expr})"


def _centre(x: np.ndarray) -> float:
    c = float(np.mean(x))
    digits = max(0, 2 - int(math.floor(math.log10(abs(c))))) if c != 0 else 0
    return round(c, digits) if digits else float(round(c, 3 - len(str(int(abs(c))))))


def _num(c: float) -> str:
    return f"{c:.6g}"


def _shapes(var: str, x: np.ndarray, mach_ref: float) -> list[tuple[str, str]]:
    """(suffix of the coefficient name, expression) of the shapes tested for a variable."""
    if var == "phi_r":
        return [("sin4phi", "sin(4*phi_r)"), ("sin2phi", "sin(2*phi_r)"), ("cos2phi", "cos(2*phi_r)")]
    if var in SLOW:
        c = mach_ref if var == "mach" else _centre(x)
        d = f"({var} - {_num(c)})"
        return [(var, d), (f"{var}2", f"{d}**2")]
    # named as the catalogue names them (Cm_abs_beta = abs(beta), Cn_beta_abs_beta = beta*abs(beta));
    # abs(x) is a kink at zero: an effect that does not change sign with x (a JSBSim DHC6's roll
    # moment grows as 0.41 |beta| at low alpha)
    return [(f"{var}2", f"{var}**2"), (f"abs_{var}", f"abs({var})"), (f"{var}_abs_{var}", f"{var}*abs({var})"),
            (f"{var}3", f"{var}**3")]


# --------------------------------------------------------------------------- the tests
class _Channel:
    """The base fit of one channel and the machinery to test one added column."""

    def __init__(self, ch, model, y, signals, win):
        from aerosid.diagnosis.core import _heldout_sse, _scaled_lstsq

        self._heldout, self._lstsq = _heldout_sse, _scaled_lstsq
        self.ch, self.model, self.y, self.signals, self.win = ch, model, y, signals, win
        self.n = y.size
        Xb, _ = model.design(signals)
        self.Xb = Xb
        self.Ab = Xb.to_numpy(float)
        self.base = fit_linear(y, Xb, names=model.names, channel=ch, cov="morelli_klein")
        self.resid = np.asarray(self.base.residuals)
        self.rss_b = float(self.resid @ self.resid)
        self.sse_b = _heldout_sse(self.Ab, y, win)

    def test(self, name: str, x: np.ndarray, given: tuple = ()) -> dict | None:
        """Base (+ the `given` columns) + column x: the catalogue's evidence for the added
        column (None if untestable).  given: ((name, column), ...) already in the model."""
        x = np.asarray(x, float)
        if x.shape != self.y.shape or not np.all(np.isfinite(x)) or np.ptp(x) <= 0:
            return None
        # added columns scaled to |x| <= 1 (a column of q-bar squared, ~1e10 Pa^2, beside
        # q_hat, ~1e-5, makes the design numerically rank-deficient); estimates scaled back
        Xb = self.Xb.copy()
        for k, (gname, gcol) in enumerate(given):
            Xb[f"__given{k}"] = gcol / (float(np.max(np.abs(gcol))) or 1.0)
        Xa = Xb.copy()
        col = name if name not in self.model.names else f"{name}__loc"
        scale = float(np.max(np.abs(x))) or 1.0
        Xa[col] = x / scale
        try:
            fa = fit_linear(self.y, Xa, names=[str(n) for n in Xb.columns] + [col], channel=self.ch,
                            cov="morelli_klein")
        except ValueError:
            return None
        j = Xb.shape[1]
        if not fa.identifiable[j]:
            return None
        rss_a = float(np.asarray(fa.residuals) @ np.asarray(fa.residuals))
        if given:
            Ab = Xb.to_numpy(float)
            e = self.y - Ab @ self._lstsq(Ab, self.y)
            rss_b, sse_b = float(e @ e), self._heldout(Ab, self.y, self.win)
        else:
            Ab, rss_b, sse_b = self.Ab, self.rss_b, self.sse_b
        d = sse_b - self._heldout(Xa.to_numpy(float), self.y, self.win)
        d = d[np.isfinite(d)]
        tot = float(np.sum(np.abs(d)))
        perp = x - Ab @ self._lstsq(Ab, x)
        return dict(fit=fa, j=j, scale=scale, estimate=float(fa.estimate[j]) / scale,
                    std_error=float(fa.std_error[j]) / scale,
                    t_value=float(fa.t_values[j]), p_value=float(fa.p_values[j]), n_eff=float(fa.n_eff),
                    variance_share=1.0 - rss_a / rss_b if rss_b > 0 else 0.0,
                    window_consistency=float(np.sum(np.clip(d, 0, None)) / tot) if tot > 0 else 0.0,
                    perp=perp, column=x)


def _rule(r: dict) -> list[str]:
    reasons = []
    if not r["p_value"] < P_MAX:
        reasons.append(f"corrected p = {r['p_value']:.2g} >= {P_MAX:g}")
    if not r["window_consistency"] >= MIN_WINDOW_CONSISTENCY:
        reasons.append(f"held-out window consistency {r['window_consistency']:.0%} < {MIN_WINDOW_CONSISTENCY:.0%}")
    if not r["variance_share"] >= MIN_VARIANCE_SHARE:
        reasons.append(f"explains {r['variance_share']:.2%} < {MIN_VARIANCE_SHARE:.0%} of the residual variance")
    return reasons


def _stats_text(r: dict) -> str:
    return (f"t = {r['t_value']:.3g}, p = {r['p_value']:.2g} (coloured-residual sigma, N_eff {r['n_eff']:.0f}), "
            f"{r['variance_share']:.1%} of the residual variance, held-out consistency {r['window_consistency']:.0%}")


def _binned_partial(x: np.ndarray, pr: np.ndarray, bins: int = 8) -> dict:
    edges = np.unique(np.quantile(x, np.linspace(0, 1, bins + 1)))
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, max(edges.size - 2, 0))
    cx, cy = [], []
    for b in range(max(edges.size - 1, 0)):
        m = idx == b
        if m.any():
            cx.append(float(np.mean(x[m])))
            cy.append(float(np.mean(pr[m])))
    return {"partial_residual_x": cx, "partial_residual_mean": cy}


def _error_share(expr: str, signals: dict, perturbed: dict | None) -> float:
    """Share of a column's variance that one draw of the angles' own error makes
    (var(column(perturbed angles) - column) / var(column)); 0 without angle errors."""
    if perturbed is None:
        return 0.0
    x = evaluate(expr, signals, len(signals["alpha"]))
    xp = evaluate(expr, perturbed, len(signals["alpha"]))
    v = float(np.var(x))
    return float(np.var(xp - x) / v) if v > 0 else 0.0


def _perturbed(signals: dict, noise, t: np.ndarray, groups: np.ndarray) -> dict | None:
    """The signals with one fixed draw of the angles' errors added to alpha and beta (alpha_r,
    phi_r recomputed): the errors-in-variables guard of the shapes.  noise: a white 1-sigma [rad],
    or (sigma, cutoff_hz) as aerosid.identification.eiv.angle_noise draws them (the diagnosis'
    own: the flight data's per-angle sigma through the band); None or 0: no guard."""
    if noise is None or (not isinstance(noise, tuple) and not float(noise) > 0):
        return None  # (the diagnosis' (sigma, cutoff) is None when the angles carry no error)
    sigma, cutoff = noise if isinstance(noise, tuple) else (float(noise), None)
    from aerosid.identification.eiv import angle_noise
    from aerosid.identification.inversion import total_angles

    da, db = angle_noise(np.random.default_rng(20240613), groups, t, sigma, cutoff)
    out = dict(signals)
    out["alpha"] = signals["alpha"] + da
    out["beta"] = signals["beta"] + db
    out["alpha_r"], out["phi_r"] = total_angles(out["alpha"], out["beta"])
    return out


def _simex_check(c: _Channel, expr: str, r: dict, simex, cache: dict,
                 given: tuple[tuple[str, str], ...] = ()) -> dict:
    """The catalogue's errors-in-variables check of an added term: refits with extra angle
    noise (aerosid.diagnosis.core.simex_check), the estimate extrapolated to no angle error and
    its p with the sigma of a SIMEX-corrected estimate; {} without SIMEX
    draws (simex: aerosid.diagnosis.core.SimexDraws).  given: (coefficient,
    expression) of the columns the term was tested beside (a schedule's main effect)."""
    if not simex:
        return {}
    from aerosid.diagnosis.core import simex_check
    from aerosid.modelling.models import parse_term

    est = r["estimate"]
    model = c.model
    for name, g in given:
        model = model.with_term(parse_term(f"{name} = {g}", c.ch))
    # the cache holds the SIMEX draws' designs of the channel's own model: not of this one
    eiv, est_s, p_s = simex_check(simex, model, lambda sig: evaluate(expr, sig, c.n), c.y, est, r["std_error"],
                                  float(r["fit"].dof_eff), None if given else cache)
    return {"eiv_fraction": eiv, "estimate_simex": est_s, "p_value_simex": p_s}


def _shape_findings(c: _Channel, mach_ref: float, perturbed: dict | None, simex=None,
                    cache: dict | None = None) -> list[Finding]:
    out = []
    model_vars = sorted(set().union(*(signal_names(t.expression, c.signals) for t in c.model.terms)) - {"t"})
    for var in [v for v in model_vars if v in c.signals] + [v for v in SLOW if v not in model_vars]:
        x = np.asarray(c.signals[var], float)
        if not np.all(np.isfinite(x)) or np.ptp(x) <= 0:
            continue
        tried = []
        for suffix, expr in _shapes(var, x, mach_ref):
            r = c.test(f"{c.ch}_{suffix}", evaluate(expr, c.signals, c.n))
            kink = {}
            if r is not None and expr == f"abs({var})":  # the kink where the flight puts it
                kink = _kink_scan(c, var, x, r)
                moved = c.test(f"{c.ch}_{suffix}", evaluate(kink["kink_expression"], c.signals, c.n)) \
                    if "kink_expression" in kink else None
                if moved is not None:
                    expr, r = kink["kink_expression"], moved
            if r is not None:
                tried.append((suffix, expr, r, kink))
        if not tried:
            continue
        suffix, expr, r, kink = max(tried, key=lambda s: abs(s[2]["t_value"]))
        reasons = _rule(r)
        share = _error_share(expr, c.signals, perturbed)
        eiv = _simex_check(c, expr, r, simex, {} if cache is None else cache) \
            if share > 0.0 and var in SIMEX_CHECKED else {}
        if (eiv or share > MAX_ERROR_VARIANCE_SHARE) and not eiv.get("p_value_simex", 1.0) < P_MAX:
            corrected = (f"; corrected for them (SIMEX) its estimate is {eiv['estimate_simex']:.3g}, "
                         f"p = {eiv['p_value_simex']:.2g}" if eiv else "")
            reasons.append(f"the errors of the recovered angles make {share:.0%} of the variance of {expr}{corrected}: "
                           "they bend its partial residual by themselves (errors in variables)")
        # partial residual: residual + the model's own part in this variable
        own = np.zeros(c.n)
        for i, t in enumerate(c.model.terms):
            if var in signal_names(t.expression, c.signals):
                own += c.base.estimate[i] * c.Ab[:, i]
        others = {s[1]: round(s[2]["t_value"], 2) for s in tried}
        bend = "bends as" if var not in SLOW else "varies as"
        where = (f" (its kink is at {var} = {kink['kink_at']:.2g}, not 0: moving it there leaves "
                 f"{1.0 - kink['kink_rss_drop']:.0%} of the residual variance of abs({var}), p = "
                 f"{kink['kink_p_value']:.2g})") if "kink_expression" in kink else ""
        msg = (f"{c.ch}: the partial residual against {var} {bend} {expr}{where} ({_stats_text(r)}); "
               f"add `{c.ch}_{suffix} = {expr}` to [{c.ch}]")
        out.append(Finding(c.ch, "shape", var, not reasons, f"{c.ch}_{suffix}", expr, r["estimate"],
                           r["std_error"], r["t_value"], r["p_value"], r["variance_share"], r["window_consistency"],
                           r["n_eff"], msg,
                           evidence={"shapes_t": others, "error_variance_share": share, **eiv, **kink,
                                     **_binned_partial(x, c.resid + own)},
                           reasons=tuple(reasons), perp=r["perp"], column=r["column"]))
    return out


def _kink_scan(c: _Channel, var: str, x: np.ndarray, r: dict) -> dict:
    """Where the kink of an abs(x) shape sits: the base model + abs(x - k) refitted for k over
    KINK_SCAN_POINTS points within one standard deviation of x from zero and between its 20th
    and 80th percentile.  The kink of an effect even in x sits at x's true zero, which the record
    misses by its calibration bias (a fraction of the excursions), and both arms must be flown:
    a kink farther out is a hinge that bends like x**2 or x**3 and takes their place (a cubic
    in alpha was suggested as abs(alpha - 0.052) on 3 of 10 seed-rlv flights without the first
    bound, 4 of 10 with the 5th..95th percentile instead of the second).  An effect that is even
    in the true x kinks where the *recorded* x has its offset (a vane's calibration bias: -0.3
    deg of beta put a JSBSim DHC6's |beta| roll moment at 0.56 of its size, and its C_l,p at
    0.6).  The optimum is suggested (``kink_expression``) when moving the kink there lowers the
    residual more than one more parameter would by chance: F-test, 1 and N_eff - p degrees of
    freedom (the coloured residual's effective count), p < P_MAX; else abs(x) stands."""
    lo, hi = np.quantile(x, [0.2, 0.8])
    s = float(np.std(x))
    lo, hi = max(lo, -s), min(hi, s)
    ks = np.unique(np.r_[np.linspace(lo, hi, KINK_SCAN_POINTS) if lo < hi else [], 0.0])
    A = np.column_stack([c.Ab, np.zeros(c.n)])
    rss = []
    for k in ks:  # each column as the fit forms it (the band order of a non-linear term), not kept
        A[:, -1] = evaluate(_kink(var, float(k)), c.signals, c.n, keep_band_order=False)
        e = c.y - A @ c._lstsq(A, c.y)
        rss.append(float(e @ e))
    rss = np.asarray(rss)
    i, i0 = int(np.argmin(rss)), int(np.flatnonzero(ks == 0.0)[0])
    dof = max(float(r["n_eff"]) - A.shape[1], 1.0)
    f = (rss[i0] - rss[i]) / (rss[i] / dof) if rss[i] > 0 else 0.0
    p = float(scipy.stats.f.sf(f, 1, dof)) if f > 0 else 1.0
    out = {"kink_at": float(ks[i]), "kink_rss_drop": float(1.0 - rss[i] / rss[i0]) if rss[i0] > 0 else 0.0,
           "kink_p_value": p}
    if p < P_MAX and ks[i] != 0.0:
        out["kink_expression"] = _kink(var, float(f"{ks[i]:.2g}"), _num)
    return out


def _kink(var: str, k: float, number=repr) -> str:
    """abs(var - k) as an expression."""
    return f"abs({var})" if k == 0.0 else f"abs({var} {'-' if k > 0 else '+'} {number(abs(k))})"


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    den = float(np.linalg.norm(a) * np.linalg.norm(b))
    return abs(float(a @ b)) / den if den > 0 else 0.0


def _confusions(findings: list[Finding], r_min: float) -> list[Finding]:
    from dataclasses import replace

    out = []
    for a in findings:
        conf = list(a.confused_with)
        for b in findings:
            if b is not a and a.perp is not None and b.perp is not None and _corr(a.perp, b.perp) >= r_min:
                conf.append(b.id)
        out.append(replace(a, confused_with=tuple(conf)))
    return out


def _shadows(c: _Channel, findings: list[Finding]) -> list[Finding]:
    """Significant findings tested given each other: A is a shadow of B when A fails the rule
    with B in the model while B still passes with A in it (A is then not significant, and says
    which finding explains it).  Two that explain each other stay, each listing the other."""
    from dataclasses import replace

    sig = [f for f in findings if f.significant and f.column is not None]
    if len(sig) < 2:
        return findings
    passes: dict[tuple[int, int], tuple[bool, dict | None]] = {}
    for a in range(len(sig)):
        for b in range(len(sig)):
            if a != b:
                given = dict(sig[a].given + sig[b].given)  # the main effects, once each
                given[sig[b].suggested_coefficient] = sig[b].column
                r = c.test(sig[a].suggested_coefficient, sig[a].column, given=tuple(given.items()))
                passes[a, b] = (r is not None and not _rule(r), r)
    out = {id(f): f for f in findings}
    for a in range(len(sig)):
        for b in range(len(sig)):
            if a == b or passes[a, b][0]:
                continue
            f = out[id(sig[a])]
            r = passes[a, b][1]
            given = (f"t = {r['t_value']:.3g}, p = {r['p_value']:.2g}, consistency {r['window_consistency']:.0%}"
                     if r else "not identifiable")
            if passes[b, a][0]:  # a shadow of b
                out[id(sig[a])] = replace(f, significant=False, reasons=(
                    f"a shadow of {sig[b].id} ({sig[b].suggested_expression}): with it in the model, {given}",)
                    + f.reasons, evidence={**f.evidence, "shadow_of": sig[b].id})
            elif sig[b].id not in f.confused_with:  # they explain each other
                out[id(sig[a])] = replace(f, confused_with=f.confused_with + (sig[b].id,))
    return [out[id(f)] for f in findings]


# --------------------------------------------------------------------------- entry point
def localise(signals: dict, y_by_channel: dict, models: dict, t: np.ndarray, groups: np.ndarray, win: np.ndarray,
             mach_reference: float, angle_noise=0.0,
             simex=None) -> dict[str, tuple[Finding, ...]]:
    """Localisation findings per channel (significant first, then by |t|): every
    significant one and the strongest others up to MAX_PER_CHANNEL.

    signals: the model signals on the diagnosed samples (the diagnosis' own);
    y_by_channel: measured coefficient per channel; win: time-window index per sample;
    angle_noise: the recovered angles' error (for the errors-in-variables guard of the shapes: a
    shape the angle errors make by themselves is not significant): a white 1-sigma [rad], or
    (sigma, cutoff_hz) as aerosid.identification.eiv.angle_noise takes them, or None;
    simex: the diagnosis' SIMEX draws of the signals (aerosid.diagnosis.core.SimexDraws):
    a shape the angle errors could bend is significant only if its SIMEX-corrected estimate is."""
    from aerosid.diagnosis.trends import _lag_findings, _trend_findings

    perturbed = _perturbed(signals, angle_noise, t, groups)
    cache: dict = {}  # the SIMEX draws' base designs per channel
    result: dict[str, tuple[Finding, ...]] = {}
    for ch, model in models.items():
        y = np.asarray(y_by_channel[ch], float)
        c = _Channel(ch, model, y, signals, win)
        if not (np.std(y) > 0) or float(np.std(c.resid)) < IDENTITY_RATIO * float(np.std(y)):
            result[ch] = ()  # an identity by construction (the angles were inverted from this channel)
            continue
        found = _shape_findings(c, mach_reference, perturbed, simex, cache) + \
            _trend_findings(c, mach_reference, t, simex, cache) + _lag_findings(c, t, groups)
        found = _confusions(found, CONFUSION_R)
        found = _shadows(c, found)
        found.sort(key=lambda f: (not f.significant, -f.score))
        sig = [f for f in found if f.significant]
        result[ch] = tuple(sig + [f for f in found if not f.significant][: max(0, MAX_PER_CHANNEL - len(sig))])
    return result
