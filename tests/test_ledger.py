"""The audit ledger: append-only, concurrent-safe, a torn line never swallows a record."""
import json
import threading

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
