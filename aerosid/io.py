"""Atomic file writes: write to a temporary file beside the target, check it,
then rename over the target, so a reader never sees a half-written file and a
crash leaves the previous version intact."""
from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Callable

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq


def _atomic(path: Path, write: Callable[[Path], None], check: Callable[[Path], None] | None = None) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file the usual permissions
    try:
        write(tmp)
        if check is not None:
            check(tmp)
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_parquet_atomic(frame: pd.DataFrame, path: str | Path, metadata: dict[str, str] | None = None,
                         check: Callable[[Path], None] | None = None) -> Path:
    """Write `frame` to Parquet at `path` atomically, with key/value metadata.

    `check(tmp_path)` runs on the written temporary file before the rename (e.g.
    re-read and validate against a pandera schema); if it raises, the target is
    left untouched.
    """

    def write(tmp: Path) -> None:
        table = pa.Table.from_pandas(frame, preserve_index=False)
        merged = dict(table.schema.metadata or {})
        merged.update({k.encode(): str(v).encode() for k, v in (metadata or {}).items()})
        pq.write_table(table.replace_schema_metadata(merged), tmp)

    return _atomic(Path(path), write, check)


def read_parquet_metadata(path: str | Path) -> dict[str, str]:
    """The aerosid.* key/value metadata of a Parquet file."""
    meta = pq.read_schema(path).metadata or {}
    return {k.decode(): v.decode() for k, v in meta.items() if k.startswith(b"aerosid")}


def write_json_atomic(document, path: str | Path) -> Path:
    def write(tmp: Path) -> None:
        tmp.write_text(json.dumps(document, indent=2, sort_keys=False, default=float) + "\n")

    return _atomic(Path(path), write, lambda tmp: json.loads(tmp.read_text()))


def write_text_atomic(text: str, path: str | Path) -> Path:
    return _atomic(Path(path), lambda tmp: tmp.write_text(text))


def telemetry_vehicle(path: str | Path, default: str = "seed-rlv") -> str:
    """The vehicle a telemetry file names in its Parquet metadata: ``aerosid.vehicle``, a
    vehicle file relative to the telemetry's folder (a generated JSBSim flight writes
    ``vehicle.toml`` beside it), else the built-in vehicle ``aerosid.case`` (written by
    ``aerosid simulate``), else `default`."""
    from aerosid.vehicle import builtin_vehicles

    try:
        meta = pq.read_schema(path).metadata or {}
    except (OSError, pa.ArrowInvalid):  # unreadable: the preprocessing stage reports it with the file name
        return default
    vehicle = meta.get(b"aerosid.vehicle", b"").decode("utf-8", "replace")
    if vehicle and (Path(path).parent / vehicle).is_file():
        return str(Path(path).parent / vehicle)
    case = meta.get(b"aerosid.case", b"").decode("utf-8", "replace")
    return case if case in builtin_vehicles() else default
