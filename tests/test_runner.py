"""tasks.runner.execute: an output is reused only when its content is the one the ledger
recorded for its cache key (issue 19); otherwise it is computed again and the ledger says why."""
from __future__ import annotations

import json

import pandas as pd
import pandera.pandas as pa
import pyarrow as pyarrow
import pyarrow.parquet as pq
import pytest

from tasks import ledger
from tasks.runner import Produced, StageContext, execute


class Toy(pa.DataFrameModel):
    x_m: float


@pytest.fixture
def stage(tmp_path):
    """A one-stage pipeline: `run()` executes it and returns (result, calls to the core so far)."""
    inp = tmp_path / "input.txt"
    inp.write_text("raw")
    out = tmp_path / "run" / "out.parquet"
    calls = []

    def produce() -> Produced:
        calls.append(1)
        return Produced(pd.DataFrame({"x_m": [1.5, 2.5, 3.5]}), {"aerosid.note": "toy"}, rows_in=3)

    def run():
        ctx = StageContext(str(tmp_path / "run" / "ledger.jsonl"), "r1", "f1")
        return execute("toy", ctx, [inp], out, {"k": 1}, Toy, produce), len(calls)

    run.out, run.ledger = out, tmp_path / "run" / "ledger.jsonl"
    return run


def tamper(path) -> None:
    """Multiply the values by 10, keeping the file's metadata (its cache key)."""
    table = pq.read_table(path)
    scaled = pyarrow.table({"x_m": pyarrow.compute.multiply(table["x_m"], 10.0)})
    pq.write_table(scaled.replace_schema_metadata(table.schema.metadata), path)


def last(path) -> dict:
    return ledger.read(path)[-1]


def test_a_verified_output_is_reused(stage):
    first, n1 = stage()
    second, n2 = stage()
    assert (first["status"], second["status"], n1, n2) == ("ok", "reused", 1, 1)
    assert first["sha256"] == second["sha256"]


def test_a_tampered_output_is_recomputed_and_the_ledger_says_why(stage):
    first, _ = stage()
    tamper(stage.out)
    assert pd.read_parquet(stage.out)["x_m"].tolist() == [15.0, 25.0, 35.0]
    again, calls = stage()
    assert again["status"] == "ok" and calls == 2
    assert pd.read_parquet(stage.out)["x_m"].tolist() == [1.5, 2.5, 3.5]  # repaired
    assert again["sha256"] == first["sha256"]
    rec = last(stage.ledger)
    assert rec["status"] == "ok"
    assert rec["reason"].startswith(f"recomputed: content of {stage.out} changed since it was recorded")
    assert stage()[0]["status"] == "reused"  # the repaired file verifies again


@pytest.mark.parametrize("rehash", [False, True])
def test_a_tampered_output_whose_hash_was_also_edited_in_the_ledger_is_recomputed(stage, rehash):
    """The attacker writes the tampered file's hash into the ledger record (and, with
    `rehash`, recomputes that record's own hash): the hash chain no longer holds there,
    so the record is not trusted and the output is computed again."""
    stage()
    stage()  # a second record (reused) follows the first
    tamper(stage.out)
    from aerosid.provenance import sha256_file

    forged = sha256_file(stage.out)
    lines = stage.ledger.read_text().splitlines()
    for k, line in enumerate(lines):
        rec = json.loads(line)
        rec["outputs"][0]["sha256"] = forged
        if rehash:
            rec["sha256"] = ledger.record_hash(rec)
        lines[k] = json.dumps(rec)
    stage.ledger.write_text("\n".join(lines) + "\n")
    again, calls = stage()
    assert again["status"] == "ok" and calls == 2
    assert pd.read_parquet(stage.out)["x_m"].tolist() == [1.5, 2.5, 3.5]
    assert "line 1" in last(stage.ledger)["reason"] and "hash chain" in last(stage.ledger)["reason"]


def test_an_output_recorded_by_an_older_unchained_ledger_is_recomputed_once(stage):
    stage()
    lines = [json.loads(x) for x in stage.ledger.read_text().splitlines()]
    for rec in lines:
        del rec["sha256"], rec["prev_sha256"]
    stage.ledger.write_text("".join(json.dumps(r) + "\n" for r in lines))
    again, calls = stage()
    assert again["status"] == "ok" and calls == 2
    assert "older aerosid" in last(stage.ledger)["reason"]
    assert stage()[0]["status"] == "reused"


def test_an_output_the_ledger_does_not_know_is_recomputed(stage):
    stage()
    stage.ledger.unlink()
    again, calls = stage()
    assert again["status"] == "ok" and calls == 2
    assert "no record" in last(stage.ledger)["reason"]


def test_the_code_version_covers_the_stage_adapters_and_schemas_not_the_flows():
    """A stage's cache key holds the code version: a change to what a task writes (tasks/) or to
    the schema that validates it (schemas/) must not be served an output written before it."""
    from pathlib import Path

    from aerosid.provenance import hashed_source_files

    root = Path(__file__).resolve().parent.parent
    rel = {p.resolve().relative_to(root).as_posix() for p in hashed_source_files()}
    assert {"tasks/stages.py", "tasks/runner.py", "schemas/telemetry.py", "aerosid/provenance.py",
            "aerosid/data/seed-rlv/vehicle.toml"} <= rel
    assert not any(r.startswith("flows/") or r.startswith("tests/") for r in rel)
