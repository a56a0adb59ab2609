"""The audit ledger: append-only, concurrent-safe, a torn line never swallows a record."""
import hashlib
import json
import threading

import pytest

from tasks import ledger


def test_a_torn_last_line_does_not_swallow_the_next_record(tmp_path):
    path = tmp_path / "ledger.jsonl"
    path.write_text('{"stage": "a"}\n{"stage": "tor')  # a crash mid-write
    ledger.append(path, {"stage": "b"})
    assert [r["stage"] for r in ledger.read(path)] == ["a", "b"]


def test_concurrent_appends_never_interleave(tmp_path):
    path = tmp_path / "ledger.jsonl"

    def writer(k):
        for i in range(200):
            ledger.append(path, {"writer": k, "i": i, "pad": "x" * 500})

    threads = [threading.Thread(target=writer, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    lines = path.read_text().splitlines()
    assert len(lines) == 800
    recs = [json.loads(line) for line in lines]  # every line is one whole record
    for k in range(4):
        assert [r["i"] for r in recs if r["writer"] == k] == list(range(200))


def test_trace_follows_inputs_back_to_files_no_stage_produced():
    recs = [
        {"status": "ok", "stage": "preprocess", "inputs": [{"path": "raw", "sha256": "r"}], "outputs": [{"sha256": "p"}]},
        {"status": "ok", "stage": "regression", "inputs": [{"path": "pre", "sha256": "p"}], "outputs": [{"sha256": "c"}]},
    ]
    chain = ledger.trace(recs, "c")
    assert [(d, r["stage"]) for d, r in chain] == [(0, "regression"), (1, "preprocess")]
    assert ledger.trace(recs, "unknown") == []


# --------------------------------------------------------------------------- the hash chain (issue 19)
def _lines(path):
    return path.read_text().splitlines()


def _write_lines(path, lines):
    path.write_text("\n".join(lines) + "\n")


def _chained(path, n=4):
    for i in range(n):
        ledger.append(path, {"stage": f"s{i}", "status": "ok", "outputs": [{"path": f"o{i}", "sha256": f"{i:064x}"}]})
    return ledger.read(path)


def test_each_record_carries_the_previous_records_hash_and_its_own(tmp_path):
    path = tmp_path / "ledger.jsonl"
    recs = _chained(path)
    assert recs[0]["prev_sha256"] is None
    for before, rec in zip(recs, recs[1:]):
        assert rec["prev_sha256"] == before["sha256"]
    for rec in recs:  # the own hash covers the canonical JSON of everything but itself
        body = {k: v for k, v in rec.items() if k != "sha256"}
        canonical = json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
        assert rec["sha256"] == hashlib.sha256(canonical.encode()).hexdigest() == ledger.record_hash(rec)
    check = ledger.verify(path)
    assert check.ok and check.problems == [] and check.n_records == 4


def _edit_value(lines, k):
    rec = json.loads(lines[k])
    rec["outputs"][0]["sha256"] = "f" * 64  # what an attacker does to make a tampered file pass
    return rec


@pytest.mark.parametrize("edit, line", [
    ("value", 2),         # a value edited, the record's hash left as it was
    ("value+hash", 3),    # ... and its own hash recomputed: line 3 no longer chains to it
    ("delete", 2),        # a record removed
    ("insert", 3),        # a record inserted (a copy of line 1 after line 2)
    ("swap", 2),          # two records exchanged
    ("delete-first", 1),  # the oldest record removed
    ("unhashed", 2),      # the hash fields removed from a record (made to look old)
])
def test_an_edit_anywhere_in_the_ledger_is_detected_naming_the_line(tmp_path, edit, line):
    path = tmp_path / "ledger.jsonl"
    _chained(path)
    lines = _lines(path)
    if edit == "value":
        lines[1] = json.dumps(_edit_value(lines, 1))
    elif edit == "value+hash":
        rec = _edit_value(lines, 1)
        rec["sha256"] = ledger.record_hash(rec)
        lines[1] = json.dumps(rec)
    elif edit == "delete":
        del lines[1]
    elif edit == "insert":
        lines.insert(2, lines[0])
    elif edit == "swap":
        lines[1], lines[2] = lines[2], lines[1]
    elif edit == "delete-first":
        del lines[0]
    elif edit == "unhashed":
        rec = json.loads(lines[1])
        del rec["sha256"], rec["prev_sha256"]
        lines[1] = json.dumps(rec)
    _write_lines(path, lines)
    check = ledger.verify(path)
    assert not check.ok
    first_line, message = check.problems[0]
    assert first_line == line, check.problems
    assert f"line {line}" in check.summary()
    if edit == "value+hash":
        assert "line 2" in message  # the record line 3 was chained to


def test_concurrent_appends_from_processes_chain_correctly(tmp_path):
    """Under the lock each appender reads the last record's hash: the chain has no fork."""
    import multiprocessing

    path = tmp_path / "ledger.jsonl"
    ctx = multiprocessing.get_context("spawn")  # fork of a process with Prefect's threads may die before it appends
    procs = [ctx.Process(target=_append_many, args=(str(path), k, 60)) for k in range(3)]
    for p in procs:
        p.start()
    for p in procs:
        p.join()
        assert p.exitcode == 0
    check = ledger.verify(path)
    assert check.ok, check.problems
    recs = ledger.read(path)
    assert len(recs) == 180 and len({r["prev_sha256"] for r in recs}) == 180  # one successor per record


def _append_many(path, k, n):
    for i in range(n):
        ledger.append(path, {"writer": k, "i": i, "pad": "x" * 300})


def test_threads_appending_at_once_chain_correctly(tmp_path):
    path = tmp_path / "ledger.jsonl"
    threads = [threading.Thread(target=_append_many, args=(path, k, 100)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    check = ledger.verify(path)
    assert check.ok and check.n_records == 400, check.problems


def test_a_torn_line_stays_outside_the_chain(tmp_path):
    """A crash mid-write leaves a torn line; the next record chains to the last whole one."""
    path = tmp_path / "ledger.jsonl"
    _chained(path, 2)
    with open(path, "a") as fh:
        fh.write('{"stage": "tor')
    ledger.append(path, {"stage": "after"})
    check = ledger.verify(path)
    assert check.ok, check.problems
    assert check.torn_lines == [3]
    assert [r["stage"] for r in ledger.read(path)] == ["s0", "s1", "after"]


def test_a_ledger_of_an_older_aerosid_is_read_and_said_to_be_unchained(tmp_path):
    path = tmp_path / "ledger.jsonl"
    path.write_text('{"stage": "preprocess", "status": "ok"}\n{"stage": "regression", "status": "ok"}\n')
    ledger.append(path, {"stage": "report", "status": "ok"})
    assert [r["stage"] for r in ledger.read(path)] == ["preprocess", "regression", "report"]
    check = ledger.verify(path)
    assert check.ok and check.legacy_lines == [1, 2]
    assert "lines 1-2" in check.summary() and "without a hash chain" in check.summary()
    # the first chained record is chained to the last old one: editing that one is seen
    lines = _lines(path)
    lines[1] = lines[1].replace("regression", "smooth")
    _write_lines(path, lines)
    line, message = ledger.verify(path).problems[0]
    assert line == 3 and "line 2" in message


def _keyed(path, n=5):
    for i in range(n):
        ledger.append(path, {"stage": "s", "status": "ok", "cache_key": f"k{i}",
                             "outputs": [{"path": "o", "sha256": f"{i:064x}"}]})


def test_a_record_is_trusted_for_reuse_only_if_the_chain_from_it_to_the_end_verifies(tmp_path):
    path = tmp_path / "ledger.jsonl"
    _keyed(path)
    assert ledger.recorded_output(path, "k1", f"{1:064x}").line == 2
    assert ledger.recorded_output(path, "k0", f"{0:064x}").line == 1
    miss = ledger.recorded_output(path, "k1", "f" * 64)  # other content: the recorded one is named
    assert miss.line is None and miss.others == {f"{1:064x}": 2}
    assert ledger.recorded_output(path, "nokey", "f" * 64) == ledger.Recorded(None, {}, ())
    # an attacker re-hashes line 2 and re-chains line 3 to it: line 4 still points at the old line 3
    lines = _lines(path)
    rec2, rec3 = json.loads(lines[1]), json.loads(lines[2])
    rec2["outputs"][0]["sha256"] = "f" * 64
    rec2["sha256"] = ledger.record_hash(rec2)
    rec3["prev_sha256"] = rec2["sha256"]
    rec3["sha256"] = ledger.record_hash(rec3)
    lines[1], lines[2] = json.dumps(rec2), json.dumps(rec3)
    _write_lines(path, lines)
    forged = ledger.recorded_output(path, "k1", "f" * 64)
    assert forged.line is None and "line 4" in forged.unverified[0], forged
    assert ledger.verify(path).problems[0][0] == 4
    # records after the break verify from there on; a record before it is not trusted
    assert ledger.recorded_output(path, "k4", f"{4:064x}").line == 5
    assert ledger.recorded_output(path, "k0", f"{0:064x}").line is None


def test_a_torn_line_and_failed_records_do_not_disturb_the_reuse_lookup(tmp_path):
    path = tmp_path / "ledger.jsonl"
    _keyed(path, 2)
    with open(path, "a") as fh:
        fh.write('{"stage": "torn')
    ledger.append(path, {"stage": "s", "status": "failed", "cache_key": "k0", "outputs": []})
    ledger.append(path, {"stage": "s", "status": "ok", "cache_key": "k9", "outputs": [{"sha256": "9" * 64}]})
    assert ledger.recorded_output(path, "k0", f"{0:064x}").line == 1
    assert ledger.recorded_output(path, "k9", "9" * 64).line == 5
    assert ledger.verify(path).ok


def test_records_chained_after_old_ones_are_trusted_for_reuse(tmp_path):
    path = tmp_path / "ledger.jsonl"
    path.write_text('{"stage": "s", "status": "ok", "cache_key": "k0", "outputs": [{"sha256": "a"}]}\n')
    _keyed(path, 2)  # k0, k1 chained after the old record
    assert ledger.recorded_output(path, "k0", f"{0:064x}").line == 2
    old = ledger.recorded_output(path, "k0", "a")
    assert old.line is None and "older aerosid" in old.unverified[0]
    assert ledger.recorded_output(path, "k1", f"{1:064x}").line == 3
