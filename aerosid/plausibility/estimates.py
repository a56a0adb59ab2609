"""The final check of a run: each estimate against its preflight value.

A flight estimate that differs from the preflight value by more than the vehicle file's
``[plausibility] preflight_factor`` (either way, or with the opposite sign), and by more
than SIGNIFICANCE standard errors, is reported loudly: it is either a real and large
deviation worth a second look or, far more often, an input mistake (a column in the wrong
unit, a wrong reference length, a sign convention).  Only coefficients with a non-zero
preflight value are compared.
"""
from __future__ import annotations

import math

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
