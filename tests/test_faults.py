"""Faults (docs/bad-input.md, rows F1-F4): a process killed mid-stage, two inbox scans at
once, a read-only output folder, a full disk.

The kill-and-resume and the concurrent-inbox tests loop AEROSID_FAULT_LOOPS times
(default 2, so every CI run repeats them; raise it for longer soak loops).
"""
from __future__ import annotations

import errno
import hashlib
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pandas as pd
import pytest
from click.testing import CliRunner

from aerosid.simulation import load_case, simulate
from tasks import ledger

ROOT = Path(__file__).resolve().parents[1]
LOOPS = int(os.environ.get("AEROSID_FAULT_LOOPS", "2"))  # CI runs each fault twice


@pytest.fixture(scope="module")
def telemetry(tmp_path_factory):
    d = tmp_path_factory.mktemp("faults") / "f7"
    simulate(load_case("seed-rlv", duration_s=30.0), seed=7).write(d)
    return d / "telemetry.parquet"


def digests(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*.parquet"))}


def no_partial_files(folder: Path) -> None:
    assert not list(folder.rglob("*.tmp")), "temporary files left behind"
    for p in folder.rglob("*.parquet"):
        pd.read_parquet(p)


def run_chain(raw: str, run_dir: str) -> None:
    """Every stage of one flight through the task functions themselves (tasks.runner.execute:
    hashing, cache reuse, atomic validated write, ledger), without a Prefect server."""
    from tasks.runner import StageContext
    from tasks.stages import (flight_data_task, plan_segments_task, preprocess_task, regression_task,
                              smooth_segment_task)

    def ctx(seg=""):
        return StageContext(str(Path(run_dir) / "ledger.jsonl"), "local", "f7", seg)

    pre = preprocess_task.fn(raw, run_dir, ctx(), {})
    plan = plan_segments_task.fn(pre["path"], None, 5.0)
    done = [smooth_segment_task.fn(pre["path"], run_dir, ctx(s["segment_id"]), s, "seed-rlv", {})
            for s in plan["segments"]]
    fd = flight_data_task.fn(pre["path"], [d["path"] for d in done], run_dir, ctx(), "seed-rlv")
    regression_task.fn([fd["path"]], run_dir, ctx(), "seed-rlv", None, 0.5)


KILLED_SCRIPT = textwrap.dedent("""
    import os, sys, time
    from pathlib import Path
    sys.path.insert(0, {root!r})
    import aerosid.io as aio

    real = aio.pq.write_table
    target = "." + os.environ["KILL_AT"] + "."

    def write_then_hang(table, where, *args, **kwargs):
        real(table, where, *args, **kwargs)
        if Path(str(where)).name.startswith(target):
            size = os.path.getsize(where)
            os.truncate(where, size // 2)          # half of the file is on disk ...
            part = os.environ["MARKER"] + ".part"  # the marker appears whole: the test polls for it
            Path(part).write_text(str(where))
            os.replace(part, os.environ["MARKER"])
            time.sleep(300)                        # ... when SIGKILL arrives

    aio.pq.write_table = write_then_hang           # a hook of this test script only
    import tasks.runner                            # the same code as the resuming run, even if the
    tasks.runner.code_version = lambda: os.environ["CODE_VERSION"]  # tree is edited meanwhile
    from tests.test_faults import run_chain
    run_chain(sys.argv[1], sys.argv[2])
""")


@pytest.fixture(scope="module")
def reference(telemetry, tmp_path_factory):
    """An uninterrupted run's outputs."""
    ref = tmp_path_factory.mktemp("uninterrupted") / "run"
    run_chain(str(telemetry), str(ref))
    return digests(ref)


@pytest.mark.parametrize("loop", range(LOOPS))
@pytest.mark.parametrize("kill_at", ["preprocessed.parquet", "smoothed.parquet", "coefficients.parquet"])
def test_f1_kill_mid_stage_then_resume_gives_identical_outputs(telemetry, reference, tmp_path, kill_at, loop):
    run_dir, marker = tmp_path / "run", tmp_path / "writing"
    script = tmp_path / "killed.py"
    script.write_text(KILLED_SCRIPT.format(root=str(ROOT)))
    from aerosid.provenance import code_version

    env = {**os.environ, "KILL_AT": kill_at, "MARKER": str(marker), "CODE_VERSION": code_version()}
    proc = subprocess.Popen([sys.executable, str(script), str(telemetry), str(run_dir)], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 180
        while not marker.exists():
            assert proc.poll() is None, proc.stderr.read().decode()[-3000:]
            assert time.monotonic() < deadline, "the stage never started writing"
            time.sleep(0.05)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL
    half = Path(marker.read_text())
    assert half.exists() and half.name.endswith(".tmp")  # killed mid-write, really
    # what a reader sees: no file under the output's name, every visible Parquet complete
    for p in run_dir.rglob(kill_at):
        pytest.fail(f"a killed write left {p}")
    for p in run_dir.rglob("*.parquet"):
        pd.read_parquet(p)
    killed_records = ledger.read(run_dir / "ledger.jsonl")
    assert all(r["status"] == "ok" for r in killed_records)

    run_chain(str(telemetry), str(run_dir))  # the next run completes ...
    no_partial_files(run_dir)                # ... removes the half-written temporary file ...
    assert digests(run_dir) == reference     # ... and gives the uninterrupted run's bytes
    resumed = ledger.read(run_dir / "ledger.jsonl")[len(killed_records):]
    assert [r["status"] for r in resumed[:len(killed_records)]] == ["reused"] * len(killed_records)
    assert {r["status"] for r in resumed[len(killed_records):]} == {"ok"}


INBOX_SCRIPT = textwrap.dedent("""
    import json, sys
    sys.path.insert(0, {root!r})
    from flows.pipeline import reprocess_inbox
    report = reprocess_inbox(sys.argv[1], sys.argv[2], settle_s=0.05)
    print("REPORT " + json.dumps(report))
""")


@pytest.mark.parametrize("loop", range(LOOPS))
def test_f2_two_inbox_scans_at_once_process_each_file_once(prefect_harness, telemetry, tmp_path, loop):
    from prefect.settings import PREFECT_API_URL

    from schemas.coefficients import Coefficients
    from tasks.runner import read_validated

    inbox, out = tmp_path / "inbox", tmp_path / "out"
    inbox.mkdir()
    flights = ["fa", "fb"]
    for name in flights:
        (inbox / f"{name}.parquet").write_bytes(telemetry.read_bytes())
    script = tmp_path / "scan.py"
    script.write_text(INBOX_SCRIPT.format(root=str(ROOT)))
    env = {**os.environ, "PREFECT_API_URL": str(PREFECT_API_URL.value()), "PREFECT_LOGGING_LEVEL": "WARNING"}
    procs = [subprocess.Popen([sys.executable, str(script), str(inbox), str(out)], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    reports = []
    for p in procs:
        stdout, stderr = p.communicate(timeout=300)
        assert p.returncode == 0, stderr[-3000:]
        reports.append(json.loads(next(li for li in stdout.splitlines() if li.startswith("REPORT "))[7:]))
    print("inbox reports", reports)
    processed = [f for r in reports for f in r["processed"]]
    assert sorted(processed) == flights, reports  # each file by exactly one of the scans
    for r in reports:
        assert r["failed"] == [] and r["not_ready"] == []
        assert set(r["processed"]) | set(r["busy"]) | set(r["unchanged"]) == set(flights)
    led = out / "ledger.jsonl"
    lines = [li for li in led.read_text().splitlines() if li.strip()]
    records = ledger.read(led)
    assert len(records) == len(lines)  # no torn or interleaved record
    for f in flights:
        ok = [r for r in records if r["flight"] == f and r["stage"] == "preprocess" and r["status"] == "ok"]
        assert len(ok) == 1
        read_validated(out / f / "coefficients.parquet", Coefficients)
    no_partial_files(out)
    # a third scan finds nothing to do
    from flows.pipeline import reprocess_inbox

    rep = reprocess_inbox(str(inbox), str(out), settle_s=0.01)
    assert rep["processed"] == [] and sorted(rep["unchanged"]) == flights


def _cli_run(telemetry, out, *extra):
    from aerosid.cli import main

    return CliRunner().invoke(main, ["run", str(telemetry), "--out", str(out), *extra])


def test_f3_read_only_output_folder_gives_a_clear_error(prefect_harness, telemetry, tmp_path, monkeypatch):
    out = tmp_path / "readonly"
    out.mkdir()
    if os.geteuid() != 0:
        out.chmod(0o555)
    else:  # root writes through 0555: make the file system say what a read-only one says
        import aerosid.io

        def read_only(*args, dir=None, **kwargs):
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(dir))

        monkeypatch.setattr(aerosid.io.tempfile, "mkstemp", read_only)
    try:
        result = _cli_run(telemetry, out)
    finally:
        out.chmod(0o755)
    assert result.exit_code == 1 and isinstance(result.exception, SystemExit), result.output
    assert "Traceback" not in result.output
    assert f"cannot write the run folder {out}" in result.output
    assert ("Read-only file system" in result.output) or ("Permission denied" in result.output)
    assert not list(out.rglob("*.parquet")) and not list(out.rglob("*.tmp"))


def test_f4_full_disk_gives_a_clear_error_and_keeps_the_previous_output(prefect_harness, telemetry, tmp_path,
                                                                       monkeypatch):
    import aerosid.io

    out = tmp_path / "run"
    first = _cli_run(telemetry, out)
    assert first.exit_code == 0, first.output
    before = digests(out)
    real = aerosid.io.pq.write_table

    def disk_full(table, where, *args, **kwargs):
        real(table, where, *args, **kwargs)
        os.truncate(where, os.path.getsize(where) // 3)  # part of it made it to disk
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(where))

    monkeypatch.setattr(aerosid.io.pq, "write_table", disk_full)
    second = _cli_run(telemetry, out, "--mach-half-width", "0.4")  # the regression must write again
    assert second.exit_code == 1 and isinstance(second.exception, SystemExit), second.output
    assert "Traceback" not in second.output
    assert f"cannot write the run folder {out}: No space left on device" in second.output
    assert "coefficients.parquet" in second.output
    assert digests(out) == before  # the previous outputs are intact
    no_partial_files(out)
    fails = [r for r in ledger.read(out / "ledger.jsonl") if r["status"] == "failed"]
    assert fails and all("No space left on device" in r["error"] for r in fails)
