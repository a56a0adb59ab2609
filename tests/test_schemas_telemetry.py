"""Tests of the pandera models in schemas/telemetry.py and of validate()."""
from __future__ import annotations

import pickle

import numpy as np
import pandas as pd
import pandera.pandas as pa
import pytest

from aerosid.preprocess import QualityFlag, TelemetryError, preprocess
from schemas.telemetry import (
    AIR_DATA_CHANNELS,
    CHANNELS,
    DEFAULT_SENTINELS,
    PHYSICAL_BOUNDS,
    RAW_COLUMNS,
    UNITS,
    PreprocessedTelemetry,
    RawTelemetry,
    sentinel_mask,
    validate,
)

RATE_HZ = 100.0


def raw_frame(n: int = 400, seed: int = 0) -> pd.DataFrame:
    """A small valid raw frame: smooth in-range signals plus noise."""
    rng = np.random.default_rng(seed)
    t = 10.0 + np.arange(n) / RATE_HZ
    data = {"t_s": t}
    for i, c in enumerate(CHANNELS):
        lo, hi = PHYSICAL_BOUNDS[c]
        mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        data[c] = mid + 0.05 * half * np.sin(2 * np.pi * 0.3 * t + i) + 1e-3 * half * rng.standard_normal(n)
    return pd.DataFrame(data)


def test_raw_schema_declares_the_contract_with_units():
    schema = RawTelemetry.to_schema()
    assert list(schema.columns) == list(RAW_COLUMNS) + list(AIR_DATA_CHANNELS)
    for c in AIR_DATA_CHANNELS:  # optional: vanes (aircraft) and measured air data
        assert not schema.columns[c].required and schema.columns[c].metadata["unit"] == UNITS[c]
    assert all(UNITS[c] == "rad" for c in ("alpha_vane_rad", "beta_vane_rad"))
    for c in RAW_COLUMNS:
        col = schema.columns[c]
        assert str(col.dtype) == "float64"
        assert col.metadata["unit"] == UNITS[c]
        assert col.nullable == (c != "t_s")


def test_preprocessed_schema_extends_the_raw_schema():
    assert issubclass(PreprocessedTelemetry, RawTelemetry)
    cols = PreprocessedTelemetry.to_schema().columns
    assert set(RAW_COLUMNS) <= set(cols)
    for c in CHANNELS:
        assert str(cols[f"{c}_clean"].dtype) == "float64"
        assert cols[f"{c}_clean"].metadata["unit"] == UNITS[c]
        assert str(cols[f"flags_{c}"].dtype) == "uint16"
    assert str(cols["flags"].dtype) == "uint16"
    assert cols["t_raw_s"].metadata["unit"] == "s"


def test_valid_raw_frame_passes_and_is_returned_uncopied():
    df = raw_frame()
    assert validate(df, RawTelemetry, "ok.parquet") is df


def test_raw_schema_tolerates_dropouts_sentinels_and_isolated_outliers():
    df = raw_frame()
    df.loc[10:30, list(CHANNELS)] = np.nan
    df.loc[50, "h_m"] = -9999.0
    df.loc[51, "V_m_s"] = 1e30
    df.loc[60, "q_rad_s"] = 1e6        # absurd spike: preprocessing flags it
    df["extra_column"] = 1.0           # extra columns are allowed
    validate(df, RawTelemetry, "ok.parquet")


@pytest.mark.parametrize("mutate, column, check, rows", [
    (lambda d: d.assign(t_s=d["t_s"].where(d.index != 7)), "t_s", None, [7]),
    (lambda d: d.assign(t_s=np.where(d.index == 8, d["t_s"].shift(1), d["t_s"])), "t_s", "strictly_increasing", [8]),
    (lambda d: d.assign(d3_rad=np.degrees(d["d3_rad"]) + 5.0), "d3_rad", "mostly_in_physical_range", [0, 1, 2]),
    (lambda d: d.assign(p_rad_s=d["p_rad_s"].astype(np.float32)), "p_rad_s", None, []),
    (lambda d: d.drop(columns=["h_m"]), "h_m", "column_in_dataframe", []),
])
def test_raw_schema_failures_name_file_column_check_and_rows(mutate, column, check, rows):
    with pytest.raises(TelemetryError) as ei:
        validate(mutate(raw_frame()), RawTelemetry, "bad.parquet")
    e = ei.value
    assert e.file == "bad.parquet" and "bad.parquet" in str(e)
    assert e.column == column and repr(column) in str(e)
    if check:
        assert check in str(e)
    assert e.rows[:len(rows)] == rows
    assert isinstance(e, ValueError)
    e2 = pickle.loads(pickle.dumps(e))
    assert str(e2) == str(e) and e2.rows == e.rows


