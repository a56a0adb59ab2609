"""The audit ledger: an append-only JSON Lines file, one record per stage execution,
and a hash chain over the records.

Plain tools query it (``grep``, ``jq``, ``pandas.read_json(lines=True)``).  A
record holds: ``time_utc, run_id, flight, segment, stage, status``
(``ok | reused | failed``; inbox records ``done | unchanged | skipped | ...``),
``inputs`` and ``outputs`` (each ``{path, sha256}``), ``params`` and
``params_sha256``, ``code_version``, ``rows_in, rows_out, flagged_rows``,
``error``, ``duration_s`` and, last, ``prev_sha256`` and ``sha256``.

The chain: ``sha256`` is the SHA-256 of the record's canonical JSON (keys sorted,
no spaces, ASCII, everything but ``sha256`` itself); ``prev_sha256`` is the
``sha256`` of the record before it (``null`` for the first).  Editing, removing,
inserting or reordering records breaks the chain at that line (``verify``).  A
record of an older aerosid (no ``sha256``) is hashed the same way when a new
record follows it, so an old ledger goes on growing as a chain.

Appends take an exclusive ``flock`` on the ledger; under it the appender reads the
last record's hash, then writes one line with one ``write`` and ``fsync``s, so
concurrent runs never interleave records nor fork the chain, and a killed process
leaves at most a missing record or a torn last line, which stays outside the chain.
"""
from __future__ import annotations

import fcntl
import hashlib
import json
import os
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

LEDGER_NAME = "ledger.jsonl"
_TAIL_CHUNK = 1 << 16


def canonical(record: dict) -> bytes:
    """The bytes a record's own hash covers: its JSON without ``sha256``, keys sorted."""
    body = {k: v for k, v in record.items() if k != "sha256"}
    return json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=True, default=str).encode()


def record_hash(record: dict) -> str:
    return hashlib.sha256(canonical(record)).hexdigest()


def _link(record: dict) -> str:
    """The hash the next record chains to: the stored one, or (an old record) its computed hash."""
    stored = record.get("sha256")
    return stored if isinstance(stored, str) else record_hash(record)


def _parse(line: bytes | str) -> dict | None:
    try:
        rec = json.loads(line)
    except (json.JSONDecodeError, UnicodeDecodeError):
        return None
    return rec if isinstance(rec, dict) else None


def _last_record(fd: int) -> dict | None:
    """The last whole record of the file (read backwards from its end; torn lines skipped)."""
    pos = os.fstat(fd).st_size
    tail, checked = b"", 0
    while pos > 0:
        step = min(_TAIL_CHUNK, pos)
        pos -= step
        tail = os.pread(fd, step, pos) + tail
        lines = tail.split(b"\n")
        whole = lines if pos == 0 else lines[1:]  # the first piece may be the end of an earlier line
        for line in reversed(whole[:len(whole) - checked]):
            if line.strip() and (rec := _parse(line)) is not None:
                return rec
        checked = len(whole)
    return None


def append(ledger: str | Path, record: dict) -> dict:
    """Append one record (time_utc, prev_sha256 and sha256 are added) and return it."""
    body = {"time_utc": datetime.now(timezone.utc).isoformat(timespec="milliseconds"), **record}
    body.pop("sha256", None), body.pop("prev_sha256", None)
    body = json.loads(json.dumps(body, default=str))  # the record exactly as a reader will see it
    path = Path(ledger)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        previous = _last_record(fd)
        body["prev_sha256"] = None if previous is None else _link(previous)
        body["sha256"] = record_hash(body)
        line = (json.dumps(body) + "\n").encode()
        size = os.fstat(fd).st_size
        if size and os.pread(fd, 1, size - 1) != b"\n":
            line = b"\n" + line  # a torn last line (a crash or a full disk mid-write) stays alone
        view = memoryview(line)
        while view:
            view = view[os.write(fd, view):]
        os.fsync(fd)
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)
    return body


