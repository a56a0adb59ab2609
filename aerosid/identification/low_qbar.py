"""Flight-data rows flown far below the flight's dynamic pressure: taxi, take-off, a low-speed leg.

The flight-derived coefficients are moments and forces over qbar, so their noise grows as
1/qbar; an unweighted equation-error fit is ruled by the rows where qbar is small, where the
vanes float and the aerodynamics are not the flight's anyway.  :func:`low_qbar_rows` finds them
(aerosid.identification.flight_data cuts them, with a ``low_qbar`` finding).  numpy/pandas only.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from aerosid.estimation.findings import span_findings

#: Flight-data rows below this share of the flight's 95th-percentile dynamic pressure are left out:
#: at a quarter of it the coefficients' noise variance is 16 x.
LOW_QBAR_SHARE = 0.25


def low_qbar_rows(frame: pd.DataFrame) -> tuple[np.ndarray, list[dict]]:
    """Rows of a flight's flight data whose dynamic pressure is below LOW_QBAR_SHARE of the
    flight's 95th percentile, and their findings (``low_qbar``, cut).  A record that holds the
    taxi or take-off roll besides the manoeuvres (c182 with 30 s at 4 m/s ahead of its flight)
    gave C_N,alpha -37, C_m,alpha 0 and a positive C_l,p: the flight-derived coefficients are
    moments over qbar, so their noise grows as 1/qbar (16 x the variance at a quarter of it) and an
    unweighted fit is ruled by those rows, where the vanes float and the aerodynamics are not the
    flight's anyway.  Nothing moves on a flight flown at its manoeuvre speed (the benches' lowest
    qbar is 0.67 of the 95th percentile, seed-rlv's)."""
    q = frame["qbar_pa"].to_numpy(float) if len(frame) else np.zeros(0)
    if not q.size:
        return np.zeros(0, bool), []
    q95 = float(np.percentile(q, 95))
    low = q < LOW_QBAR_SHARE * q95
    found = []
    for seg in pd.unique(frame.loc[low, "segment"]) if low.any() else ():
        rows = (frame["segment"] == seg).to_numpy()
        f, _ = span_findings("low_qbar", str(seg), "qbar_pa", frame["t_s"].to_numpy(float)[rows], low[rows], 1, True,
                             f"dynamic pressure below {LOW_QBAR_SHARE:g} of the flight's 95th percentile "
                             f"({q95:.4g} Pa): taxi, take-off or a low-speed leg, where the coefficients' noise "
                             "grows as 1/qbar and the vanes float; left out of the regression (cut the record with "
                             "--window to keep only the manoeuvres)")
        found += [x.as_dict() for x in f]
    return low, found
