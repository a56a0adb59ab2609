"""Parquet I/O of the preprocessing stage; the schemas are enforced on write and read.

These are the only functions of ``aerosid.preprocess`` with side effects.
"""
from __future__ import annotations

import os
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from schemas.telemetry import PreprocessedTelemetry, RawTelemetry, validate

from .errors import TelemetryError
from .result import PreprocessResult

#: What a damaged Parquet file can raise while it is read: Arrow's and the OS's errors, and
#: the KeyError / TypeError / ValueError of pandas rebuilding the frame from a damaged
#: ``pandas`` schema metadata entry (a hypothesis-found case: KeyError 'pandas_type').
_UNREADABLE = (OSError, pa.ArrowException, ValueError, KeyError, TypeError, IndexError)


def read_parquet_frame(path: str | os.PathLike) -> pd.DataFrame:
    """``pd.read_parquet(path)``; a file that exists but cannot be read becomes a
    TelemetryError naming it (a missing file stays FileNotFoundError)."""
    try:
        return pd.read_parquet(path)
    except _UNREADABLE as exc:
        if isinstance(exc, FileNotFoundError):
            raise
        raise TelemetryError(f"not a readable Parquet file ({type(exc).__name__}: {exc})", file=str(path)) from exc


def _write(df: pd.DataFrame, path: str | os.PathLike, metadata: dict[str, str]) -> Path:
    path = Path(path)
    table = pa.Table.from_pandas(df, preserve_index=False)
    meta = dict(table.schema.metadata or {})
    meta.update({k.encode(): v.encode() for k, v in metadata.items()})
    pq.write_table(table.replace_schema_metadata(meta), path)
    return path


def read_raw_parquet(path: str | os.PathLike) -> pd.DataFrame:
    """Read raw telemetry and enforce ``RawTelemetry`` (TelemetryError names the file)."""
    df = read_parquet_frame(path)
    return validate(df, RawTelemetry, str(path))


def write_raw_parquet(df: pd.DataFrame, path: str | os.PathLike, metadata: dict[str, str] | None = None) -> Path:
    """Enforce ``RawTelemetry`` and write ``df`` (no index) with optional string metadata."""
    validate(df, RawTelemetry, str(path))
    return _write(df, path, metadata or {})


def write_preprocessed_parquet(result: PreprocessResult, path: str | os.PathLike) -> Path:
    """Enforce ``PreprocessedTelemetry`` and write ``result.frame`` with ``result.metadata()``."""
    validate(result.frame, PreprocessedTelemetry, str(path))
    return _write(result.frame, path, result.metadata())


def read_preprocessed_parquet(path: str | os.PathLike) -> tuple[pd.DataFrame, dict[str, str]]:
    """Read a preprocessed file: (frame enforced against ``PreprocessedTelemetry``,
    its ``aerosid.*`` metadata as str -> str)."""
    table = pq.read_table(path)
    meta = {k.decode(): v.decode() for k, v in (table.schema.metadata or {}).items()
            if k.decode().startswith("aerosid.")}
    df = table.to_pandas()
    return validate(df, PreprocessedTelemetry, str(path)), meta
