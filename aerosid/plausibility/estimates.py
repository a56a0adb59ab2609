"""The final check of a run: each estimate against its preflight value, and an aircraft's lift
slope and roll damping against what a wing can give.

A flight estimate that differs from the preflight value by more than the vehicle file's
``[plausibility] preflight_factor`` (either way, or with the opposite sign), and by more
than SIGNIFICANCE standard errors, is reported loudly: it is either a real and large
deviation worth a second look or, far more often, an input mistake (a column in the wrong
unit, a wrong reference length, a sign convention).  Only coefficients with a non-zero
preflight value are compared.

An aircraft has physics instead where it has no preflight value (a JSBSim vehicle file, a
real aircraft's): its normal-force slope C_N,alpha and roll damping C_l,p lie in ranges a
wing can give (the vehicle's ``[plausibility] cn_alpha_per_rad``, ``cl_p_per_rad``;
aerosid.plausibility.envelope has the numbers).  A 95 % interval wholly outside is an input
mistake that scales the coefficients and that nothing else sees: on c182 a wing area written
in ft^2 ran to "ok" with every coefficient x0.09, a span and chord in ft with C_l,p x0.09.
"""
from __future__ import annotations

import math

import numpy as np

#: An estimate is reported only when |estimate - preflight| exceeds this many standard errors.
SIGNIFICANCE = 3.0


def preflight_departure(estimate: float, std_error: float, reference: float, factor: float) -> tuple[float, str]:
    """(estimate / preflight, message); the message is empty when the estimate is within
    the factor, not significantly different, or there is nothing to compare."""
    if not (math.isfinite(estimate) and math.isfinite(reference)) or reference == 0.0:
        return math.nan, ""
    ratio = estimate / reference
    within = 1.0 / factor <= ratio <= factor
    sigma = std_error if math.isfinite(std_error) else 0.0
    if within or abs(estimate - reference) <= SIGNIFICANCE * sigma:
        return ratio, ""
    how = (f"{ratio:.3g} x its preflight value" if ratio > 0 else
           f"of the opposite sign to its preflight value ({ratio:.3g} x)")
    return ratio, (f"estimate {estimate:.4g} is {how} {reference:.4g}, beyond the factor {factor:g} "
                   f"([plausibility] preflight_factor) by more than {SIGNIFICANCE:g} sigma: check the units of "
                   "the telemetry columns it is built from and the vehicle file before trusting it")


#: (channel, signal, envelope field, what it is) of the aircraft's physical-range checks.
AIRCRAFT_RANGES = (("CN", "alpha", "cn_alpha_per_rad", "normal-force (lift) slope"),
                   ("Cl", "p_hat", "cl_p_per_rad", "roll damping"))
#: What scales each of them, for the message.
_CAUSES = {"CN": "the wing area S_m2 (ft^2 reads x1/10.8), the mass (lb reads x2.2) and the measured air data "
                 "(qbar_pa in psf reads x48)",
           "Cl": "the wing area S_m2 (ft^2 reads x1/10.8), the span span_m (ft reads x1/10.8), Ixx_kg_m2 and the "
                 "measured air data"}


def physical_range_departure(channel: str, expression: str, ci: tuple[float, float], envelope) -> str:
    """A message when an aircraft's term (AIRCRAFT_RANGES) has its whole 95 % interval ci outside
    the envelope's range (per rad of its signal: the expression's factor taken out), else ''."""
    from aerosid.identification.term_report import pure_term_factor

    for ch, signal, field, what in AIRCRAFT_RANGES:
        if ch != channel:
            continue
        factor = pure_term_factor(expression, signal)
        if factor is None:
            continue
        lo, hi = sorted(float(v) * factor for v in ci)
        bounds = getattr(envelope, field)
        if not (math.isfinite(lo) and math.isfinite(hi)) or (hi >= bounds[0] and lo <= bounds[1]):
            return ""
        return (f"its 95 % interval [{lo:.4g}, {hi:.4g}] /rad lies outside an aircraft's {what} "
                f"{bounds[0]:g}..{bounds[1]:g} /rad ([plausibility] {field}): check the units of {_CAUSES[ch]} "
                "before trusting any coefficient; with the inputs right, the channel's model misses what the "
                "aircraft does (`aerosid diagnose`)")
    return ""


def regression_span(t_s) -> tuple[float, float, int]:
    """(first, last [s], count) of the regressed flight data's finite times t_s: a regression
    finding's span (NaN, NaN, 0 when there are none)."""
    t = np.asarray(t_s, float)
    t = t[np.isfinite(t)]
    return (float(t.min()), float(t.max()), int(t.size)) if t.size else (math.nan, math.nan, 0)


def implausible_estimate_findings(table, t_s) -> list[dict]:
    """Run findings (aerosid.estimation.findings.Finding as dicts, kind ``implausible_estimate``)
    for the coefficients table's rows that carry a ``preflight_warning`` (a preflight departure
    or an aircraft's physical range): such a run is not "ok".  t_s: the regressed flight data's
    times [s], for the span."""
    t0, t1, _ = regression_span(t_s)
    out = []
    for _, row in table.iterrows():
        text = row.get("preflight_warning") or ""
        if text:
            out.append({"kind": "implausible_estimate", "segment": "regression", "channel": str(row["channel"]),
                        "t0_s": t0, "t1_s": t1, "n_samples": int(row["n_obs"]), "cut": False,
                        "detail": f"{row['coefficient']} = {row['estimate']:.4g}: {text}"})
    return out
