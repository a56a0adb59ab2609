"""Property tests of the telemetry *reader* and the preprocessing on random damage to the
file and to its columns (tests/preprocess/test_preprocess.py damages the values of a valid frame).

Whatever the damage, the answer is a result or a TelemetryError naming the file (and,
when it is about a column, a contract column) -- never another exception.
"""
from __future__ import annotations

import io

import numpy as np
import pandas as pd
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aerosid.preprocess import TelemetryError, preprocess
from schemas.telemetry import RAW_COLUMNS, RawTelemetry
from tasks.runner import read_validated
from tests.preprocess.test_preprocess import make_flight

_RAW = make_flight(seed=5, duration_s=3.0, faults=False).raw
_BUF = io.BytesIO()
_RAW.to_parquet(_BUF, index=False)
_BYTES = _BUF.getvalue()
SETTINGS = settings(max_examples=40, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


def read_then_preprocess(path) -> None:
    try:
        raw = read_validated(path, RawTelemetry)
        preprocess(raw, source=str(path))
    except TelemetryError as e:
        assert e.file == str(path)
        assert e.column is None or e.column in RAW_COLUMNS
        assert str(path) in str(e)


@st.composite
def damaged_bytes(draw):
    data = bytearray(_BYTES)
    kind = draw(st.sampled_from(["truncate", "flip", "zero_block", "append", "prefix"]))
    if kind == "truncate":
        data = data[: draw(st.integers(0, len(data) - 1))]
    elif kind == "flip":
        for _ in range(draw(st.integers(1, 20))):
            k = draw(st.integers(0, len(data) - 1))
            data[k] ^= 1 << draw(st.integers(0, 7))
    elif kind == "zero_block":
        k = draw(st.integers(0, len(data) - 1))
        n = draw(st.integers(1, 4096))
        data[k:k + n] = bytes(len(data[k:k + n]))
    elif kind == "append":
        data += draw(st.binary(min_size=1, max_size=256))
    else:
        data = bytearray(draw(st.binary(min_size=0, max_size=64))) + data
    return bytes(data)


@SETTINGS
@given(damaged_bytes())
def test_random_damage_to_the_file_gives_a_frame_or_telemetry_error(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("bytes") / "damaged.parquet"
    path.write_bytes(data)
    read_then_preprocess(path)


@st.composite
def damaged_columns(draw):
    raw = _RAW.copy()
    for _ in range(draw(st.integers(1, 4))):
        col = draw(st.sampled_from(RAW_COLUMNS))
        kind = draw(st.sampled_from(["drop", "rename", "float32", "int", "str", "nan", "inf", "scale",
                                     "shuffle", "duplicate_name", "constant", "negate"]))
        if col not in raw.columns or raw.columns.tolist().count(col) > 1:
            continue
        if kind not in ("drop", "rename", "shuffle", "duplicate_name", "constant", "str") \
                and not pd.api.types.is_float_dtype(raw[col]):
            continue  # value damage on a column already made non-float
        if kind == "drop":
            raw = raw.drop(columns=[col])
        elif kind == "rename":
            raw = raw.rename(columns={col: col.upper()})
        elif kind == "float32":
            raw[col] = raw[col].astype("float32")
        elif kind == "int":
            # (an earlier "inf" damage on the column cannot be cast: it becomes 0 too)
            raw[col] = raw[col].replace([np.inf, -np.inf], np.nan).fillna(0).round().astype("int64")
        elif kind == "str":
            raw[col] = raw[col].astype(str)
        elif kind == "nan":
            raw.loc[raw.sample(frac=draw(st.floats(0.01, 1.0)), random_state=1).index, col] = np.nan
        elif kind == "inf":
            raw.loc[raw.index[draw(st.integers(0, len(raw) - 1))], col] = np.inf
        elif kind == "scale":
            raw[col] = raw[col] * draw(st.sampled_from([1e-3, 57.29577951308232, 1e3, 1e6, -1.0]))
        elif kind == "shuffle":
            raw = raw.sample(frac=1.0, random_state=draw(st.integers(0, 100))).reset_index(drop=True)
        elif kind == "duplicate_name":
            other = draw(st.sampled_from([c for c in raw.columns if c != col]))
            raw = raw.rename(columns={other: col})
        elif kind == "constant":
            raw[col] = 0.0
        else:
            raw[col] = -raw[col]
    return raw


@SETTINGS
@given(damaged_columns())
def test_random_damage_to_the_columns_gives_a_result_or_telemetry_error(tmp_path_factory, raw):
    path = tmp_path_factory.mktemp("columns") / "damaged.parquet"
    try:
        raw.to_parquet(path, index=False)
    except (ValueError, TypeError):  # pyarrow refuses to write it (e.g. duplicate names): nothing to read
        return
    read_then_preprocess(path)
