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
from .flags import ACTION, DETECTION, DROPOUT, FAULT, UNFILLED, UNUSABLE, QualityFlag, flag_names, usable_mask
from .params import (
    DEFAULT_MIN_NOISE_SCALE,
    DEFAULT_MIN_SEGMENT_S,
    SENSOR_KEYS,
    PreprocessParams,
    SettingsError,
    merge_settings,
    parse_assignments,
    parse_settings,
)
from .core import preprocess
from .result import PREPROCESS_VERSION, PreprocessResult
from .sensors import SensorProfile
from .io import read_preprocessed_parquet, read_raw_parquet, write_preprocessed_parquet, write_raw_parquet

__all__ = [
    "ACTION", "DETECTION", "DROPOUT", "FAULT", "UNFILLED", "UNUSABLE",
    "DEFAULT_MIN_NOISE_SCALE", "DEFAULT_MIN_SEGMENT_S", "PREPROCESS_VERSION", "SENSOR_KEYS",
    "PreprocessParams", "PreprocessResult", "QualityFlag", "SensorProfile", "SettingsError", "TelemetryError",
    "merge_settings", "parse_assignments", "parse_settings",
    "flag_names", "preprocess", "usable_mask",
    "read_preprocessed_parquet", "read_raw_parquet", "write_preprocessed_parquet", "write_raw_parquet",
]
