"""Pandera models of raw and preprocessed telemetry (SI units, radians).

``RawTelemetry``
    The shared raw contract: ``t_s`` plus 12 channels, all float64.  Channels may be
    NaN (dropouts).  ``t_s`` must be finite and strictly increasing.  Range checks
    are *tolerant*: a raw channel may carry isolated outliers and sentinel values
    (finding them is the preprocessing stage's job), but a channel whose finite,
    non-sentinel values are mostly (> ``RAW_MAX_OUT_OF_RANGE_FRACTION``) outside the
    physical bounds is rejected: that is a unit error (e.g. fins in degrees).
    Optional columns: the vanes ``alpha_vane_rad, beta_vane_rad`` and the measured air
    data ``rho_kg_m3, qbar_pa, p_static_pa, T_total_K`` (range-checked the same way).

``PreprocessedTelemetry(RawTelemetry)``
    The output of ``aerosid.preprocess.preprocess``: the raw columns (``t_s`` is now
    the uniform grid), ``t_raw_s``, ``<channel>_clean`` (strictly within the physical
    bounds, NaN inside unfilled gaps), ``flags_<channel>`` and ``flags`` (uint16,
    bits in ``aerosid.preprocess.QualityFlag``), plus consistency checks between
    them.

``validate(df, model, source)`` runs a model lazily and turns pandera's
``SchemaErrors`` into a ``TelemetryError`` naming file, column, check and rows.

Units are in each field's ``metadata["unit"]``; ``metadata["bounds"]`` holds the
physical bounds used by the range checks (inclusive).
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import pandas as pd
import pandera.pandas as pa
from pandera.typing import Series

# ---------------------------------------------------------------------------
# The contract's constants (imported by aerosid.preprocess; no aerosid import here
# at module level, to keep the import graph acyclic).
# ---------------------------------------------------------------------------

#: Raw telemetry columns, in contract order.
RAW_COLUMNS: tuple[str, ...] = (
    "t_s", "ax_m_s2", "ay_m_s2", "az_m_s2", "p_rad_s", "q_rad_s", "r_rad_s",
    "d1_rad", "d2_rad", "d3_rad", "d4_rad", "V_m_s", "h_m",
)
#: The 12 measurement channels (every raw column but time).
CHANNELS: tuple[str, ...] = RAW_COLUMNS[1:]
#: Optional air-data vanes: a vehicle file with ``[air_data] source = "vanes"`` needs them.
VANE_CHANNELS: tuple[str, ...] = ("alpha_vane_rad", "beta_vane_rad")
#: Optional measured air data (issue 17): density, dynamic pressure, static pressure and
#: total temperature.  When present they replace the US-1976 atmosphere in the flight
#: coefficients (``aerosid.vehicles.atmosphere.air_data``; the run records the source of each
#: quantity).
MEASURED_AIR_DATA_CHANNELS: tuple[str, ...] = ("rho_kg_m3", "qbar_pa", "p_static_pa", "T_total_K")
#: Every optional air-data channel: cleaned like the others when a telemetry file
#: carries it.  They do not enter the ``flags`` OR (that stays the 12 contract channels').
AIR_DATA_CHANNELS: tuple[str, ...] = VANE_CHANNELS + MEASURED_AIR_DATA_CHANNELS

#: SI unit of every raw column.
UNITS: dict[str, str] = {
    "t_s": "s",
    "ax_m_s2": "m/s^2", "ay_m_s2": "m/s^2", "az_m_s2": "m/s^2",
    "p_rad_s": "rad/s", "q_rad_s": "rad/s", "r_rad_s": "rad/s",
    "d1_rad": "rad", "d2_rad": "rad", "d3_rad": "rad", "d4_rad": "rad",
    "V_m_s": "m/s", "h_m": "m",
    "alpha_vane_rad": "rad", "beta_vane_rad": "rad",
    "rho_kg_m3": "kg/m^3", "qbar_pa": "Pa", "p_static_pa": "Pa", "T_total_K": "K",
}

#: Physical bounds (inclusive) per channel.  Accelerations ~100 g, body rates
#: 10 rad/s (573 deg/s), fins 0.6 rad (34 deg: a fin column in degrees fails),
#: navigation speed 0..12 km/s, altitude -500 m .. 150 km.  Measured air data: density
#: 0..2 kg/m^3 (sea level on the coldest day ~1.5), dynamic pressure 0..2 MPa (a
#: hypersonic vehicle's ~0.1 MPa with room), static pressure 0..120 kPa (-500 m on a
#: high-pressure day ~108 kPa), total temperature 150..8000 K (Mach 12 at 220 K
#: stagnates at ~6600 K).  These catch gross unit errors only (a temperature in deg C,
#: a pressure in mbar x 1000): slug/ft^3 or psf values are inside, an importer converts.
PHYSICAL_BOUNDS: dict[str, tuple[float, float]] = {
    "ax_m_s2": (-1000.0, 1000.0), "ay_m_s2": (-1000.0, 1000.0), "az_m_s2": (-1000.0, 1000.0),
    "p_rad_s": (-10.0, 10.0), "q_rad_s": (-10.0, 10.0), "r_rad_s": (-10.0, 10.0),
    "d1_rad": (-0.6, 0.6), "d2_rad": (-0.6, 0.6), "d3_rad": (-0.6, 0.6), "d4_rad": (-0.6, 0.6),
    "V_m_s": (0.0, 12000.0),
    "h_m": (-500.0, 150000.0),
    "alpha_vane_rad": (-1.6, 1.6), "beta_vane_rad": (-1.6, 1.6),
    "rho_kg_m3": (0.0, 2.0), "qbar_pa": (0.0, 2.0e6), "p_static_pa": (0.0, 1.2e5), "T_total_K": (150.0, 8000.0),
}

_FLT_MAX = float(np.finfo(np.float32).max)
#: Sentinel values that mean "no data" (matched exactly, or after a float32 round
#: trip, e.g. float32(1e30) = 1.0000000150474662e30).
DEFAULT_SENTINELS: tuple[float, ...] = (
    -9999.0, 9999.0, -99999.0, 99999.0, -999999.0, 999999.0,
    -1e30, 1e30, -_FLT_MAX, _FLT_MAX,
)

#: A raw channel is rejected when more than this fraction of its finite,
#: non-sentinel values lies outside PHYSICAL_BOUNDS (unit error, not outliers).
RAW_MAX_OUT_OF_RANGE_FRACTION = 0.5


def sentinel_mask(values: np.ndarray, sentinels=DEFAULT_SENTINELS) -> np.ndarray:
    """True where ``values`` equals a sentinel exactly or after a float32 round trip."""
    values = np.asarray(values, dtype=np.float64)
    cands = set()
    for s in sentinels:
        cands.add(float(s))
        with np.errstate(over="ignore"):
            cands.add(float(np.float32(s)))
    cands.discard(float("inf"))
    cands.discard(float("-inf"))
    return np.isin(values, np.array(sorted(cands), dtype=np.float64))


def strictly_increasing(s: pd.Series) -> pd.Series:
    """Element-wise check: each value larger than the one before (the first passes)."""
    t = s.to_numpy()
    ok = np.ones(t.shape, dtype=bool)
    ok[1:] = t[1:] > t[:-1]
    return pd.Series(ok, index=s.index)


def _chan_meta(col: str, **extra) -> dict:
    meta = {"unit": UNITS[col]}
    if col in PHYSICAL_BOUNDS:
        meta["bounds"] = PHYSICAL_BOUNDS[col]
    meta.update(extra)
    return meta


def _raw(col: str):
    return pa.Field(nullable=True, metadata=_chan_meta(col, description="raw value as received; NaN = dropout"))


def _clean(col: str):
    return pa.Field(
        nullable=True,
        metadata=_chan_meta(col, description="usable value: raw where good, linearly interpolated over short "
                                             "bad runs, NaN in unfilled gaps"),
    )


def _flags(col: str):
    return pa.Field(metadata={"unit": "bitmask", "description": f"QualityFlag bits of {col}"})


class RawTelemetry(pa.DataFrameModel):
    """Raw telemetry (see module docstring).  Extra columns are allowed."""

    t_s: Series[float] = pa.Field(nullable=False, metadata={"unit": "s", "description": "sample time"})
    ax_m_s2: Series[float] = _raw("ax_m_s2")
    ay_m_s2: Series[float] = _raw("ay_m_s2")
    az_m_s2: Series[float] = _raw("az_m_s2")
    p_rad_s: Series[float] = _raw("p_rad_s")
    q_rad_s: Series[float] = _raw("q_rad_s")
    r_rad_s: Series[float] = _raw("r_rad_s")
    d1_rad: Series[float] = _raw("d1_rad")
    d2_rad: Series[float] = _raw("d2_rad")
    d3_rad: Series[float] = _raw("d3_rad")
    d4_rad: Series[float] = _raw("d4_rad")
    V_m_s: Series[float] = _raw("V_m_s")
    h_m: Series[float] = _raw("h_m")
    alpha_vane_rad: Optional[Series[float]] = _raw("alpha_vane_rad")
    beta_vane_rad: Optional[Series[float]] = _raw("beta_vane_rad")
    rho_kg_m3: Optional[Series[float]] = _raw("rho_kg_m3")
    qbar_pa: Optional[Series[float]] = _raw("qbar_pa")
    p_static_pa: Optional[Series[float]] = _raw("p_static_pa")
    T_total_K: Optional[Series[float]] = _raw("T_total_K")

    class Config:
        strict = False
        coerce = False

    @pa.check("t_s", name="finite")
    def _t_finite(cls, s: pd.Series) -> pd.Series:
        return pd.Series(np.isfinite(s.to_numpy()), index=s.index)

    @pa.check("t_s", name="strictly_increasing")
    def _t_increasing(cls, s: pd.Series) -> pd.Series:
        return strictly_increasing(s)

    @pa.check(*CHANNELS, *MEASURED_AIR_DATA_CHANNELS, name="mostly_in_physical_range")
    def _mostly_in_range(cls, s: pd.Series) -> pd.Series:
        lo, hi = PHYSICAL_BOUNDS[s.name]
        x = s.to_numpy()
        considered = np.isfinite(x) & ~sentinel_mask(x)
        outside = considered & ((x < lo) | (x > hi))
        n = int(considered.sum())
        if n == 0 or outside.sum() <= RAW_MAX_OUT_OF_RANGE_FRACTION * n:
            return pd.Series(np.ones(x.shape, dtype=bool), index=s.index)
        return pd.Series(~outside, index=s.index)


class PreprocessedTelemetry(RawTelemetry):
    """Output of ``aerosid.preprocess.preprocess`` (see module docstring).

    ``t_s`` is a uniform grid; raw channels are as received (NaN on inserted rows);
    ``t_raw_s`` is the original timestamp (NaN on inserted rows).
    """

    t_raw_s: Series[float] = pa.Field(
        nullable=True, metadata={"unit": "s", "description": "original timestamp; NaN for inserted rows"})

    ax_m_s2_clean: Series[float] = _clean("ax_m_s2")
    ay_m_s2_clean: Series[float] = _clean("ay_m_s2")
    az_m_s2_clean: Series[float] = _clean("az_m_s2")
    p_rad_s_clean: Series[float] = _clean("p_rad_s")
    q_rad_s_clean: Series[float] = _clean("q_rad_s")
    r_rad_s_clean: Series[float] = _clean("r_rad_s")
    d1_rad_clean: Series[float] = _clean("d1_rad")
    d2_rad_clean: Series[float] = _clean("d2_rad")
    d3_rad_clean: Series[float] = _clean("d3_rad")
    d4_rad_clean: Series[float] = _clean("d4_rad")
    V_m_s_clean: Series[float] = _clean("V_m_s")
    h_m_clean: Series[float] = _clean("h_m")

    flags_ax_m_s2: Series[np.uint16] = _flags("ax_m_s2")
    flags_ay_m_s2: Series[np.uint16] = _flags("ay_m_s2")
    flags_az_m_s2: Series[np.uint16] = _flags("az_m_s2")
    flags_p_rad_s: Series[np.uint16] = _flags("p_rad_s")
    flags_q_rad_s: Series[np.uint16] = _flags("q_rad_s")
    flags_r_rad_s: Series[np.uint16] = _flags("r_rad_s")
    flags_d1_rad: Series[np.uint16] = _flags("d1_rad")
    flags_d2_rad: Series[np.uint16] = _flags("d2_rad")
    flags_d3_rad: Series[np.uint16] = _flags("d3_rad")
    flags_d4_rad: Series[np.uint16] = _flags("d4_rad")
    flags_V_m_s: Series[np.uint16] = _flags("V_m_s")
    flags_h_m: Series[np.uint16] = _flags("h_m")
    alpha_vane_rad_clean: Optional[Series[float]] = _clean("alpha_vane_rad")
    beta_vane_rad_clean: Optional[Series[float]] = _clean("beta_vane_rad")
    flags_alpha_vane_rad: Optional[Series[np.uint16]] = _flags("alpha_vane_rad")
    flags_beta_vane_rad: Optional[Series[np.uint16]] = _flags("beta_vane_rad")
    rho_kg_m3_clean: Optional[Series[float]] = _clean("rho_kg_m3")
    qbar_pa_clean: Optional[Series[float]] = _clean("qbar_pa")
    p_static_pa_clean: Optional[Series[float]] = _clean("p_static_pa")
    T_total_K_clean: Optional[Series[float]] = _clean("T_total_K")
    flags_rho_kg_m3: Optional[Series[np.uint16]] = _flags("rho_kg_m3")
    flags_qbar_pa: Optional[Series[np.uint16]] = _flags("qbar_pa")
    flags_p_static_pa: Optional[Series[np.uint16]] = _flags("p_static_pa")
    flags_T_total_K: Optional[Series[np.uint16]] = _flags("T_total_K")
    flags: Series[np.uint16] = pa.Field(
        metadata={"unit": "bitmask", "description": "bitwise OR of the flags_<channel> columns"})

    class Config:
        strict = False
        coerce = False

    @pa.check(*(f"{c}_clean" for c in CHANNELS), name="in_physical_range")
    def _clean_in_range(cls, s: pd.Series) -> pd.Series:
        lo, hi = PHYSICAL_BOUNDS[s.name.removesuffix("_clean")]
        x = s.to_numpy()
        return pd.Series(np.isnan(x) | ((x >= lo) & (x <= hi)), index=s.index)

    @pa.dataframe_check(name="uniform_time_grid")
    def _uniform_grid(cls, df: pd.DataFrame) -> pd.Series:
        t = df["t_s"].to_numpy()
        ok = np.ones(t.shape, dtype=bool)
        if t.size > 2:
            d = np.diff(t)
            dt = np.median(d)
            tol = 1e-6 * abs(dt) + 8 * np.finfo(float).eps * np.abs(t[1:])
            ok[1:] = np.abs(d - dt) <= tol
        return pd.Series(ok, index=df.index)

    @pa.dataframe_check(name="t_raw_snapped_to_nearest_grid_point")
    def _t_raw_near_grid(cls, df: pd.DataFrame) -> pd.Series:
        from aerosid.preprocess.flags import QualityFlag

        t = df["t_s"].to_numpy()
        tr = df["t_raw_s"].to_numpy()
        ok = np.ones(t.shape, dtype=bool)
        if t.size > 1:
            dt = np.median(np.diff(t))
            # a TIME_JITTER row may sit up to a step away (moved off a point another row holds)
            jitter = (df["flags"].to_numpy().astype(np.int64) & int(QualityFlag.TIME_JITTER)) != 0
            reach = np.where(jitter, 1.0, 0.5) * dt * (1 + 1e-9)
            with np.errstate(invalid="ignore"):
                ok = np.isnan(tr) | (np.abs(tr - t) <= reach)
            present = ~np.isnan(tr)
            trp = tr[present]
            inc = np.ones(trp.shape, dtype=bool)
            inc[1:] = trp[1:] > trp[:-1]
            ok[present] &= inc
        return pd.Series(ok, index=df.index)

    @pa.dataframe_check(name="flags_is_or_of_channel_flags")
    def _flags_or(cls, df: pd.DataFrame) -> pd.Series:
        acc = np.zeros(len(df), dtype=np.int64)
        for c in CHANNELS:
            acc |= df[f"flags_{c}"].to_numpy().astype(np.int64)
        return pd.Series(acc == df["flags"].to_numpy().astype(np.int64), index=df.index)

    @pa.dataframe_check(name="flags_consistent_with_values")
    def _flags_consistent(cls, df: pd.DataFrame) -> pd.Series:
        """Per row and channel: missing row <=> t_raw_s NaN <=> raw NaN-by-insertion;
        flags == 0 => clean is raw bit for bit; clean NaN <=> LONG_GAP|EDGE_GAP;
        a detection bit <=> an action bit."""
        from aerosid.preprocess.flags import ACTION, DETECTION, QualityFlag, UNFILLED

        missing_row = np.isnan(df["t_raw_s"].to_numpy())
        ok = np.ones(len(df), dtype=bool)
        for c in (*CHANNELS, *(a for a in AIR_DATA_CHANNELS if f"flags_{a}" in df.columns)):
            f = df[f"flags_{c}"].to_numpy().astype(np.int64)
            raw = df[c].to_numpy()
            clean = df[f"{c}_clean"].to_numpy()
            is_missing = (f & int(QualityFlag.MISSING_ROW)) != 0
            ok &= is_missing == missing_row
            ok &= ~missing_row | np.isnan(raw)
            good = f == 0
            ok &= ~good | (raw.view(np.int64) == clean.view(np.int64))
            ok &= ~good | np.isfinite(clean)
            ok &= ((f & int(UNFILLED)) != 0) == np.isnan(clean)
            ok &= ((f & int(DETECTION)) != 0) == ((f & int(ACTION)) != 0)
        return pd.Series(ok, index=df.index)


def validate(df: pd.DataFrame, model: type[pa.DataFrameModel], source: str = "<memory>") -> pd.DataFrame:
    """Validate ``df`` against ``model`` lazily (all failures collected; no coercion,
    the frame is not copied) and return it.

    Raises ``aerosid.preprocess.TelemetryError`` naming the file (``source``), the
    first failing column and check, and the first failing row positions; the full
    list of failures is in the message (grouped by column and check).
    """
    from aerosid.preprocess.errors import TelemetryError

    if not isinstance(df, pd.DataFrame):
        raise TelemetryError(f"expected a pandas DataFrame, got {type(df).__name__}", file=source)
    try:
        return model.validate(df, lazy=True, inplace=True)
    except pa.errors.SchemaErrors as exc:
        failure_cases = exc.failure_cases
    # raised outside the except block: the message carries every failure, and the
    # SchemaErrors (which holds the data) is not chained as context, which would make
    # the error heavy to pickle (Prefect, tblib)
    reason, column, rows = _describe(failure_cases, df, model)
    raise TelemetryError(reason, file=source, column=column, rows=rows)


def _describe(fc: pd.DataFrame, df: pd.DataFrame, model) -> tuple[str, str | None, list[int]]:
    """Message, first failing column and its first rows from pandera failure cases."""
    pos_of = _positions(df)
    groups = []
    first_column, first_rows = None, []
    frame_level = fc["schema_context"].astype(str).eq("DataFrameSchema") & ~fc["check"].astype(str).isin(
        ["column_in_dataframe", "column_in_schema"])
    keys = fc["check"].astype(str).where(frame_level, fc["column"].astype(str) + "\x00" + fc["check"].astype(str))
    for _, sub in fc.groupby(keys, sort=False):
        check = str(sub["check"].iloc[0])
        idx = [i for i in sub["index"].tolist() if i is not None and not pd.isna(i)]
        rows = sorted({pos_of(i) for i in idx})
        if bool(frame_level.loc[sub.index[0]]):
            # a frame-wide check: pandera repeats it for every column; report it once
            col = FRAME_CHECK_COLUMN.get(check)
            desc = f"frame check {check}" + (f" (column {col!r})" if col else "")
            values = []
        else:
            column = sub["column"].iloc[0]
            col = None if pd.isna(column) else str(column)
            if col == model.__name__ or col is None:
                # a missing column is reported against the model, not a column
                col = str(sub["failure_case"].iloc[0]) if check == "column_in_dataframe" else None
            desc = f"column {col!r} check {check}"
            values = sub["failure_case"].tolist()[:3]
        if rows:
            desc += f" failed at {len(rows)} row(s), first {rows[:5]}" + (f" (values {values})" if values else "")
        else:
            desc += " failed" + (f" ({', '.join(str(v) for v in values)})" if values else "")
        groups.append(desc)
        if first_column is None:
            first_column, first_rows = col, rows
    return f"does not conform to {model.__name__}: " + "; ".join(groups), first_column, first_rows


#: The column a frame-wide check of PreprocessedTelemetry is about (for the error).
FRAME_CHECK_COLUMN = {
    "uniform_time_grid": "t_s",
    "t_raw_snapped_to_nearest_grid_point": "t_raw_s",
    "flags_is_or_of_channel_flags": "flags",
}


def _positions(df: pd.DataFrame):
    """Map an index label from failure_cases to a 0-based row position."""
    if isinstance(df.index, pd.RangeIndex) and df.index.start == 0 and df.index.step == 1:
        return lambda i: int(i)

    def pos(i):
        loc = df.index.get_loc(i)
        if isinstance(loc, slice):
            return int(loc.start)
        if isinstance(loc, np.ndarray):
            return int(np.flatnonzero(loc)[0])
        return int(loc)

    return pos
