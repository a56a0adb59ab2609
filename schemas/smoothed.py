"""Pandera model of a smoothed segment (output of the EKF + MBF smoother stage).

One row per sample of the segment's uniform grid.  The 21 states carry their units
in the column names; ``sigma_<column>`` is the smoothed 1-sigma of each.
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import pandas as pd
import pandera.pandas as pa
from pandera.typing import Series

from schemas.telemetry import strictly_increasing

#: EKF state -> column name (method.md §5; L, M, N are moment/inertia).
STATE_COLUMNS: dict[str, str] = {
    "p": "p_rad_s", "q": "q_rad_s", "r": "r_rad_s",
    "X1": "X1_m_s2", "X2": "X2_m_s3", "X3": "X3_m_s4",
    "Y1": "Y1_m_s2", "Y2": "Y2_m_s3", "Y3": "Y3_m_s4",
    "Z1": "Z1_m_s2", "Z2": "Z2_m_s3", "Z3": "Z3_m_s4",
    "L1": "L1_rad_s2", "L2": "L2_rad_s3", "L3": "L3_rad_s4",
    "M1": "M1_rad_s2", "M2": "M2_rad_s3", "M3": "M3_rad_s4",
    "N1": "N1_rad_s2", "N2": "N2_rad_s3", "N3": "N3_rad_s4",
}
RATE_DERIVATIVE_COLUMNS = ("p_dot_rad_s2", "q_dot_rad_s2", "r_dot_rad_s2")
MEAS_NAMES = ("ax", "ay", "az", "p", "q", "r")


def _unit(column: str) -> str:
    tail = column.split("_", 1)[1]
    return tail.replace("_", "/").replace("s2", "s^2").replace("s3", "s^3").replace("s4", "s^4")


def _finite(s: pd.Series) -> pd.Series:
    return pd.Series(np.isfinite(s.to_numpy(dtype=float)), index=s.index)


class SmoothedSegment(pa.DataFrameModel):
    """Smoothed states of one segment.  State and sigma columns are checked by the
    dynamic checks below (all 21 + 21 must be present and finite; sigma >= 0)."""

    t_s: Series[float] = pa.Field(metadata={"unit": "s"})
    segment: Series[str] = pa.Field(metadata={"description": "segment id within the flight"})
    nis_filter: Series[float] = pa.Field(nullable=True, metadata={"unit": "-", "description": "EKF NIS; NaN where no update"})
    nis_smoother: Series[float] = pa.Field(nullable=True, metadata={"unit": "-"})
    suspect: Optional[Series[bool]] = pa.Field(metadata={
        "unit": "-", "description": "sample condemned by a finding (gated run, NIS excursion): cut from the regression"})
    suspect_ax: Optional[Series[bool]] = pa.Field(metadata={
        "unit": "-", "description": "gated run on ax, kept for the channels a_x does not feed (aerosid.estimation."
                                   "findings.kept_sensors): cut only from C_A's fit"})
    suspect_ay: Optional[Series[bool]] = pa.Field(metadata={
        "unit": "-", "description": "gated run on ay, kept likewise (vanes only): cut only from C_Y's fit"})
    suspect_az: Optional[Series[bool]] = pa.Field(metadata={
        "unit": "-", "description": "gated run on az, kept likewise (vanes only): cut only from C_N's fit"})
    updated: Series[bool] = pa.Field(metadata={"description": "a measurement update happened at this sample"})

    class Config:
        strict = False
        coerce = False

    @pa.dataframe_check(name="states_and_sigmas_present_finite")
    def _states(cls, df: pd.DataFrame) -> pd.Series:
        cols = list(STATE_COLUMNS.values()) + [f"sigma_{c}" for c in STATE_COLUMNS.values()] + list(RATE_DERIVATIVE_COLUMNS)
        missing = [c for c in cols if c not in df.columns]
        if missing:
            return pd.Series(False, index=df.index)
        values = df[cols].to_numpy(dtype=float)
        ok = np.all(np.isfinite(values), axis=1)
        sig = df[[f"sigma_{c}" for c in STATE_COLUMNS.values()]].to_numpy(dtype=float)
        return pd.Series(ok & np.all(sig >= 0, axis=1), index=df.index)

    @pa.check("t_s", name="strictly_increasing")
    def _t_increasing(cls, s: pd.Series) -> pd.Series:
        return strictly_increasing(s)


def state_columns() -> list[str]:
    return list(STATE_COLUMNS.values())
