"""The orchestrated pipeline: same numbers as the core, idempotent inbox, failed-segment
retry, Dask campaign, audit trail.  Prefect runs hermetically (tests/conftest.py)."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from aerosid.ebm import process_telemetry
from aerosid.simulation import load_case, simulate
from aerosid.vehicles.vehicle import load_vehicle
from tasks import ledger

pytestmark = pytest.mark.prefect

COLS = ["channel", "coefficient", "estimate", "std_error", "std_error_ols", "ci_low", "ci_high"]


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    """Three short simulated flights written as telemetry files."""
    root = tmp_path_factory.mktemp("flights")
    case = load_case("seed-rlv", duration_s=40.0)
    paths = []
    for seed in (11, 12, 13):
        d = root / f"f{seed}"
        simulate(case, seed=seed).write(d)
        paths.append(d / "telemetry.parquet")
    return paths


def records(path, **match):
    return [r for r in ledger.read(path) if all(r.get(k) == v for k, v in match.items())]


def test_flow_gives_the_same_coefficients_as_the_core(prefect_harness, flights, tmp_path):
    from flows.pipeline import process_flight

    summary = process_flight(str(flights[0]), str(tmp_path / "run"))
    assert summary["status"] in ("ok", "ok with findings") and len(summary["segments"]) == 2
    flow_table = pd.read_parquet(tmp_path / "run" / "coefficients.parquet")
    core = process_telemetry(pd.read_parquet(flights[0]), load_vehicle("seed-rlv"), flight=summary["flight"])
    pd.testing.assert_frame_equal(flow_table[COLS], core.identification.table()[COLS], check_exact=True)
    # every stage wrote one ok record; the audit trail leads back to the telemetry
    led = tmp_path / "run" / "ledger.jsonl"
    assert {r["stage"] for r in records(led, status="ok")} == {"preprocess", "smooth", "flight_data", "regression",
                                                             "report"}
    from aerosid.cli import main

    out = CliRunner().invoke(main, ["audit", str(tmp_path / "run" / "coefficients.parquet")])
    assert out.exit_code == 0, out.output
    for stage in ("regression", "flight_data", "smooth", "preprocess"):
        assert f"stage {stage}" in out.output
    assert str(flights[0]) in out.output
    # the same inputs and code again: every stage reuses its output, nothing is recomputed
    # (the report, which reads the model history, is written again)
    n = len(ledger.read(led))
    process_flight(str(flights[0]), str(tmp_path / "run"))
    again = [r for r in ledger.read(led)[n:] if r["stage"] != "report"]
    assert [r["status"] for r in again] == ["reused"] * 5


def test_inbox_processes_new_and_changed_files_only(prefect_harness, flights, tmp_path):
    from flows.pipeline import reprocess_inbox

    inbox, out = tmp_path / "inbox", tmp_path / "out"
    inbox.mkdir()
    for p in flights[:2]:
        shutil.copy(p, inbox / f"{p.parent.name}.parquet")
    first = reprocess_inbox(str(inbox), str(out), settle_s=0.05)
    assert sorted(first["processed"]) == ["f11", "f12"]
    second = reprocess_inbox(str(inbox), str(out), settle_s=0.05)
    assert second["processed"] == [] and sorted(second["unchanged"]) == ["f11", "f12"]
    n_stage_records = len([r for r in ledger.read(out / "ledger.jsonl") if r["stage"] != "inbox"])
    shutil.copy(flights[2], inbox / "f12.parquet")  # new content under an old name
    third = reprocess_inbox(str(inbox), str(out), settle_s=0.05)
    assert third["processed"] == ["f12"] and third["unchanged"] == ["f11"]
    new = [r for r in ledger.read(out / "ledger.jsonl") if r["stage"] != "inbox"][n_stage_records:]
    assert {r["flight"] for r in new} == {"f12"}
    assert any(r["stage"] == "preprocess" and r["status"] == "ok" for r in new)


def test_a_failed_segment_is_recorded_and_retry_failed_completes_only_it(prefect_harness, flights, tmp_path,
                                                                        monkeypatch):
    import tasks.stages
    from flows.pipeline import process_flight, retry_failed

    real = tasks.stages.smooth_segment_frame

    def broken(rows, vehicle, options, segment_id):
        if segment_id == "seg01":
            raise FloatingPointError("injected: covariance not positive definite")
        return real(rows, vehicle, options, segment_id)

    monkeypatch.setattr(tasks.stages, "smooth_segment_frame", broken)
    out = tmp_path / "root"
    summary = process_flight(str(flights[1]), str(out / "f12"))
    assert summary["status"] == "partial"
    assert [f["segment"] for f in summary["segments_failed"]] == ["seg01"]
    led = out / "f12" / "ledger.jsonl"
    failed = records(led, stage="smooth", status="failed")
    assert [r["segment"] for r in failed] == ["seg01"] and "injected" in failed[0]["error"]
    assert (out / "f12" / "coefficients.parquet").exists()  # the flight went on with seg00

    monkeypatch.setattr(tasks.stages, "smooth_segment_frame", real)  # the cause is removed
    n_before = len(ledger.read(led))
    result = retry_failed(str(out))
    assert result["retried"] == ["f12"]
    smooth_after = [r for r in ledger.read(led)[n_before:] if r["stage"] == "smooth"]
    assert {(r["segment"], r["status"]) for r in smooth_after} == {("seg00", "reused"), ("seg01", "ok")}
    assert json.loads((out / "f12" / "run.json").read_text())["status"] in ("ok", "ok with findings")
    assert retry_failed(str(out))["retried"] == []  # nothing left to retry


def test_campaign_on_dask_equals_the_core(prefect_harness, flights, tmp_path):
    from flows.pipeline import campaign_runner

    two = [str(p) for p in flights[:2]]  # one flight per Dask worker (CI time: the third added ~20 s)
    parallel = campaign_runner(n_workers=2)(two, str(tmp_path / "dask"))
    assert all(s["status"] in ("ok", "ok with findings") for s in parallel)
    # the serial flow equals the core (test_flow_gives_the_same_coefficients_as_the_core), so the
    # core stands in for the serial campaign here (CI time: the serial campaign took ~40 s)
    for path, b in zip(two, parallel):
        ta = process_telemetry(pd.read_parquet(path), load_vehicle("seed-rlv"), flight=b["flight"])
        ta = ta.identification.table()[COLS]
        tb = pd.read_parquet(b["coefficients"]["path"])[COLS]
        pd.testing.assert_frame_equal(ta, tb, check_exact=True)
    assert np.isfinite(tb["estimate"]).any()


def test_the_prefect_artifact_lists_segments_and_findings_named_with_their_manoeuvre():
    import pandas as pd

    from flows.steps import artifact_markdown

    table = pd.DataFrame({"channel": ["Cm"], "coefficient": ["Cm_alpha"], "estimate": [-0.25], "std_error": [0.01],
                          "std_error_ols": [0.001], "ci_low": [-0.27], "ci_high": [-0.23], "reference": [-0.38]})
    jitter = {"kind": "time_jitter", "segment": "preprocess", "channel": "t_s", "t0_s": 12.0, "t1_s": 12.8,
              "n_samples": 80, "cut": True, "detail": "off the grid | check the clock"}
    edge = {"kind": "database_edge", "segment": "m2 seg01", "channel": "", "t0_s": 40.0, "t1_s": 41.5,
            "n_samples": 150, "cut": True, "detail": "alpha at the table's edge"}
    pooled = {"status": "ok with findings", "findings": [edge],
              "flights": [{"flight": "m1", "segments": ["seg00"], "segments_ok": [{"segment": "seg00"}],
                           "findings": [jitter]},
                          {"flight": "m2", "segments": ["seg00", "seg01"], "segments_ok": [{"segment": "seg00"}],
                           "findings": []}]}
    md = artifact_markdown("pool", table, pooled)
    assert "| m1/seg00 | ok |" in md and "| m2/seg01 | failed |" in md
    assert "## Findings (status: ok with findings)" in md
    assert "| m1/preprocess | time_jitter | t_s | 12.00–12.80 | 80 | cut | off the grid \\| check the clock |" in md
    assert "| m2 seg01 | database_edge |" in md
    single = {"status": "ok", "segments": ["seg00"], "segments_ok": [{"segment": "seg00"}], "findings": []}
    assert "## Findings" not in artifact_markdown("f", table, single)
