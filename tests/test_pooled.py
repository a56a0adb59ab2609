"""Several manoeuvres, one model (issue 17): `aerosid run A B --out RUN` preprocesses and
smooths each telemetry file on its own and fits one regression on their pooled flight
data; the ledger traces the coefficients back to every input."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from aerosid.ebm import process_manoeuvres, process_telemetry
from aerosid.io import write_parquet_atomic
from aerosid.simulation import load_case, simulate
from aerosid.vehicles.vehicle import load_vehicle
from tasks import ledger

COLS = ["channel", "coefficient", "estimate", "std_error", "std_error_ols", "ci_low", "ci_high"]


def us1976_density(h: np.ndarray) -> np.ndarray:
    from aerosid.vehicles.atmosphere import density_kg_m3

    ok = np.isfinite(h) & (h > -5000) & (h < 81000)
    return np.where(ok, density_kg_m3(np.where(ok, h, 0.0)), np.nan)


@pytest.fixture(scope="module")
def manoeuvres(tmp_path_factory):
    """Two 30 s seed-rlv flights (seeds 1, 2) as telemetry files naming their vehicle; the
    second carries a measured density column (the standard day's, so the physics agree)."""
    root = tmp_path_factory.mktemp("manoeuvres")
    case = load_case("seed-rlv", duration_s=30.0)
    paths = {}
    for fid, seed in (("m1", 1), ("m2", 2)):
        flight = simulate(case, seed=seed)
        flight.write(root / fid)
        paths[fid] = root / fid / "telemetry.parquet"
    raw = pd.read_parquet(paths["m2"])
    raw["rho_kg_m3"] = us1976_density(raw["h_m"].to_numpy())
    write_parquet_atomic(raw, paths["m2"], metadata={"aerosid.case": "seed-rlv"})
    return paths


@pytest.fixture(scope="module")
def in_memory(manoeuvres):
    vehicle = load_vehicle("seed-rlv")
    raws = {fid: pd.read_parquet(p) for fid, p in manoeuvres.items()}
    singles = {fid: process_telemetry(raw, vehicle, flight=fid) for fid, raw in raws.items()}
    return singles, process_manoeuvres(raws, vehicle)


def test_pooled_regression_is_over_the_union_of_the_manoeuvres(in_memory):
    singles, pooled = in_memory
    n = {fid: s.identification.n_samples for fid, s in singles.items()}
    assert pooled.identification.n_samples == sum(n.values()) > 2000
    for channel, fit in pooled.identification.fits.items():
        assert fit.n_obs == sum(s.identification.fits[channel].n_obs for s in singles.values()), channel
    # each manoeuvre was preprocessed and smoothed on its own: its rows of the pooled flight
    # data are its single-flight rows, bit for bit
    for fid, single in singles.items():
        part = pooled.flight_data[pooled.flight_data["flight"] == fid].reset_index(drop=True)
        pd.testing.assert_frame_equal(part, single.flight_data, check_exact=True)


def test_pooled_coefficients_lie_between_or_near_the_single_flight_ones(in_memory):
    """The pooled estimate combines both manoeuvres' information: within 2 sigma (pooled)
    of the span of the two single-flight estimates (measured: all 16 strictly between), and
    its sigma below the worse manoeuvre's (measured: ~1/sqrt(2) of the single ones)."""
    singles, pooled = in_memory
    table = pooled.identification.table().set_index("coefficient")
    per = [s.identification.table().set_index("coefficient") for s in singles.values()]
    checked = 0
    for name, row in table.iterrows():
        if not row["identifiable"]:
            continue
        lo = min(t.loc[name, "estimate"] for t in per)
        hi = max(t.loc[name, "estimate"] for t in per)
        assert lo - 2 * row["std_error"] <= row["estimate"] <= hi + 2 * row["std_error"], (name, lo, hi, row)
        # (the errors-in-variables correction's own error, in sigma, does not shrink with pooling as
        # the fit's does: up to 1.2x the worse manoeuvre's measured on Cn_beta)
        assert row["std_error"] < 1.25 * max(t.loc[name, "std_error"] for t in per), name
        checked += 1
    assert checked >= 10  # C_N, C_Y are identities of the inversion for seed-rlv (no number)


def test_cli_pools_the_files_like_the_core_and_records_every_input(prefect_harness, manoeuvres, in_memory, tmp_path):
    from aerosid.cli import main

    _, pooled = in_memory
    out = tmp_path / "run"
    res = CliRunner().invoke(main, ["run", str(manoeuvres["m1"]), str(manoeuvres["m2"]), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "pooled 2 manoeuvres" in res.output
    flow_table = pd.read_parquet(out / "coefficients.parquet")
    pd.testing.assert_frame_equal(flow_table[COLS], pooled.identification.table()[COLS], check_exact=True)
    state = json.loads((out / "run.json").read_text())
    assert state["status"] in ("ok", "ok with findings") and [f["flight"] for f in state["flights"]] == ["m1", "m2"]
    assert state["telemetry"] == [str(manoeuvres["m1"]), str(manoeuvres["m2"])]
    # the air data's source, per manoeuvre: m2 brought its density
    assert state["air_data"]["m1"]["rho_kg_m3"].startswith("US-1976")
    assert state["air_data"]["m2"]["rho_kg_m3"] == "measured: rho_kg_m3"
    for fid in ("m1", "m2"):
        sub = json.loads((out / "flights" / fid / "run.json").read_text())
        assert sub["pooled_into"] == str(out) and sub["status"] in ("ok", "ok with findings")
        assert not (out / "flights" / fid / "coefficients.parquet").exists()  # one regression only
    # lineage: the pooled flight data reads both preprocessed files; they read the two telemetry files
    recs = ledger.read(out / "ledger.jsonl")
    fd = next(r for r in recs if r["stage"] == "flight_data" and r["status"] == "ok")
    assert {Path(i["path"]).parent.name for i in fd["inputs"] if i["path"].endswith("preprocessed.parquet")} == {
        "m1", "m2"}
    raws = {i["path"] for r in recs if r["stage"] == "preprocess" for i in r["inputs"]}
    assert raws == {str(manoeuvres["m1"]), str(manoeuvres["m2"])}
    audit = CliRunner().invoke(main, ["audit", str(out / "coefficients.parquet")])
    assert audit.exit_code == 0 and str(manoeuvres["m1"]) in audit.output and str(manoeuvres["m2"]) in audit.output
    html = (out / "report.html").read_text()
    assert "Manoeuvre m1" in html and "Manoeuvre m2" in html and "measured: rho_kg_m3" in html


def test_a_failed_segment_leaves_the_pool_partial_and_retry_reruns_the_pool(prefect_harness, manoeuvres,
                                                                          in_memory, tmp_path, monkeypatch):
    """m2's second segment fails: the pool is fitted without it (partial); retry_failed
    re-runs the pooled identification (not a one-flight run in flights/m2/), reusing
    everything else, and the pooled result then equals the full one."""
    import tasks.stages
    from flows.pipeline import process_manoeuvres as flow, retry_failed
    from tasks.runner import StageFailed

    _, pooled = in_memory
    real = tasks.stages.smooth_segment_frame
    broken = {"on": True}

    def flaky(rows, vehicle, options, segment_id):
        if broken["on"] and segment_id == "seg01" and float(rows["t_s"].iloc[0]) > 10 and "rho_kg_m3" in rows:
            raise StageFailed("injected failure")
        return real(rows, vehicle, options, segment_id)

    monkeypatch.setattr(tasks.stages, "smooth_segment_frame", flaky)
    out = tmp_path / "pool"
    first = flow([str(manoeuvres["m1"]), str(manoeuvres["m2"])], str(out))
    assert first["status"] == "partial"
    assert [f["status"].replace(" with findings", "") for f in first["flights"]] == ["ok", "partial"]
    fd = pd.read_parquet(out / "flight_data.parquet")
    assert set(fd.loc[fd["flight"] == "m2", "segment"]) == {"seg00"}
    broken["on"] = False
    again = retry_failed(str(out))
    assert again["errors"] == {} and again["retried"] == ["pool"]
    assert again["results"][0]["status"] in ("ok", "ok with findings")
    assert not (out / "flights" / "m2" / "coefficients.parquet").exists()
    pd.testing.assert_frame_equal(pd.read_parquet(out / "coefficients.parquet")[COLS],
                                  pooled.identification.table()[COLS], check_exact=True)
    recs = ledger.read(out / "ledger.jsonl")
    smooth = [r for r in recs if r["stage"] == "smooth" and r["run_id"] == recs[-1]["run_id"]]
    assert sorted((r["flight"], r["segment"], r["status"]) for r in smooth) == [
        ("m1", "seg00", "reused"), ("m1", "seg01", "reused"), ("m2", "seg00", "reused"), ("m2", "seg01", "ok")]


def test_a_manoeuvres_findings_reach_the_pools_status_output_and_report(prefect_harness, manoeuvres, tmp_path):
    """One manoeuvre with 0.8 s of timestamps off the grid: its run.json entry carries the
    time_jitter finding, the pool says "ok with findings", the CLI lists it and the report's run
    section names it with its manoeuvre, once."""
    from aerosid.cli import main

    raw = pd.read_parquet(manoeuvres["m1"])
    t = raw["t_s"].to_numpy().copy()
    t[(t > 12.0) & (t < 12.8)] += 0.004  # 0.4 sample step late
    raw["t_s"] = t
    jittered = tmp_path / "mj" / "telemetry.parquet"
    jittered.parent.mkdir()
    write_parquet_atomic(raw, jittered, metadata={"aerosid.case": "seed-rlv"})
    out = tmp_path / "run"
    res = CliRunner().invoke(main, ["run", str(jittered), str(manoeuvres["m2"]), "--out", str(out)])
    assert res.exit_code == 0, res.output
    state = json.loads((out / "run.json").read_text())
    kinds = {fs["flight"]: [f["kind"] for f in fs["findings"]] for fs in state["flights"]}
    assert "time_jitter" in kinds["mj"] and "time_jitter" not in kinds["m2"]
    assert state["status"] == "ok with findings" and state["flights"][0]["status"] == "ok with findings"
    assert "mj: preprocess t_s: time_jitter at t = 12." in res.output
    html = (out / "report.html").read_text()
    table = html[html.index('<table id="run-findings"'):]
    table = table[:table.index("</table>")]
    assert table.count("<td>time_jitter</td>") == 1 and "<td>mj preprocess</td>" in table
    # the pool's own findings (its flight data's) are stored with the flight data and handed on
    import pyarrow.parquet as pq

    stored = json.loads((pq.read_schema(out / "flight_data.parquet").metadata or {}).get(b"aerosid.findings", b"[]"))
    assert stored == state.get("findings", [])
