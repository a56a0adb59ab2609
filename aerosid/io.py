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


def write_text_atomic(text: str, path: str | Path, check: Callable[[Path], None] | None = None) -> Path:
    return _atomic(Path(path), lambda tmp: tmp.write_text(text), check)


#: Parquet metadata keys that name a telemetry file's vehicle, in order of precedence:
#: ``aerosid.vehicle_file`` (``aerosid import``'s vehicle file beside the telemetry),
#: ``aerosid.vehicle`` (an importer's: a built-in name or a vehicle TOML path, relative
#: to the telemetry file's folder or absolute) and ``aerosid.case`` (``aerosid simulate``'s
#: case name, which is a built-in vehicle's).
VEHICLE_METADATA_KEYS = ("aerosid.vehicle_file", "aerosid.vehicle", "aerosid.case")


class NoVehicleError(ValueError):
    """A telemetry file names no usable vehicle and none was given."""


def telemetry_vehicle(path: str | Path) -> str | None:
    """The vehicle a telemetry file names in its Parquet metadata (``VEHICLE_METADATA_KEYS``):
    a built-in vehicle's name, or the absolute path of the vehicle TOML file it names
    (a relative path is taken from the telemetry file's folder).

    Raises ``NoVehicleError`` when the file names none, or names one that is neither
    a built-in vehicle nor an existing file: there is no default vehicle (a wrong
    vehicle's mass and inertia would silently scale every coefficient).  Returns None
    when the file cannot be read at all: the preprocessing stage reports that, with
    the file's name."""
    from aerosid.vehicles.vehicle import builtin_vehicles

    path = Path(path)
    try:
        meta = pq.read_schema(path).metadata or {}
    except (OSError, pa.ArrowInvalid):
        return None
    builtin = builtin_vehicles()
    hint = (f"give the vehicle (aerosid run ... --vehicle NAME_OR_FILE): a built-in vehicle "
            f"({', '.join(builtin)}) or a vehicle TOML file (docs/vehicles.md)")
    for key in VEHICLE_METADATA_KEYS:
        value = meta.get(key.encode(), b"").decode("utf-8", "replace").strip()
        if not value:
            continue
        if value in builtin:
            return value
        candidate = Path(value) if Path(value).is_absolute() else path.parent / value
        if candidate.is_file():
            return str(candidate.resolve())
        raise NoVehicleError(f"{path}: its metadata {key} = {value!r} names neither a built-in vehicle nor an "
                             f"existing vehicle file (looked for {candidate}); {hint}")
    raise NoVehicleError(f"{path}: the telemetry names no vehicle (no {' or '.join(VEHICLE_METADATA_KEYS)} in its "
                         f"Parquet metadata) and none was given; {hint}")
