"""Coefficient trends and control lags: two of the localisation's tests of a channel's model
(:mod:`aerosid.diagnosis.localise` has the shapes, the rule and the entry point).

``trend``: each term's coefficient against the flight condition (t, Mach, q-bar) and, as a
finding of its own, against the angle of attack (a schedule); ``lag``: each control term's
rate, u(t - tau) ~ u - tau u_dot, with a refit of the control shifted by tau as evidence.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd
import scipy.stats

from aerosid.diagnosis.finding import Finding
from aerosid.diagnosis.localise import (_UNITS, CONTROLS, LAG_SCAN_S, SCHEDULES, SIMEX_CHECKED, SLOW, _centre, _Channel,
                                        _corr, _num, _rule, _simex_check, _stats_text, _wrap)
from aerosid.diagnosis.rule import CONFUSION_R, P_MAX
from aerosid.identification.regression import fit_linear
from aerosid.modelling.expressions import evaluate, signal_names


#: Signals the recovered angles' errors reach (the SIMEX draws recompute them from alpha and beta).
ANGLE_SIGNALS = frozenset({"alpha", "beta", "alpha_r", "phi_r", "alpha_dot_hat", "beta_dot_hat"})


def _trend_findings(c: _Channel, mach_ref: float, t: np.ndarray, simex=None,
                    cache: dict | None = None) -> list[Finding]:
    """Per model term (not the intercept): its coefficient against the flight condition (t, Mach,
    q-bar: the best of the three, the others listed where they move together) and, as a second
    finding, against the angle of attack (a derivative scheduled on alpha, as aerodynamic tables
    are: JSBSim's DHC-6 has C_n,beta = 0.5 + 5.7 alpha)."""
    out = []
    in_model = set().union(*(signal_names(t.expression, c.signals) for t in c.model.terms))
    for i, term in enumerate(c.model.terms):
        names = signal_names(term.expression, c.signals)
        if not names or "t" in names:
            continue  # the intercept's trend is the partial residual against t (a shape)
        for group in (SLOW, SCHEDULES):
            # not a schedule of the total-angle terms: alpha_r and phi_r are alpha themselves, and
            # cos(4 phi_r) x alpha "passed" on 4 of 10 no-effect seed-rlv flights (phi_r is singular
            # at alpha_r = 0, where the angles' errors and the band's low-pass bend it)
            skip = names | ({"alpha", "alpha_r", "phi_r"} if names & {"alpha_r", "phi_r"} else set())
            f = _trend_finding(c, i, term, [v for v in group if v not in skip], mach_ref, t, in_model, simex,
                               {} if cache is None else cache)
            if f is not None:
                out.append(f)
    return out


def _trend_finding(c: _Channel, i: int, term, variables: list[str], mach_ref: float, t: np.ndarray,
                   in_model: set, simex=None, cache: dict | None = None) -> Finding | None:
    """The best variable's trend of term i.  A schedule on alpha is tested with alpha's own
    linear term beside it when the channel's model has none (an interaction with its main
    effect): the term's signal times alpha holds the signal's record offset times alpha, which
    only that term absorbs (the DHC-6's beta vane, -0.3 deg off, made beta*alpha in C_n a
    third alpha, and the schedule t = -0.26 instead of its share of the residual)."""
    b = float(c.base.estimate[i])
    tried = []
    for var in variables:
        v = np.asarray(c.signals.get(var, np.full(c.n, np.nan)), float)
        if not np.all(np.isfinite(v)) or np.ptp(v) <= 0:
            continue
        given_expr = ()
        if var in SLOW and var != "mach":
            expr = f"{_wrap(term.expression)}*{var}"
        else:  # about the reference Mach, or the flight's mean angle (the coefficient keeps its meaning)
            ref = mach_ref if var == "mach" else _centre(v)
            expr = f"{_wrap(term.expression)}*{_minus(var, ref)}"
            if var in SCHEDULES and var not in in_model:
                given_expr = ((f"{c.ch}_{var}", _minus(var, ref)),)  # its main effect, as a spec would name it
        given = tuple((name, evaluate(e, c.signals, c.n)) for name, e in given_expr)
        # evaluated as the spec will have it: a product of signals is low-passed after it is formed
        # (aerosid.identification.band_order), as the model's own columns are
        r = c.test(f"{term.coefficient}_{var}", evaluate(expr, c.signals, c.n), given=given)
        if r is not None:
            r["given"] = given
            tried.append((var, expr, r, given_expr))
    if not tried:
        return None
    var, expr, r, given_expr = max(tried, key=lambda s: abs(s[2]["t_value"]))
    alike = tuple(f"trend:{term.coefficient}:{v}" for v, _, o, _ in tried
                  if v != var and _corr(r["perp"], o["perp"]) >= CONFUSION_R)
    reasons = _rule(r)
    # a column the angles' errors reach is checked as the catalogue's are (SIMEX), where SIMEX
    # holds: alpha and beta, not alpha_r, phi_r (singular at alpha_r = 0) or the angle rates
    angles = signal_names(expr, c.signals) & ANGLE_SIGNALS
    eiv = _simex_check(c, expr, r, simex, cache, given_expr) if angles and angles <= set(SIMEX_CHECKED) else {}
    if eiv and not eiv.get("p_value_simex", 1.0) < P_MAX:
        reasons.append(f"corrected for the recovered angles' errors (SIMEX) its estimate is "
                       f"{eiv['estimate_simex']:.3g}, p = {eiv['p_value_simex']:.2g}: the angles' errors bend it "
                       "by themselves (errors in variables)")
    rel = r["estimate"] / b if b != 0 else float("nan")  # relative change of the coefficient per unit
    ev = {"relative_change_per_unit": rel, "coefficient_mean": b,
          "variable_range": [float(np.min(c.signals[var])), float(np.max(c.signals[var]))],
          "others_t": {s[0]: round(s[2]["t_value"], 2) for s in tried}, **eiv}
    if var == "t":
        ev["change_pct_per_min"] = 100.0 * 60.0 * rel
        rate = f"{100.0 * 60.0 * rel:+.2g} %/min ({100.0 * rel * float(np.ptp(t)):+.2g} % over {np.ptp(t):.0f} s)"
    else:
        rate = f"{100.0 * rel:+.2g} % per {_UNITS.get(var, 'unit')}"
    ev.update(_window_slope(c, i, t))
    also = [a.rsplit(":", 1)[1] for a in alike]
    with_var = f"{var} (or {' or '.join(also)}: they move together on this flight)" if also else var
    main = "".join(f" and `{g} = {var}`" for g, _ in r["given"])
    if main:
        ev["main_effect"] = r["given"][0][0]
    msg = (f"{c.ch}: {term.coefficient} {'drifts' if var == 't' else 'changes'} {rate} with {with_var} "
           f"({_stats_text(r)}{', with ' + var + ' itself in the model' if main else ''}; per-window estimates: "
           f"slope p = {ev.get('window_slope_p', float('nan')):.2g}); "
           f"add `{term.coefficient}_{var} = {expr}`{main} to [{c.ch}]")
    return Finding(c.ch, "trend", var, not reasons, f"{term.coefficient}_{var}", expr, r["estimate"],
                   r["std_error"], r["t_value"], r["p_value"], r["variance_share"], r["window_consistency"],
                   r["n_eff"], msg, coefficient=term.coefficient, evidence=ev, reasons=tuple(reasons),
                   confused_with=alike, perp=r["perp"], column=r["column"], given=r["given"])


def _minus(var: str, ref: float) -> str:
    return f"({var} - {_num(ref)})" if ref >= 0 else f"({var} + {_num(-ref)})"


def _window_slope(c: _Channel, i: int, t: np.ndarray) -> dict:
    """Coefficient i fitted per time window (Morelli-Klein sigma) and its estimates regressed
    on the window's mean time (weighted; sigma inflated by sqrt(max(chi2/dof, 1)))."""
    est, se, tm = [], [], []
    for k in np.unique(c.win):
        m = c.win == k
        try:
            f = fit_linear(c.y[m], c.Xb.loc[m], names=c.model.names, channel=c.ch, cov="morelli_klein")
        except ValueError:
            continue
        if f.identifiable[i] and math.isfinite(f.std_error[i]) and f.std_error[i] > 0:
            est.append(float(f.estimate[i]))
            se.append(float(f.std_error[i]))
            tm.append(float(np.mean(t[m])))
    if len(est) < 4:
        return {}
    est, se, tm = map(np.asarray, (est, se, tm))
    w = 1.0 / se**2
    A = np.column_stack([np.ones_like(tm), tm - np.average(tm, weights=w)])
    cov = np.linalg.inv(A.T @ (A * w[:, None]))
    coef = cov @ (A.T @ (w * est))
    chi2 = float(np.sum(w * (est - A @ coef) ** 2))
    dof = len(est) - 2
    s = math.sqrt(cov[1, 1] * max(chi2 / dof, 1.0))
    tv = coef[1] / s if s > 0 else float("nan")
    return {"window_estimates": [float(v) for v in est], "window_std_errors": [float(v) for v in se],
            "window_t_s": [float(v) for v in tm], "window_slope_per_s": float(coef[1]),
            "window_slope_p": float(2.0 * scipy.stats.t.sf(abs(tv), dof)) if math.isfinite(tv) else float("nan")}


def _lag_findings(c: _Channel, t: np.ndarray, groups: np.ndarray) -> list[Finding]:
    out = []
    for i, term in enumerate(c.model.terms):
        names = signal_names(term.expression, c.signals)
        ctrl = [u for u in CONTROLS if u in names]
        if len(ctrl) != 1 or f"{ctrl[0]}_dot" not in c.signals:
            continue
        u = ctrl[0]
        expr = re.sub(rf"\b{u}\b", f"{u}_dot", term.expression)
        r = c.test(f"{term.coefficient}_dot", evaluate(expr, c.signals, c.n))
        if r is None:
            continue
        fa, j = r["fit"], r["j"]
        b_u, b_d = float(fa.estimate[i]), r["estimate"]
        tau = -b_d / b_u if b_u != 0 else float("nan")
        # delta method: tau = -b_d/b_u (the added column was fitted scaled by 1/r["scale"])
        unscale = np.diag([1.0, 1.0 / r["scale"]])
        cov = unscale @ np.asarray(fa.cov)[np.ix_([i, j], [i, j])] @ unscale
        g = np.array([b_d / b_u**2, -1.0 / b_u]) if b_u != 0 else np.full(2, np.nan)
        tau_se = float(math.sqrt(max(g @ cov @ g, 0.0))) if np.all(np.isfinite(cov)) else float("nan")
        scan = _lag_scan(c, i, term.expression, u, t, groups)
        reasons = _rule(r)
        if not abs(tau) <= LAG_SCAN_S:
            reasons.append(f"the implied lag {1e3 * tau:.0f} ms is outside +-{1e3 * LAG_SCAN_S:.0f} ms")
        what = "lag" if tau > 0 else "lead"
        msg = (f"{c.ch}: control {what} of about {1e3 * abs(tau):.0f} ± {1e3 * tau_se:.0f} ms on {u} "
               f"(refit with {u} shifted: optimum at {1e3 * scan['lag_scan_s']:+.0f} ms; {_stats_text(r)}); "
               f"add `{term.coefficient}_dot = {expr}` to [{c.ch}] (its coefficient is -lag x {term.coefficient})")
        out.append(Finding(c.ch, "lag", u, not reasons, f"{term.coefficient}_dot", expr, r["estimate"],
                           r["std_error"], r["t_value"], r["p_value"], r["variance_share"], r["window_consistency"],
                           r["n_eff"], msg, coefficient=term.coefficient,
                           evidence={"lag_s": tau, "lag_std_s": tau_se, **scan}, reasons=tuple(reasons),
                           perp=r["perp"], column=r["column"]))
    return out


def _lag_scan(c: _Channel, i: int, expression: str, u: str, t: np.ndarray, groups: np.ndarray) -> dict:
    """RSS of the base model with the control shifted by tau (u(t - tau)) over +-LAG_SCAN_S."""
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.01
    step = max(dt, 0.005)
    taus = np.arange(-LAG_SCAN_S, LAG_SCAN_S + 0.5 * step, step)
    rss = []
    sig = dict(c.signals)
    u0 = np.asarray(c.signals[u], float)
    A = c.Ab.copy()
    for tau in taus:
        sig[u] = _shift(t, u0, groups, tau)
        A[:, i] = evaluate(expression, sig, c.n)
        e = c.y - A @ c._lstsq(A, c.y)
        rss.append(float(e @ e))
    rss = np.asarray(rss)
    k = int(np.argmin(rss))
    k0 = int(np.argmin(np.abs(taus)))
    return {"lag_scan_s": float(taus[k]), "lag_scan_rss_drop": float(1.0 - rss[k] / rss[k0]) if rss[k0] > 0 else 0.0,
            "lag_scan_tau_s": [round(float(v), 4) for v in taus[:: max(1, len(taus) // 20)]],
            "lag_scan_rss": [float(v) for v in rss[:: max(1, len(taus) // 20)]]}


def _shift(t: np.ndarray, u: np.ndarray, groups: np.ndarray, tau: float) -> np.ndarray:
    """u(t - tau) within each contiguous group (held at the ends)."""
    out = np.empty_like(u)
    for g in pd.unique(groups):
        m = groups == g
        out[m] = np.interp(t[m] - tau, t[m], u[m])
    return out
