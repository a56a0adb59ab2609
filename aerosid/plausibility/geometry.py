"""The vehicle file's reference geometry against itself: an aircraft's chord against the mean
chord its wing area and span give.

Every C_m divides by the chord and every pitch-rate term by its square, every C_l and C_n by
the span, every coefficient by the wing area; a length written in feet scales them and nothing
in the flight sees it (c182: a chord in ft ran to "ok" with C_m x0.30, C_m,q x0.09).  The
wing area in ft^2 and the span in ft are caught by the estimates' physical ranges
(aerosid.plausibility.estimates); the chord is caught here: a trapezoidal wing's mean
aerodynamic chord is 1.0 to 1.33 x S/b (taper 1 to 0), and JSBSim's aircraft read 0.75-1.31
(delta wings and lifting bodies up to 2.2: Concorde 1.97, 787-8 2.13, X-24B 2.16).  One length
in feet moves the ratio by 3.28 (the chord or the span) or the area by 10.8.
"""
from __future__ import annotations

import math

from aerosid.estimation.findings import Finding
from aerosid.plausibility.estimates import regression_span

#: Each unit slip and the factor it puts on chord_m / (S_m2 / span_m).
SLIPS = (("chord_m in ft", 1.0 / 0.3048), ("span_m in ft", 1.0 / 0.3048), ("S_m2 in ft^2", 0.3048**2))


def reference_chord_ratio(S_m2, chord_m, span_m) -> float:
    """chord_m / (S_m2 / span_m): the chord over the mean chord the wing area and span give; NaN
    when one of them is missing."""
    if not all(x is not None and math.isfinite(float(x)) and float(x) > 0 for x in (S_m2, chord_m, span_m)):
        return math.nan
    return float(chord_m) / (float(S_m2) / float(span_m))


def chord_ratio(vehicle) -> float:
    """The vehicle file's reference_chord_ratio."""
    return reference_chord_ratio(vehicle.S_m2, vehicle.chord_m, vehicle.span_m)


def geometry_findings(vehicle, t_s) -> list[dict]:
    """Run findings (kind ``vehicle_geometry``, aerosid.estimation.findings.Finding as dicts) when
    the vehicle's chord ratio lies outside its [plausibility] chord_ratio.  t_s: the regressed
    flight data's times [s], for the span."""
    ratio = chord_ratio(vehicle)
    lo, hi = vehicle.envelope.chord_ratio
    if not math.isfinite(ratio) or lo <= ratio <= hi:
        return []
    slips = [name for name, f in SLIPS if lo <= ratio / f <= hi]
    cause = (f"as if {' or '.join(slips)} (it would read {ratio / dict(SLIPS)[slips[0]]:.3g})" if slips else
             "no single unit slip explains it")
    detail = (f"the vehicle file's chord_m {vehicle.chord_m:.4g} m is {ratio:.3g} x the mean chord its wing area and "
              f"span give (S_m2 / span_m = {vehicle.S_m2 / vehicle.span_m:.4g} m), outside {lo:g}..{hi:g} "
              f"([plausibility] chord_ratio; a wing's mean aerodynamic chord is 1.0-1.33 x S/b): {cause}. Every C_m "
              "scales with 1/chord and its pitch-rate terms with 1/chord^2, so check the reference lengths' units "
              "before comparing the coefficients with anything")
    return [Finding("vehicle_geometry", "regression", "Cm", *regression_span(t_s), False, detail).as_dict()]