def read(ledger: str | Path) -> list[dict]:
    """All records, oldest first; a torn line (a crash mid-write) is skipped."""
    return [rec for _, rec in _numbered(ledger)]


def _numbered(ledger: str | Path) -> list[tuple[int, dict]]:
    path = Path(ledger)
    if not path.exists():
        return []
    out = []
    for n, line in enumerate(path.read_bytes().split(b"\n"), start=1):
        if line.strip() and (rec := _parse(line)) is not None:
            out.append((n, rec))
    return out


# ----------------------------------------------------------------------- verification
@dataclass
class ChainCheck:
    """The outcome of checking a ledger's hash chain line by line."""

    path: str
    entries: list[tuple[int, dict]] = field(default_factory=list)  # (line number, record), whole records
    problems: list[tuple[int, str]] = field(default_factory=list)  # (line number, what is wrong), first first
    legacy_lines: list[int] = field(default_factory=list)           # records of an aerosid without the chain
    torn_lines: list[int] = field(default_factory=list)             # lines that are not a whole record

    @property
    def ok(self) -> bool:
        return not self.problems

    @property
    def n_records(self) -> int:
        return len(self.entries)

    def line_of(self, record: dict) -> int | None:
        return next((n for n, rec in self.entries if rec is record), None)

    def summary(self) -> str:
        out = [f"{self.path}: {self.n_records} records"]
        if self.legacy_lines:
            out.append(f"  {_span(self.legacy_lines)} written by an older aerosid without a hash chain: those "
                       "records cannot be checked for edits")
        if self.torn_lines:
            out.append(f"  {_span(self.torn_lines)}: not a whole record (a write cut short by a crash or a full "
                       "disk); left outside the chain")
        if self.problems:
            out += [f"  line {n}: {m}" for n, m in self.problems]
        elif len(self.legacy_lines) == self.n_records:
            out.append("  no record is chained yet (the next aerosid run starts the chain)")
        else:
            out.append("  hash chain intact" + (" from the first chained record" if self.legacy_lines else ""))
        return "\n".join(out)


def _span(lines: list[int]) -> str:
    if len(lines) > 1 and lines == list(range(lines[0], lines[-1] + 1)):
        return f"lines {lines[0]}-{lines[-1]}"
    return ("line " if len(lines) == 1 else "lines ") + ", ".join(map(str, lines))


_EDITED = "edited: the record's content does not match its own hash"
_UNHASHED = "a record without the hash chain's fields after the chain began: inserted, or its hash fields removed"


def _broken_link(line: int, prev_line: int | None) -> str:
    if prev_line is None:
        return "edited ledger: the first record, but chained to an earlier one: records before it were removed"
    return (f"edited ledger: chained to a different record than line {prev_line}: line {prev_line} was edited (its "
            f"hash recomputed), or records were removed or inserted between lines {prev_line} and {line}")


def verify(ledger: str | Path) -> ChainCheck:
    """Check every record's own hash and its link to the record before it; name the lines
    where the chain breaks (an edit, a removal, an insertion or a reordering)."""
    check = ChainCheck(str(ledger))
    path = Path(ledger)
    if not path.exists():
        return check
    prev_link, prev_line, chained = None, None, False
    for n, line in enumerate(path.read_bytes().split(b"\n"), start=1):
        if not line.strip():
            continue
        rec = _parse(line)
        if rec is None:
            check.torn_lines.append(n)
            continue
        check.entries.append((n, rec))
        stored = rec.get("sha256")
        if stored is None and "prev_sha256" not in rec:
            if chained:
                check.problems.append((n, _UNHASHED))
            else:
                check.legacy_lines.append(n)
        else:
            chained = True
            if stored != record_hash(rec):
                check.problems.append((n, _EDITED))
            if rec.get("prev_sha256") != prev_link:
                check.problems.append((n, _broken_link(n, prev_line)))
        prev_link, prev_line = _link(rec), n
    check.problems.sort(key=lambda p: p[0])
    return check


