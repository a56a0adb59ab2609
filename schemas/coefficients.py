"""Pandera model of ``coefficients.parquet``: one row per (channel, coefficient).

Estimates are SI per radian (per radian of delta/2 for pitch/yaw fin terms),
moments about the CG, named as in ``truth.json``.  ``std_error`` is corrected for
coloured residuals and the interval is built from it; ``std_error_ols`` is the
plain least-squares value, kept for comparison.  A coefficient that the flight
cannot identify (no excitation) has NaN estimate and ``identifiable`` False.
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import pandas as pd
import pandera.pandas as pa
from pandera.typing import Series

CHANNELS = ("CN", "CY", "Cm", "Cn", "Cl")


class Coefficients(pa.DataFrameModel):
    channel: Series[str] = pa.Field(isin=list(CHANNELS), metadata={"description": "regression channel"})
    coefficient: Series[str] = pa.Field(metadata={"description": "name as in truth.json"})
    estimate: Series[float] = pa.Field(nullable=True, metadata={"unit": "per rad (or -)"})
    std_error: Series[float] = pa.Field(nullable=True, ge=0, metadata={"unit": "per rad", "description": "coloured-residual corrected"})
    std_error_ols: Series[float] = pa.Field(nullable=True, ge=0, metadata={"unit": "per rad"})
    crb_std: Optional[Series[float]] = pa.Field(nullable=True, ge=0, metadata={
        "unit": "per rad (or -), as estimate", "description": "Cramér-Rao lower bound on the std: output-error "
        "information of the gyros and accelerometers under the run's R (aerosid.identification.crb)"})
    ci_low: Series[float] = pa.Field(nullable=True, metadata={"unit": "per rad", "description": "95 % interval from std_error"})
    ci_high: Series[float] = pa.Field(nullable=True, metadata={"unit": "per rad"})
    reference: Series[float] = pa.Field(nullable=True, metadata={"unit": "per rad", "description": "preflight value about the CG"})
    identifiable: Series[bool] = pa.Field()

    class Config:
        strict = False
        coerce = False

    @pa.dataframe_check(name="interval_contains_estimate")
    def _interval(cls, df: pd.DataFrame) -> pd.Series:
        est, lo, hi = (df[c].to_numpy(dtype=float) for c in ("estimate", "ci_low", "ci_high"))
        ok = ~np.isfinite(est) | ((lo <= est) & (est <= hi))
        return pd.Series(ok, index=df.index)

    @pa.dataframe_check(name="unique_channel_coefficient")
    def _unique(cls, df: pd.DataFrame) -> pd.Series:
        return ~df.duplicated(["channel", "coefficient"], keep=False)
