"""The common shape of a stage execution: hash the inputs, reuse a verified cached
output, or compute, validate and write atomically; record it in the ledger.

An output is reused only when its metadata carries this execution's cache key *and*
its content hash is one the ledger recorded for that key in a record that verifies
in the hash chain; otherwise it is computed again and the ``ok`` record's
``reason`` says why (``recomputed: content of X changed since it was recorded``).

No numerics here: ``produce`` is a closure that calls the core.
"""
from __future__ import annotations

import fcntl
import json
import os
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import pandas as pd
import pandera.pandas as pa
from pyarrow.lib import ArrowException

from aerosid.io import read_parquet_metadata, write_parquet_atomic
from aerosid.preprocess.io import read_parquet_frame
from aerosid.provenance import code_version, params_hash, sha256_file
from schemas.telemetry import validate
from tasks import ledger, progress


class StageFailed(RuntimeError):
    """A stage failed for a numerical or data reason (not retried; the ledger has it)."""


@dataclass(frozen=True)
class StageContext:
    """Where the ledger is and what this execution belongs to."""

    ledger_path: str
    run_id: str
    flight: str
    segment: str = ""


@dataclass(frozen=True)
class Produced:
    """What a stage computed: the frame to write and numbers for the ledger."""

    frame: pd.DataFrame
    metadata: dict
    rows_in: int
    flagged_rows: int = 0
    note: str = ""


def read_validated(path: str | Path, schema: type[pa.DataFrameModel]) -> pd.DataFrame:
    """Read a Parquet file and validate it; unreadable files name themselves."""
    return validate(read_parquet_frame(path), schema, str(path))


@contextmanager
def _writing(output: Path):
    """Exclusive right to write `output`: an flock on its folder.  Every writer of a
    stage output holds it, so a temporary file of the output found under it was left
    by a killed process and is removed (a kill mid-write leaves nothing behind)."""
    output.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(output.parent, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        for stale in output.parent.glob(f".{output.name}.*.tmp"):
            stale.unlink(missing_ok=True)
        yield
    finally:
        os.close(fd)  # releases the lock


def base_record(stage: str, ctx: StageContext, inputs: list[str | Path], input_hashes: list[str],
                params: dict) -> dict:
    """The ledger fields every stage execution shares (status, outputs and timing come later)."""
    return {"run_id": ctx.run_id, "flight": ctx.flight, "segment": ctx.segment, "stage": stage,
            "inputs": [{"path": os.path.abspath(p), "sha256": h} for p, h in zip(inputs, input_hashes)],
            "params": params, "params_sha256": params_hash(params), "code_version": code_version()}


def cache_key(stage: str, input_hashes: list[str], params: dict) -> str:
    return params_hash({"stage": stage, "inputs": input_hashes, "params": params, "code": code_version()})


def execute(stage: str, ctx: StageContext, inputs: list[str | Path], output: str | Path, params: dict,
            schema: type[pa.DataFrameModel], produce: Callable[[], Produced]) -> dict:
    """Run one stage execution; returns a small JSON-able dict (path, sha256, status, rows)."""
    output = Path(output)
    shown = progress.label(stage, ctx.flight, ctx.segment)
    progress.emit(shown, 0.0)
    try:
        return _execute(stage, ctx, inputs, output, params, schema, produce)
    finally:
        progress.emit(shown, 1.0)


def _execute(stage: str, ctx: StageContext, inputs: list[str | Path], output: Path, params: dict,
             schema: type[pa.DataFrameModel], produce: Callable[[], Produced]) -> dict:
    in_hashes = [sha256_file(p) for p in inputs]
    key = cache_key(stage, in_hashes, params)
    base = {**base_record(stage, ctx, inputs, in_hashes, params), "cache_key": key}
    started = time.perf_counter()
    reason = None
    if output.is_file():
        try:
            cached = read_parquet_metadata(output).get("aerosid.cache_key") == key
        except (OSError, ArrowException):
            cached = False
        if cached:
            sha = sha256_file(output)
            reason = _refusal(output, sha, ledger.recorded_output(ctx.ledger_path, key, sha))
            if reason is None:
                meta = read_parquet_metadata(output)
                out = {"path": os.path.abspath(output), "sha256": sha}
                ledger.append(ctx.ledger_path, {**base, "status": "reused", "outputs": [out],
                                                "rows_in": int(meta.get("aerosid.rows_in", -1)),
                                                "rows_out": int(meta.get("aerosid.rows_out", -1)),
                                                "flagged_rows": int(meta.get("aerosid.flagged_rows", 0)),
                                                "error": None, "duration_s": time.perf_counter() - started})
                return {**out, "status": "reused", "stage": stage, "segment": ctx.segment}
    if reason is not None:
        base["reason"] = reason
    try:
        produced = produce()
        metadata = {**{k: (v if isinstance(v, str) else json.dumps(v)) for k, v in produced.metadata.items()},
                    "aerosid.kind": stage, "aerosid.cache_key": key, "aerosid.code_version": code_version(),
                    "aerosid.params": json.dumps(params, sort_keys=True, default=str),
                    "aerosid.rows_in": str(produced.rows_in), "aerosid.rows_out": str(len(produced.frame)),
                    "aerosid.flagged_rows": str(produced.flagged_rows)}
        with _writing(output):
            write_parquet_atomic(produced.frame, output, metadata=metadata,
                                 check=lambda tmp: validate(pd.read_parquet(tmp), schema, str(output)))
    except Exception as exc:
        ledger.append(ctx.ledger_path, {**base, "status": "failed", "outputs": [], "rows_in": None, "rows_out": None,
                                        "flagged_rows": None, "error": f"{type(exc).__name__}: {exc}",
                                        "duration_s": time.perf_counter() - started})
        raise
    out = {"path": os.path.abspath(output), "sha256": sha256_file(output)}
    ledger.append(ctx.ledger_path, {**base, "status": "ok", "outputs": [out], "rows_in": produced.rows_in,
                                    "rows_out": len(produced.frame), "flagged_rows": produced.flagged_rows,
                                    "error": None, "note": produced.note,
                                    "duration_s": time.perf_counter() - started})
    return {**out, "status": "ok", "stage": stage, "segment": ctx.segment, "note": produced.note,
            **({"reason": reason} if reason else {})}


def _refusal(output: Path, sha: str, recorded: ledger.Recorded) -> str | None:
    """None when the output's content is what the ledger recorded for its cache key (in a
    record that verifies), else why it is computed again."""
    output = os.path.abspath(output)
    if recorded.line is not None:
        return None
    if recorded.others:
        known, line = max(recorded.others.items(), key=lambda kv: kv[1])
        return (f"recomputed: content of {output} changed since it was recorded (sha256 {sha[:16]}… on disk, "
                f"{known[:16]}… recorded at ledger line {line})")
    if recorded.unverified:
        return f"recomputed: the ledger's record of {output} cannot be trusted: " + "; ".join(recorded.unverified)
    return (f"recomputed: the ledger has no record of {output} for this cache key (the file was written "
            "elsewhere, or the ledger was replaced)")