@dataclass(frozen=True)
class Recorded:
    """What the ledger says about an output's content for one cache key."""

    line: int | None                     # a verifying record that recorded exactly this content, or None
    others: dict[str, int]               # other contents recorded for the key by verifying records: sha -> line
    unverified: tuple[str, ...]          # why the key's other records cannot be trusted


def recorded_output(ledger: str | Path, cache_key: str, sha256: str) -> Recorded:
    """Find a record of this cache key (status ok or reused) that recorded an output with
    this content and verifies in the hash chain: its own hash, its link to the record
    before it, and every record after it to the end of the ledger (so a record edited
    and re-hashed, with or without the records after it, is not trusted unless the whole
    rest of the chain was rewritten).  Records are read from the end, only as far back as
    the oldest record of the key: a long ledger costs little."""
    path = Path(ledger)
    needle = cache_key.encode()
    data = path.read_bytes() if path.exists() else b""
    if needle not in data:
        return Recorded(None, {}, ())
    lines = data.split(b"\n")
    lowest = next(i for i, line in enumerate(lines) if needle in line)
    others, unverified = {}, []
    after, suffix_ok, problem = None, True, None  # the record after the current one; is the chain from it intact
    pending = None  # a record of the key, waiting for its link to the record before it

    def resolve(cand, suffix_problem, link_problem):
        n, rec = cand
        why = None
        if "sha256" not in rec and "prev_sha256" not in rec:
            why = f"line {n} was written by an older aerosid without a hash chain, so it cannot be checked for edits"
        elif suffix_problem or link_problem:
            why = f"line {n} fails the hash chain ({link_problem or suffix_problem})"
        hashes = [o.get("sha256") for o in rec.get("outputs") or []]
        if why is None:
            if sha256 in hashes:
                return n
            others.update({h: n for h in hashes if h not in others})
        elif why not in unverified:
            unverified.append(why)
        return None

    for i in range(len(lines) - 1, -1, -1):
        if pending is None and i < lowest:
            break
        if not lines[i].strip() or (rec := _parse(lines[i])) is None:
            continue
        n = i + 1
        link_ok = after is None or after[1].get("prev_sha256") == _link(rec)
        link_problem = None if link_ok else f"line {after[0]}: {_broken_link(after[0], n)}"
        if pending is not None:
            found = resolve(pending[0], pending[1], link_problem)
            if found is not None:
                return Recorded(found, others, tuple(unverified))
            pending = None
        chained = "sha256" in rec or "prev_sha256" in rec  # an old record is checked by the link to it only
        own = None if not chained or rec.get("sha256") == record_hash(rec) else f"line {n}: {_EDITED}"
        problem = own or link_problem or problem
        suffix_ok = suffix_ok and own is None and link_ok
        if needle in lines[i] and rec.get("cache_key") == cache_key and rec.get("status") in ("ok", "reused"):
            pending = ((n, rec), None if suffix_ok else problem)
        after = (n, rec)
    if pending is not None:  # the key's record is the ledger's first: it must not be chained to anything
        first_ok = pending[0][1].get("prev_sha256") is None
        found = resolve(pending[0], pending[1],
                        None if first_ok else f"line {pending[0][0]}: {_broken_link(pending[0][0], None)}")
        if found is not None:
            return Recorded(found, others, tuple(unverified))
    return Recorded(None, others, tuple(unverified))


# ----------------------------------------------------------------------- lineage
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


def writer_of_path(records: list[dict], path: str | Path) -> tuple[dict, dict] | None:
    """The latest successful record that wrote a file at this path (whatever its content): (record, output)."""
    target = os.path.abspath(path)
    for rec in reversed(records):
        if rec.get("status") in ("ok", "reused"):
            for out in rec.get("outputs") or []:
                if out.get("path") and os.path.abspath(out["path"]) == target:
                    return rec, out
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
