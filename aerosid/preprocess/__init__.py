"""Preprocessing stage (method.md §1): raw telemetry -> uniform grid + quality flags.

Public API::

    from aerosid.preprocess import preprocess, PreprocessParams, PreprocessResult
    from aerosid.preprocess import QualityFlag, usable_mask, TelemetryError
    from aerosid.preprocess import read_raw_parquet, write_raw_parquet
    from aerosid.preprocess import write_preprocessed_parquet, read_preprocessed_parquet

``preprocess`` is pure (no I/O); the ``*_parquet`` helpers are the only functions
here that touch files, and they enforce the schemas on write (and read).
"""
from .errors import TelemetryError
from .flags import ACTION, DETECTION, DROPOUT, UNFILLED, UNUSABLE, QualityFlag, flag_names, usable_mask
from .core import (
    DEFAULT_MIN_NOISE_SCALE,
    PREPROCESS_VERSION,
    PreprocessParams,
    PreprocessResult,
    preprocess,
)
from .io import read_preprocessed_parquet, read_raw_parquet, write_preprocessed_parquet, write_raw_parquet

__all__ = [
    "ACTION", "DETECTION", "DROPOUT", "UNFILLED", "UNUSABLE",
    "DEFAULT_MIN_NOISE_SCALE", "PREPROCESS_VERSION",
    "PreprocessParams", "PreprocessResult", "QualityFlag", "TelemetryError",
    "flag_names", "preprocess", "usable_mask",
    "read_preprocessed_parquet", "read_raw_parquet", "write_preprocessed_parquet", "write_raw_parquet",
]
