"""Designed input time histories: columns, reading (``simulate --input``) and writing.

An input file holds ``t_s`` plus the control columns the simulator takes, radians:

* seed-rlv (the built-in simulator): ``delta_p_cmd_rad`` (pitch-fin command, mixed
  delta_p = -d2 + d4; the autopilot adds half of it to delta_p/2, exactly where the
  case's pitch plan goes), optionally ``delta_y_cmd_rad`` (yaw-fin command, mixed) and
  ``phi_cmd_rad`` (roll-angle command of the roll autopilot).  A column replaces the
  case's plan of its axis; a missing one keeps the case's plan; zero outside the file's
  time span.  The rate-damping autopilot and the guidance stay in the loop.
* JSBSim aircraft: ``elevator_cmd_rad``, ``aileron_cmd_rad``, ``rudder_cmd_rad``:
  surface-command increments about the trimmed commands [rad of surface deflection,
  JSBSim's signs: positive elevator = trailing edge down], converted to JSBSim's
  normalised commands through the aircraft's own control scaling; a missing column
  means no input on that axis.  The flight lasts the file's time span.
  Optionally ``throttle_cmd_norm`` (JSBSim's normalised throttle, 0 = idle .. 1 = full;
  constant over the file; c172x only): the flight is trimmed in a steady glide at this
  fixed throttle (the flight-path angle is solved for) and flown at it -- 0 is the
  power-off glide that keeps the propeller's moment out of the pitch-damping fit
  (docs/design.md).  Without it the throttle is the trim's (simulation.toml).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

RLV_COLUMNS = ("delta_p_cmd_rad", "delta_y_cmd_rad", "phi_cmd_rad")
JSBSIM_COLUMNS = ("elevator_cmd_rad", "aileron_cmd_rad", "rudder_cmd_rad", "throttle_cmd_norm")
#: settings rather than time histories: constant over the file, inside their range
SETTING_RANGES = {"throttle_cmd_norm": (0.0, 1.0)}
INPUT_COLUMNS = RLV_COLUMNS + JSBSIM_COLUMNS


class InputFileError(ValueError):
    """A designed-input file that cannot be flown; the message names file, column and rows."""


def read_input(path: str | Path, allowed: tuple[str, ...] = INPUT_COLUMNS) -> pd.DataFrame:
    """Read and check an input file (.parquet or .csv): t_s strictly increasing and
    finite, every other column one of `allowed` and finite."""
    path = Path(path)
    try:
        df = pd.read_parquet(path) if path.suffix.lower() == ".parquet" else pd.read_csv(path)
    except Exception as exc:  # pyarrow / pandas raise several types
        raise InputFileError(f"{path}: cannot read the input file ({exc})") from exc
    if "t_s" not in df.columns:
        raise InputFileError(f"{path}: no column t_s")
    controls = [c for c in df.columns if c != "t_s"]
    unknown = [c for c in controls if c not in allowed]
    if unknown:
        raise InputFileError(f"{path}: column(s) {', '.join(unknown)} are not inputs this simulator takes; "
                             f"expected t_s and some of {', '.join(allowed)}")
    if not controls:
        raise InputFileError(f"{path}: no control column (expected some of {', '.join(allowed)})")
    for c in ["t_s", *controls]:
        v = pd.to_numeric(df[c], errors="coerce").to_numpy(float)
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise InputFileError(f"{path}: column {c}: {bad.size} non-finite value(s), rows {_rows(bad)}")
        df[c] = v
    for c, (lo, hi) in SETTING_RANGES.items():
        if c in df.columns:
            v = df[c].to_numpy(float)
            bad = np.flatnonzero((v < lo) | (v > hi))
            if bad.size:
                raise InputFileError(f"{path}: column {c}: {bad.size} value(s) outside {lo:g}..{hi:g}, rows {_rows(bad)}")
            bad = np.flatnonzero(v != v[0])
            if bad.size:
                raise InputFileError(f"{path}: column {c} must be constant (a trim setting: the flight is trimmed "
                                     f"at it), but changes at rows {_rows(bad)}")
    t = df["t_s"].to_numpy(float)
    bad = np.flatnonzero(np.diff(t) <= 0) + 1
    if bad.size:
        raise InputFileError(f"{path}: column t_s is not strictly increasing at rows {_rows(bad)}")
    if t[0] < 0:
        raise InputFileError(f"{path}: column t_s starts before 0 s (row 0: {t[0]:g})")
    return df[["t_s", *controls]].reset_index(drop=True)


def _rows(idx: np.ndarray, k: int = 5) -> str:
    s = ", ".join(str(int(i)) for i in idx[:k])
    return s + (f" ... ({idx.size} in all)" if idx.size > k else "")


def as_case_inputs(df: pd.DataFrame) -> dict:
    """column -> (t_s, values) for SimulationCase.inputs."""
    t = df["t_s"].to_numpy(float)
    return {c: (t, df[c].to_numpy(float)) for c in df.columns if c != "t_s"}


def write_input(df: pd.DataFrame, out_dir: str | Path, metadata: dict | None = None) -> dict[str, Path]:
    """DIR/input.parquet and DIR/input.csv, atomically."""
    from aerosid.io import write_parquet_atomic, write_text_atomic

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    meta = {"aerosid.kind": "designed_input", **{k: str(v) for k, v in (metadata or {}).items()}}
    return {
        "parquet": write_parquet_atomic(df, out / "input.parquet", metadata=meta),
        "csv": write_text_atomic(df.to_csv(index=False, float_format="%.9g"), out / "input.csv"),
    }
