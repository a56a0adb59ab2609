"""The fitted terms of a model version as text: estimate, sigma, t and p per term.

Sigma is the coloured-residual (Morelli–Klein) standard error of the coefficients
table, t = estimate / sigma and p its two-sided Student-t(dof_eff) probability, the
same statistics the diagnosis judges a candidate by (``aerosid.diagnosis.P_MAX``).
A non-constant term with p >= P_MAX gets a warning suggesting its removal.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from aerosid.identification.coefficient_units import per_degree_factor, unit_label, units_header
from aerosid.modelling.expressions import evaluate

#: Significance level of a term (the diagnosis's rule: corrected p < 0.001).
P_MAX = 1e-3


def _num(x, spec: str) -> str:
    return "nan" if x is None or not math.isfinite(float(x)) else format(float(x), spec)


def term_table(table: pd.DataFrame, per_degree: bool = False, new_terms: frozenset[str] = frozenset(),
               p_max: float = P_MAX) -> str:
    """A coefficients table (coefficients.parquet rows) as one block per channel:
    coefficient, estimate, sigma, t, p, significant at p < p_max, unit.  new_terms: the
    coefficients added relative to the parent (marked +)."""
    lines = [f"fitted terms ({units_header(per_degree)}); sigma corrected for coloured residuals, t = estimate/sigma, "
             f"p two-sided Student-t(N_eff - terms); significant: p < {p_max:g}; + = new vs the parent",
             f"  {'coefficient':<22}{'estimate':>13}{'sigma':>11}{'t':>9}{'p':>10}  {'signif.':<8}unit"]
    for channel, rows in table.groupby("channel", sort=False):
        first = rows.iloc[0]
        identity = not rows["identifiable"].any() and bool(str(first.get("note", "")))
        lines.append(f"[{channel}] N = {int(first['n_obs'])} (effective {_num(first['n_eff'], '.0f')}), "
                     f"residual RMS {_num(first['rms_residual'], '.4g')}, R^2 {_num(first['r2'], '.4f')}"
                     + ("; an identity: alpha/beta are inverted from this channel, no estimates" if identity else ""))
        if identity:
            continue
        for _, row in rows.iterrows():
            k = per_degree_factor(row["expression"]) if per_degree else 1.0
            mark = "+" if row["coefficient"] in new_terms else " "
            name = f"{mark}{row['coefficient']}"
            if not math.isfinite(float(row["estimate"])):
                lines.append(f"  {name:<22}{'-':>13}{'-':>11}{'-':>9}{'-':>10}  not identifiable")
                continue
            sig = "yes" if float(row["p_value"]) < p_max else "NO"
            lines.append(f"  {name:<22}{_num(row['estimate'] * k, '.5g'):>13}{_num(row['std_error'] * k, '.3g'):>11}"
                         f"{_num(row['t_value'], '.3g'):>9}{_num(row['p_value'], '.2g'):>10}  {sig:<8}"
                         f"{unit_label(row['expression'], per_degree) or '-'}")
    return "\n".join(lines)


def significance_warnings(table: pd.DataFrame, p_max: float = P_MAX) -> list[str]:
    """One warning per non-constant term whose p >= p_max (an intercept is kept whatever its p):
    'Cm_a3: t = 0.8, not significant at p < 0.001 — consider removing it'."""
    out = []
    for _, row in table.iterrows():
        est, p = float(row["estimate"]), float(row["p_value"])
        if not math.isfinite(est) or not math.isfinite(p) or p < p_max:
            continue
        if per_degree_factor(row["expression"]) == 1.0 and _is_constant(row["expression"]):
            continue
        out.append(f"{row['coefficient']}: t = {float(row['t_value']):.2g}, not significant at p < {p_max:g} "
                   f"(p = {p:.2g}) — consider removing it ([{row['channel']}] remove = [\"{row['coefficient']}\"])")
    return out


def interval_includes_zero(ci_low, ci_high) -> bool:
    """Whether a finite 95 % interval [ci_low, ci_high] holds 0: the flight does not tell the
    coefficient from zero, not even its sign."""
    lo, hi = float(ci_low), float(ci_high)
    return math.isfinite(lo) and math.isfinite(hi) and lo <= 0.0 <= hi


def undetermined(table: pd.DataFrame) -> list[str]:
    """The non-constant coefficients of a coefficients table whose 95 % interval holds 0:
    NOT DETERMINED by this flight (the issue-16 bench once counted such an estimate, F4N's
    C_n,r -0.024 +- 0.05 against -0.15, as a silent failure: the number alone looked like a
    result).  Intercepts are left out (0 is a plausible value for them); identities and
    unidentifiable terms have no interval and are reported as such elsewhere."""
    out = []
    if "expression" not in table.columns:  # cannot tell an intercept from a term: flag nothing
        return out
    signed = set(wrong_sign(table))  # named for what they are (the mixture widened their interval)
    for _, row in table.iterrows():
        if str(row["coefficient"]) in signed:
            continue
        if not interval_includes_zero(row.get("ci_low", math.nan), row.get("ci_high", math.nan)):
            continue
        if _is_constant(str(row.get("expression", ""))):
            continue
        out.append(str(row["coefficient"]))
    return out


UNDETERMINED_NOTE = "95 % interval holds 0: not determined by this flight"

#: The pure damping terms, per channel: a rate signal alone.  Body-axis damping derivatives
#: (C_m,q, C_m,alpha_dot, C_l,p, C_n,r) are negative on a vehicle that is not unstable in that
#: axis (the tail's or the wing's lift opposes the rotation; for C_m,alpha_dot the downwash lag on
#: the tail).  A whole 95 % interval above 0 is, far more often than a real positive value, the
#: signature of errors in the regressor or of its collinearity with another one: on JSBSim's pa28
#: (C_m,alpha_dot +0.02), alpha-dot read off the noisy vane came out +4.8 .. +6.4 +- 1.3 .. 1.7 on 3 of
#: 10 flights, with C_m,alpha 9 % short of the truth; with the noise-free angles it is +1.2 and -0.2.
DAMPING_TERMS = {"Cm": ("q_hat", "alpha_dot_hat"), "Cl": ("p_hat",), "Cn": ("r_hat",)}
WRONG_SIGN_NOTE = ("came out positive at 95 %, a sign damping seldom has (suspect the noise in its regressor or "
                   "its collinearity; see the channel's warnings)")


def damping_term(channel: str, expression: str) -> tuple[str, float] | None:
    """(rate signal, factor) of a pure damping term of `channel` (DAMPING_TERMS): an expression
    that reads that signal alone, proportional to it with a positive factor (``q_hat`` -> 1,
    ``(q_hat)`` -> 1, ``2*q_hat`` -> 2: the derivative is the coefficient times the factor);
    None for anything else."""
    for rate in DAMPING_TERMS.get(str(channel), ()):
        factor = pure_term_factor(expression, rate)
        if factor is not None:
            return rate, factor
    return None


def pure_term_factor(expression: str, signal: str) -> float | None:
    """The positive factor c of an expression that is c x `signal` alone (``q_hat`` -> 1,
    ``delta_p/2`` -> 0.5), or None for anything else (another signal, an offset, a negative or
    non-constant factor)."""
    x = np.array([-2.0, -0.5, 1.0, 3.0])
    try:
        y = evaluate(str(expression), {signal: x})
    except (ValueError, TypeError, SyntaxError, ZeroDivisionError, KeyError):
        return None
    ratio = np.asarray(y, float) / x
    if np.all(np.isfinite(ratio)) and ratio[0] > 0 and np.ptp(ratio) <= 1e-12 * abs(ratio[0]):
        return float(ratio[0])
    return None


#: An aircraft's primary control terms and the sign of their derivative under aerosid's
#: conventions (docs/real-flight.md, [controls]: elevator and ailerons positive trailing edge down,
#: rudder trailing edge left, mixed into delta_p, delta_r, delta_y): the elevator pitches nose down,
#: the roll control rolls right, the rudder yaws nose left.  All 25 JSBSim aircraft that fly and
#: the Twin Otter have these signs (a canard is the exception in pitch).
AIRCRAFT_CONTROL_SIGNS = {"Cm": ("delta_p", -1.0), "Cl": ("delta_r", 1.0), "Cn": ("delta_y", -1.0)}


def control_sign_warnings(fits: dict, models: dict) -> dict[str, str]:
    """channel -> a warning, for an aircraft's primary control derivative (AIRCRAFT_CONTROL_SIGNS)
    whose whole 95 % interval has the other sign: the sign of that surface in the telemetry (an
    import map's ``sign = -1``) or the vehicle's mixing is the likely cause, far more than the
    aircraft (a flipped elevator on c182 gave C_m,delta_p +0.652 +- 0.016, every other estimate
    as before, and nothing said so)."""
    out = {}
    for channel, (signal, sign) in AIRCRAFT_CONTROL_SIGNS.items():
        fit, model = fits.get(channel), models.get(channel)
        if fit is None or model is None:
            continue
        ci = np.asarray(fit.conf_int(), float)
        for j, term in enumerate(model.terms):
            if pure_term_factor(term.expression, signal) is None:
                continue
            lo, hi = (float(v) for v in ci[j])
            if (sign < 0 and lo > 0) or (sign > 0 and hi < 0):
                out[channel] = (f"{term.coefficient} came out {'positive' if sign < 0 else 'negative'} at 95 % "
                                f"[{lo:.4g}, {hi:.4g}], where aerosid's control conventions give an aircraft a "
                                f"{'negative' if sign < 0 else 'positive'} one (elevator and ailerons positive "
                                "trailing edge down, rudder trailing edge left): check that surface's sign in the "
                                "telemetry (an import map's sign = -1) and the vehicle file's [controls] mixing "
                                "before using the estimates" + ("; a canard is the exception" if channel == "Cm" else ""))
    return out


def damping_signal(channel: str, expression: str) -> str | None:
    """The rate signal of a pure damping term of `channel` (:func:`damping_term`), or None."""
    found = damping_term(channel, expression)
    return None if found is None else found[0]


def wrong_sign_damping(channel: str, expression: str, ci_low) -> bool:
    """Whether a pure damping term (:func:`damping_signal`) has its whole 95 % interval above 0."""
    lo = float(ci_low)
    return math.isfinite(lo) and lo > 0.0 and damping_signal(channel, expression) is not None


def wrong_sign(table: pd.DataFrame) -> list[str]:
    """The damping coefficients of a coefficients table that came out wholly positive at 95 %
    (:func:`wrong_sign_damping`): the table's ``wrong_sign`` column (identify sets it on the
    interval before the model-structure mixture widens it), or the rule on the table's interval."""
    flag = (table["wrong_sign"].map(lambda w: isinstance(w, (bool, np.bool_)) and bool(w))
            if "wrong_sign" in table.columns else pd.Series(False, index=table.index))
    rule = (pd.Series([wrong_sign_damping(r["channel"], r["expression"], r["ci_low"]) for _, r in table.iterrows()],
                      index=table.index, dtype=bool)
            if {"expression", "channel", "ci_low"} <= set(table.columns) and len(table)
            else pd.Series(False, index=table.index))
    return [str(c) for c, f in zip(table["coefficient"], flag | rule) if f]


def _is_constant(expression: str) -> bool:
    from aerosid.modelling.expressions import parse

    try:
        parse(expression, frozenset())
    except ValueError:
        return False  # it reads a signal
    return True
