"""`aerosid audit FILE`: the lineage of a file through the ledger, every file in it
re-hashed, and the ledger's hash chain checked.

A file passes when (1) some ledger record wrote its exact content, (2) every file
the lineage read (the stages' inputs, back to the raw telemetry, the vehicle file
and its database) still has the content the ledger recorded, and (3) the ledgers
looked at verify in their hash chain.  A file that cannot be found is reported
but does not fail the audit (raw telemetry is often moved after processing).
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

from aerosid.provenance import sha256_file
from tasks import ledger


@dataclass(frozen=True)
class FileCheck:
    """One file of the lineage: the content hash recorded when a stage read it, and now."""

    path: str
    recorded: str
    now: str | None  # None: not found
    stage: str
    line: int | None

    @property
    def changed(self) -> bool:
        return self.now is not None and self.now != self.recorded

    def status(self) -> str:
        if self.now is None:
            return "NOT FOUND (not checked)"
        return f"CHANGED: now sha256 {self.now[:16]}…" if self.changed else "unchanged"


@dataclass(frozen=True)
class Audit:
    file: str
    sha256: str
    ledger: str | None
    lineage: tuple  # ((depth, ledger line, record), ...), the file's producer first
    files: tuple[FileCheck, ...]
    chain_summaries: tuple[str, ...]
    problems: tuple[str, ...]  # why the audit fails, most telling first
    notes: tuple[str, ...]

    @property
    def ok(self) -> bool:
        return not self.problems

    def lineage_text(self) -> str:
        if not self.lineage:
            return ""
        out = [f"{self.file} (sha256 {self.sha256[:16]}…), ledger {self.ledger}"]
        checks = {(f.path, f.recorded): f for f in self.files}
        for depth, line, rec in self.lineage:
            pad = "  " * depth
            out.append(f"{pad}<- stage {rec['stage']} [{rec['status']}] flight {rec.get('flight')} "
                       f"{rec.get('segment') or ''} run {rec.get('run_id')} at {rec.get('time_utc')} "
                       f"code {rec.get('code_version')} (ledger line {line})")
            out.append(f"{pad}   params {json.dumps(rec.get('params'), sort_keys=True, default=str)}")
            for inp in rec.get("inputs", []):
                check = checks.get((inp["path"], inp["sha256"]))
                state = f": {check.status()}" if check is not None else ""
                out.append(f"{pad}   input {inp['path']} sha256 {inp['sha256'][:16]}…{state}")
        return "\n".join(out)

    def summary(self) -> str:
        out = [self.lineage_text()] if self.lineage else []
        out += list(self.chain_summaries)
        n = len(self.files)
        missing = [f.path for f in self.files if f.now is None]
        if self.lineage:
            if not any(f.changed for f in self.files):
                out.append(f"{n - len(missing)} file{'' if n - len(missing) == 1 else 's'} in the lineage "
                           "re-hashed: unchanged" + (f"; not found (not checked): {missing}" if missing else ""))
        out += [f"note: {m}" for m in self.notes]
        return "\n".join(o for o in out if o)


def audit(file: str | Path) -> Audit:
    """Trace `file` through the ledgers in its folder and its parents; re-hash its lineage."""
    file = Path(file)
    sha = sha256_file(file)
    problems, notes, summaries = [], [], []
    used, lineage, checks = None, [], []
    for led in ledger.find_ledgers(file.parent):
        check = ledger.verify(led)
        checks.append(check)
        summaries.append(check.summary())
        problems += [f"{led} line {n}: {m}" for n, m in check.problems]
        records = [rec for _, rec in check.entries]
        chain = ledger.trace(records, sha)
        if chain:
            used, lineage = str(led), [(d, check.line_of(rec), rec) for d, rec in chain]
            latest = ledger.writer_of_path(records, file)
            if latest is not None and latest[1].get("sha256") != sha:
                notes.append(f"a later record (ledger line {check.line_of(latest[0])}, stage {latest[0]['stage']}) "
                             f"wrote other content to {file}: this is an earlier output, restored or copied here")
            break
    if not lineage:
        problems.insert(0, _unknown_content(file, sha, checks))
    files = _rehash(lineage)
    changed = [f for f in files if f.changed]
    if changed:
        first = changed[0]
        problems.insert(0, f"first changed file: {first.path} changed since stage {first.stage} read it (ledger "
                           f"line {first.line}: sha256 {first.recorded[:16]}… recorded, {first.now[:16]}… now)")
        problems[1:1] = [f"also changed: {f.path} (read by stage {f.stage})" for f in changed[1:]]
    return Audit(str(file), sha, used, tuple(lineage), tuple(files), tuple(summaries), tuple(problems), tuple(notes))


def _unknown_content(file: Path, sha: str, checks: list) -> str:
    for check in checks:
        latest = ledger.writer_of_path([rec for _, rec in check.entries], file)
        if latest is not None:
            rec, out = latest
            return (f"{file} changed since stage {rec['stage']} wrote it (ledger {check.path} line "
                    f"{check.line_of(rec)}: sha256 {str(out.get('sha256'))[:16]}… recorded, {sha[:16]}… now): "
                    "edited or replaced after the run; `aerosid run` computes it again")
    where = ", ".join(c.path for c in checks) or f"no ledger.jsonl in {file.parent} or its parents"
    return (f"{file}: no ledger record produced this content (sha256 {sha[:16]}…; looked in {where}); "
            "was it written by aerosid, or modified since?")


def _rehash(lineage: list) -> list[FileCheck]:
    """Every input of the lineage, each path once, in lineage order (nearest the file first)."""
    seen, out, hashes = set(), [], {}
    for _, line, rec in lineage:
        for inp in rec.get("inputs", []):
            path = inp.get("path")
            if not path or (path, inp.get("sha256")) in seen:
                continue
            seen.add((path, inp.get("sha256")))
            if path not in hashes:
                hashes[path] = sha256_file(path) if os.path.isfile(path) else None
            out.append(FileCheck(path, inp.get("sha256", ""), hashes[path], rec.get("stage", "?"), line))
    return out
