"""The audit ledger: an append-only JSON Lines file, one record per stage execution.

Plain tools query it (``grep``, ``jq``, ``pandas.read_json(lines=True)``).  A
record holds: ``time_utc, run_id, flight, segment, stage, status``
(``ok | reused | failed``), ``inputs`` and ``outputs`` (each ``{path, sha256}``),
``params`` and ``params_sha256``, ``code_version``, ``rows_in, rows_out,
flagged_rows``, ``error`` and ``duration_s``.

Appends take an exclusive ``flock`` on the ledger and are one ``write`` of one
line followed by ``fsync``, so concurrent runs never interleave records and a
killed process leaves at most a missing record, never a torn one.
"""
from __future__ import annotations

import fcntl
import json
import os
from datetime import datetime, timezone
from pathlib import Path

LEDGER_NAME = "ledger.jsonl"


def append(ledger: str | Path, record: dict) -> dict:
    """Append one record (time_utc is added) and return it."""
    record = {"time_utc": datetime.now(timezone.utc).isoformat(timespec="milliseconds"), **record}
    line = (json.dumps(record, sort_keys=False, default=str) + "\n").encode()
    path = Path(ledger)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        if os.fstat(fd).st_size and os.pread(fd, 1, os.fstat(fd).st_size - 1) != b"\n":
            line = b"\n" + line  # a torn last line (a crash or a full disk mid-write) stays alone
        view = memoryview(line)
        while view:
            view = view[os.write(fd, view):]
        os.fsync(fd)
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)
    return record


def read(ledger: str | Path) -> list[dict]:
    """All records, oldest first; a torn last line (a crash mid-write) is skipped."""
    path = Path(ledger)
    if not path.exists():
        return []
    records = []
    for line in path.read_text().splitlines():
        if not line.strip():
            continue
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return records


def find_ledgers(start: str | Path) -> list[Path]:
    """Ledgers in the file's folder and its parents (a run folder or an inbox's output root)."""
    p = Path(start).resolve()
    folders = [p] if p.is_dir() else []
    folders += list(p.parents)
    return [f / LEDGER_NAME for f in folders if (f / LEDGER_NAME).is_file()]


def producer_of(records: list[dict], sha256: str) -> dict | None:
    """The latest successful record that wrote a file with this content hash."""
    for rec in reversed(records):
        if rec.get("status") in ("ok", "reused") and any(o.get("sha256") == sha256 for o in rec.get("outputs", [])):
            return rec
    return None


def trace(records: list[dict], sha256: str, depth: int = 0, seen: set | None = None) -> list[tuple[int, dict]]:
    """Lineage of a file back to inputs no stage produced (the raw telemetry):
    a list of (depth, record), the file's producer first."""
    seen = set() if seen is None else seen
    rec = producer_of(records, sha256)
    if rec is None or sha256 in seen:
        return []
    seen.add(sha256)
    chain = [(depth, rec)]
    for inp in rec.get("inputs", []):
        chain.extend(trace(records, inp["sha256"], depth + 1, seen))
    return chain