def test_rows_are_positions_even_with_a_non_default_index():
    df = raw_frame().set_index(pd.RangeIndex(1000, 1400))
    df.iloc[5, df.columns.get_loc("t_s")] = df["t_s"].iloc[4]
    with pytest.raises(TelemetryError) as ei:
        validate(df, RawTelemetry, "x")
    assert ei.value.rows == [5]


def test_sentinel_mask_matches_exactly_and_after_float32_round_trip():
    x = np.array([-9999.0, 9999.0, 1e30, float(np.float32(1e30)), float(np.float32(-1e30)),
                  float(np.finfo(np.float32).max), 9999.001, 1e29, 0.0, np.nan, np.inf])
    assert sentinel_mask(x).tolist() == [True] * 6 + [False] * 5
    assert sentinel_mask(np.array([5.0]), sentinels=(5.0,)).tolist() == [True]
    assert -9999.0 in DEFAULT_SENTINELS


@pytest.fixture(scope="module")
def preprocessed() -> pd.DataFrame:
    df = raw_frame(600)
    df.loc[100:120, list(CHANNELS)] = np.nan
    df = df.drop(index=range(300, 340)).reset_index(drop=True)
    df.loc[200, "q_rad_s"] += 5.0
    return preprocess(df, source="mem").frame


def test_preprocess_output_conforms(preprocessed):
    validate(preprocessed, PreprocessedTelemetry, "pre.parquet")


def _corrupt(name: str, fr: pd.DataFrame) -> pd.DataFrame:
    fr = fr.copy()
    if name == "flags_not_or":
        fr.loc[3, "flags"] = np.uint16(0) | np.uint16(int(QualityFlag.OUTLIER))
    elif name == "clean_out_of_range":
        fr.loc[3, "d1_rad_clean"] = 0.9
    elif name == "grid_not_uniform":
        fr.loc[3, "t_s"] = fr.loc[3, "t_s"] + 0.003
    elif name == "flags_wrong_dtype":
        fr["flags_h_m"] = fr["flags_h_m"].astype(np.int64)
    elif name == "clean_differs_from_good_raw":
        fr.loc[3, "V_m_s_clean"] = fr.loc[3, "V_m_s"] + 1.0
    elif name == "t_raw_off_grid":
        fr.loc[3, "t_raw_s"] = fr.loc[3, "t_s"] + 0.008
    elif name == "unflagged_nan_clean":
        fr.loc[3, "ax_m_s2_clean"] = np.nan
    elif name == "missing_row_without_flag":
        fr.loc[3, "t_raw_s"] = np.nan
    return fr


@pytest.mark.parametrize("name, column_hint", [
    ("flags_not_or", "flags_is_or_of_channel_flags"),
    ("clean_out_of_range", "in_physical_range"),
    ("grid_not_uniform", "uniform_time_grid"),
    ("flags_wrong_dtype", "uint16"),
    ("clean_differs_from_good_raw", "flags_consistent_with_values"),
    ("t_raw_off_grid", "t_raw_snapped_to_nearest_grid_point"),
    ("unflagged_nan_clean", "flags_consistent_with_values"),
    ("missing_row_without_flag", "flags_consistent_with_values"),
])
def test_preprocessed_schema_catches_inconsistencies(preprocessed, name, column_hint):
    with pytest.raises(TelemetryError) as ei:
        validate(_corrupt(name, preprocessed), PreprocessedTelemetry, "pre.parquet")
    assert column_hint in str(ei.value)
    if name not in ("flags_wrong_dtype",):
        assert 3 in ei.value.rows or any(f"[3" in part for part in str(ei.value).split("first "))


def test_validate_rejects_non_frames():
    with pytest.raises(TelemetryError, match="DataFrame"):
        validate([1, 2, 3], RawTelemetry, "list")


def test_models_are_plain_pandera_models():
    assert issubclass(RawTelemetry, pa.DataFrameModel)
    with pytest.raises(pa.errors.SchemaErrors):
        RawTelemetry.validate(raw_frame().drop(columns=["t_s"]), lazy=True)
