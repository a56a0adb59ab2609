"""The bad-input catalogue, rows I1-I8 (docs/bad-input.md): tampered outputs, an edited
ledger, inbox file names that would share a run folder, inbox files skipped without a
record.  Each test failed on the code before issue 19.  The ledger's own chain tests
are in tests/test_ledger.py, the reuse rule's in tests/test_runner.py."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from aerosid.cli import main
from tests.test_bad_input import flight, write  # noqa: F401  (the module's short flight fixture)


def edit_parquet(path: Path, column: str, change) -> None:
    """Change the values of one column, keeping the file's metadata (its cache key)."""
    import pyarrow
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    values = change(table[column].to_numpy().copy())
    edited = table.set_column(table.schema.get_field_index(column), column, pyarrow.array(values))
    pq.write_table(edited.replace_schema_metadata(table.schema.metadata), path)


def _bump_one_value(x):
    x[len(x) // 2] += 0.5
    return x


def _preprocess_only(raw: Path, run_dir: Path) -> dict:
    from tasks.runner import StageContext
    from tasks.stages import preprocess_task

    return preprocess_task.fn(str(raw), str(run_dir), StageContext(str(run_dir / "ledger.jsonl"), "local", "f"), {})


def test_i2_an_edited_intermediate_output_is_recomputed_not_reused(flight, tmp_path):
    """A value edited in preprocessed.parquet (metadata kept): the next run computes it
    again, byte-identical to the original, and the ledger says why."""
    from tasks import ledger

    run_dir = tmp_path / "run"
    first = _preprocess_only(flight[0], run_dir)
    original = (run_dir / "preprocessed.parquet").read_bytes()
    edit_parquet(run_dir / "preprocessed.parquet", "q_rad_s_clean", _bump_one_value)
    again = _preprocess_only(flight[0], run_dir)
    assert again["status"] == "ok" and again["sha256"] == first["sha256"]
    assert (run_dir / "preprocessed.parquet").read_bytes() == original
    rec = ledger.read(run_dir / "ledger.jsonl")[-1]
    assert rec["stage"] == "preprocess" and rec["status"] == "ok"
    assert f"recomputed: content of {run_dir / 'preprocessed.parquet'} changed since it was recorded" in rec["reason"]


def test_i2b_audit_rehashes_the_lineage_and_names_the_file_that_changed(flight, tmp_path):
    raw = tmp_path / "raw" / "f.parquet"
    raw.parent.mkdir()
    shutil.copy(flight[0], raw)
    run_dir = tmp_path / "run"
    _preprocess_only(raw, run_dir)
    target = str(run_dir / "preprocessed.parquet")
    ok = CliRunner().invoke(main, ["audit", target])
    assert ok.exit_code == 0, ok.output
    assert "1 file in the lineage re-hashed: unchanged" in ok.output
    edit_parquet(raw, "q_rad_s", _bump_one_value)  # the raw telemetry changed after the run
    bad = CliRunner().invoke(main, ["audit", target])
    assert bad.exit_code == 1 and isinstance(bad.exception, SystemExit) and "Traceback" not in bad.output
    assert f"first changed file: {raw}" in bad.output and "changed since stage preprocess read it" in bad.output


def test_i4_flight_ids_from_file_names_never_collide():
    from flows.steps import check_flight_id, flight_id_from_path

    names = ["a b.parquet", "a_b.parquet", "a-b.parquet", "a__b.parquet", "航班.parquet", "飞行.parquet",
             "....parquet", "x" * 150 + ".parquet", "x" * 151 + ".parquet", "A b.parquet", "a%20b.parquet"]
    ids = [flight_id_from_path(n) for n in names]
    assert len(set(ids)) == len(ids), dict(zip(names, ids))
    assert all(check_flight_id(i) == i for i in ids)
    assert ids[1] == "a_b" and ids[2] == "a-b"  # a name that is already an id stays as it is
    assert [flight_id_from_path(n) for n in names] == ids  # stable: the same name, the same flight


def test_i5_files_that_would_share_a_run_folder_are_refused_naming_both():
    from flows.steps import flight_id_from_path, inbox_flight_ids

    inbox = Path("/inbox")
    spaced = inbox / "a b.parquet"
    lookalike = inbox / f"{flight_id_from_path(spaced)}.parquet"  # a file named like another's id
    ids, refused = inbox_flight_ids([spaced, lookalike, inbox / "c.parquet"], inbox, {})
    assert ids == {inbox / "c.parquet": "c"}
    for p, other in ((spaced, lookalike), (lookalike, spaced)):
        assert other.name in refused[p] and "same flight id" in refused[p]
    # an id an earlier scan gave to one file stays that file's: a look-alike arriving later is refused
    ids, refused = inbox_flight_ids([spaced, lookalike], inbox, {flight_id_from_path(spaced): "a b.parquet"})
    assert ids == {spaced: flight_id_from_path(spaced)}
    assert "'a b.parquet'" in refused[lookalike] and "rename" in refused[lookalike]
    # a campaign: two files, one id -> an error naming both
    from flows.steps import FlightJob, check_unique_flights

    jobs = [FlightJob("/x/f1/telemetry.parquet", "/out/f1", "f1"), FlightJob("/y/f1/telemetry.parquet", "/out/f1", "f1")]
    with pytest.raises(ValueError, match="/x/f1/telemetry.parquet and /y/f1/telemetry.parquet map to the same"):
        check_unique_flights(jobs)


def test_i6_i7_inbox_files_never_share_a_run_folder_and_none_is_skipped_without_a_record(
        prefect_harness, flight, tmp_path, monkeypatch):
    """`a b.parquet`/`a_b.parquet` and `航班.parquet`/`飞行.parquet` (different contents) get four
    run folders, stable over scans; a hidden file, a folder, a busy flight and a file named
    like another's id are skipped with a ledger record saying why."""
    import fcntl
    import os

    import flows.pipeline
    from aerosid.provenance import sha256_file
    from flows.steps import flight_id_from_path
    from tasks import ledger

    def fake_run_flights(jobs, isolate=False):  # the stages are tested elsewhere: here, where files go
        (job,) = jobs
        Path(job.run_dir).mkdir(parents=True, exist_ok=True)
        (Path(job.run_dir) / "source.sha256").write_text(sha256_file(job.telemetry))
        return [{"status": "ok", "flight": job.flight, "segments_failed": []}]

    monkeypatch.setattr(flows.pipeline, "run_flights", fake_run_flights)
    inbox, out = tmp_path / "inbox", tmp_path / "out"
    inbox.mkdir()
    _, raw = flight
    contents = {}
    for k, name in enumerate(["a b.parquet", "a_b.parquet", "航班.parquet", "飞行.parquet"]):
        write(raw.iloc[k:], inbox / name)  # four different contents
        contents[name] = sha256_file(inbox / name)
    write(raw, inbox / ".partial.parquet")
    (inbox / "folder.parquet").mkdir()
    write(raw, inbox / f"{flight_id_from_path('a b.parquet')}x.parquet")  # an innocent neighbour
    for scan in range(2):
        report = flows.pipeline.reprocess_inbox(str(inbox), str(out), vehicle="seed-rlv", settle_s=0.01)
        assert report["failed"] == []
        for name, sha in contents.items():
            run_dir = out / flight_id_from_path(name)
            assert (run_dir / "source.sha256").read_text() == sha, name
    assert len({flight_id_from_path(n) for n in contents}) == 4
    # a file named like another's flight id, and a flight held by another scan
    write(raw.iloc[9:], inbox / f"{flight_id_from_path('a b.parquet')}.parquet")
    write(raw.iloc[11:], inbox / "held.parquet")
    (out / ".locks").mkdir(exist_ok=True)
    fd = os.open(out / ".locks" / "held.lock", os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX)
    try:
        report = flows.pipeline.reprocess_inbox(str(inbox), str(out), vehicle="seed-rlv", settle_s=0.01)
    finally:
        os.close(fd)
    assert (out / flight_id_from_path("a b.parquet") / "source.sha256").read_text() == contents["a b.parquet"]
    assert report["busy"] == ["held"]
    records = [r for r in ledger.read(out / "ledger.jsonl") if r["stage"] == "inbox"]
    last_scan = {}
    for r in records:
        last_scan[r["source"]] = r
    for p in inbox.iterdir():  # every file the pattern matches has a record of what became of it
        assert p.name in last_scan, p.name
    why = {name: rec.get("reason") or "" for name, rec in last_scan.items() if rec["status"] == "skipped"}
    assert set(why) == {".partial.parquet", "folder.parquet", f"{flight_id_from_path('a b.parquet')}.parquet",
                        "held.parquet"}
    assert "hidden" in why[".partial.parquet"] and "not a regular file" in why["folder.parquet"]
    assert "'a b.parquet'" in why[f"{flight_id_from_path('a b.parquet')}.parquet"]
    assert "busy" in why["held.parquet"]
    assert set(report["skipped"]) == {str(inbox / n) for n in why}


def _estimate_line(output: str, name: str) -> str:
    return next(line for line in output.splitlines() if line.strip().startswith(name + " "))


def test_i1_i3_tampered_outputs_are_recomputed_and_the_audit_names_what_changed(prefect_harness, flight, tmp_path):
    """End to end through the CLI: estimates ×10 in coefficients.parquet (metadata kept) are
    caught by the audit and recomputed by the next run; so is an edited preprocessed.parquet;
    an edited hash in ledger.jsonl fails the audit naming its line."""
    import json

    import pyarrow.parquet as pq

    from tasks import ledger

    out = tmp_path / "run"
    coefficients = out / "coefficients.parquet"

    def run_ok():
        result = CliRunner().invoke(main, ["run", str(flight[0]), "--out", str(out)])
        assert result.exit_code == 0, result.output
        return result.output

    def audit():
        return CliRunner().invoke(main, ["audit", str(coefficients)])

    first = run_ok()
    stages = sorted(str(p.relative_to(out)) for p in out.rglob("*.parquet"))
    original = {p: (out / p).read_bytes() for p in stages}
    assert audit().exit_code == 0
    # I1: estimates multiplied by 10, the metadata (and so the cache key) kept
    meta = pq.read_schema(coefficients).metadata
    edit_parquet(coefficients, "estimate", lambda x: x * 10.0)
    assert pq.read_schema(coefficients).metadata == meta
    tampered = audit()
    assert tampered.exit_code == 1 and "Traceback" not in tampered.output
    assert f"{coefficients} changed since stage regression wrote it" in tampered.output
    second = run_ok()
    assert _estimate_line(second, "CN_alpha") == _estimate_line(first, "CN_alpha")
    regression = [r for r in ledger.read(out / "ledger.jsonl") if r["stage"] == "regression"][-1]
    assert regression["status"] == "ok"
    assert regression["reason"].startswith(f"recomputed: content of {coefficients} changed since it was recorded")
    assert audit().exit_code == 0
    # I2: a value edited in an intermediate output
    edit_parquet(out / "preprocessed.parquet", "q_rad_s_clean", _bump_one_value)
    tampered = audit()
    assert tampered.exit_code == 1 and f"first changed file: {out / 'preprocessed.parquet'}" in tampered.output
    n = len(ledger.read(out / "ledger.jsonl"))
    run_ok()
    statuses = {(r["stage"], r["segment"]): r["status"] for r in ledger.read(out / "ledger.jsonl")[n:]}
    assert statuses.pop(("preprocess", "")) == "ok" and statuses.pop(("report", "")) == "ok"
    assert set(statuses.values()) == {"reused"}  # the repaired file is the original: the rest verifies
    assert {p: (out / p).read_bytes() for p in stages} == original
    assert audit().exit_code == 0
    # I3: an output hash edited in the ledger (line 1: the first preprocess record)
    lines = (out / "ledger.jsonl").read_text().splitlines()
    rec = json.loads(lines[0])
    rec["outputs"][0]["sha256"] = "0" * 64
    lines[0] = json.dumps(rec)
    (out / "ledger.jsonl").write_text("\n".join(lines) + "\n")
    edited = audit()
    assert edited.exit_code == 1 and "Traceback" not in edited.output
    assert f"{out / 'ledger.jsonl'} line 1:" in edited.output and "edited" in edited.output


def test_the_preprocess_stage_checks_units_and_signs_for_the_inbox_and_campaign_flows(flight, tmp_path):
    """The unit and sign check ran only in `aerosid run`'s pre-flight: an inbox scan or a campaign
    processed a pitch gyro in deg/s. The stage now refuses it, naming file and column, and writes
    no output; without a vehicle (nothing to check against) it preprocesses as before."""
    from aerosid.preprocess import TelemetryError
    from tasks.runner import StageContext
    from tasks.stages import preprocess_task

    _, raw = flight
    bad = write(raw.assign(q_rad_s=raw["q_rad_s"] * 57.29577951308232), tmp_path / "q_deg_s.parquet")
    run_dir = tmp_path / "run"
    ctx = StageContext(str(run_dir / "ledger.jsonl"), "local", "f")
    with pytest.raises(TelemetryError) as err:
        preprocess_task.fn(str(bad), str(run_dir), ctx, {}, "seed-rlv")
    assert err.value.column == "q_rad_s" and "look like deg/s" in str(err.value) and "q_deg_s.parquet" in str(err.value)
    assert not (run_dir / "preprocessed.parquet").exists()
    assert preprocess_task.fn(str(flight[0]), str(run_dir), ctx, {}, "seed-rlv")["status"] == "ok"
