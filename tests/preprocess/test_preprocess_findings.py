"""Timestamps off the grid are a finding of the run (PreprocessResult.findings), not only a flag count."""
import json

import numpy as np
import pytest

from aerosid.preprocess import preprocess
from aerosid.preprocess.flags import QualityFlag
from aerosid.preprocess.result import JITTER_MIN_ROWS
from tests.preprocess.test_preprocess import make_flight


def _shifted(rows: slice, steps: float, seed: int = 5):
    """A clean 100 Hz flight whose rows `rows` carry timestamps `steps` sample steps late."""
    fl = make_flight(seed=seed, duration_s=20.0, faults=False)
    raw = fl.raw.copy()
    t = raw["t_s"].to_numpy().copy()
    t[rows] += steps / 100.0
    raw["t_s"] = t
    return raw


def test_a_run_of_timestamps_off_the_grid_is_one_finding_with_its_span():
    raw = _shifted(slice(800, 840), 0.4)  # 0.4 step late: beyond snap_tolerance (0.25)
    res = preprocess(raw)
    (f,) = res.findings  # 0.4 s: interpolated across (max_interp_gap_s 0.5 s), so not cut
    assert (f.kind, f.segment, f.channel, f.n_samples, f.cut) == ("time_jitter", "preprocess", "t_s", 40, False)
    t = res.frame["t_s"].to_numpy()
    assert np.isclose(f.t0_s, t[800], atol=0.006) and np.isclose(f.t1_s, t[839], atol=0.006)
    assert "snap_tolerance" in f.detail
    stored = json.loads(res.metadata()["aerosid.findings"])  # what the flow reads back from the Parquet file
    assert stored == [f.as_dict()]


def test_a_span_longer_than_the_interpolation_limit_is_cut():
    (f,) = preprocess(_shifted(slice(800, 880), 0.4)).findings
    assert (f.kind, f.n_samples, f.cut) == ("time_jitter", 80, True)


def test_a_stuck_sensor_and_sentinel_values_are_findings_of_their_channel():
    raw = make_flight(seed=6, duration_s=20.0, faults=False).raw.copy()
    q = raw["q_rad_s"].to_numpy().copy()
    q[500:600] = q[500]  # stuck for 1 s
    raw["q_rad_s"] = q
    v = raw["V_m_s"].to_numpy().copy()
    v[1200:1220] = -9999.0  # 0.2 s of sentinels
    raw["V_m_s"] = v
    found = {(f.kind, f.channel): f for f in preprocess(raw).findings}
    assert set(found) == {("frozen", "q_rad_s"), ("sentinel", "V_m_s")}
    frozen, sentinel = found["frozen", "q_rad_s"], found["sentinel", "V_m_s"]
    assert frozen.n_samples >= 90 and frozen.cut  # 1 s > max_interp_gap_s: left empty
    t = raw["t_s"].to_numpy()
    assert abs(frozen.t0_s - t[500]) <= 0.1 and abs(frozen.t1_s - t[599]) <= 0.1
    assert sentinel.n_samples == 20 and not sentinel.cut and "sentinel" in sentinel.detail


def test_a_few_stray_timestamps_and_jitter_inside_the_tolerance_are_not_findings():
    assert preprocess(_shifted(slice(800, 800 + JITTER_MIN_ROWS - 1), 0.4)).findings == []
    assert preprocess(_shifted(slice(800, 840), 0.2)).findings == []  # snapped to the grid, not flagged


def test_the_preprocess_stage_hands_the_finding_on_computed_and_reused(tmp_path):
    """The flow reads the stage's findings (flows.steps: a run with findings is not "ok")."""
    from tasks.runner import StageContext
    from tasks.stages import preprocess_task

    raw_path = tmp_path / "telemetry.parquet"
    _shifted(slice(800, 840), 0.4).to_parquet(raw_path, index=False)
    run_dir = tmp_path / "run"
    ctx = StageContext(str(run_dir / "ledger.jsonl"), "local", "f")
    first = preprocess_task.fn(str(raw_path), str(run_dir), ctx, {})
    again = preprocess_task.fn(str(raw_path), str(run_dir), ctx, {})  # the output reused
    assert [f["kind"] for f in first["findings"]] == ["time_jitter"] and first["findings"][0]["n_samples"] == 40
    assert again["status"] == "reused" and again["findings"] == first["findings"]


def _thinned_after_dropouts(seed: int = 9):
    """A clean 100 Hz flight with two dropouts of an odd number of rows (7 and 5), then every
    other row kept: the 50 Hz record's sample phase moves by half a step at the first dropout
    and back at the second (telemetry thinned after dropouts)."""
    fl = make_flight(seed=seed, duration_s=20.0, faults=False, jitter=0.0)
    keep = np.ones(len(fl.raw), bool)
    keep[600:607] = False
    keep[1400:1405] = False
    return fl, fl.raw[keep].iloc[::2].reset_index(drop=True)


def test_a_sample_phase_that_moves_at_a_dropout_is_re_timed_and_kept():
    fl, raw = _thinned_after_dropouts()
    res = preprocess(raw)
    assert res.nominal_rate_hz == pytest.approx(50.0, rel=1e-3)
    fr = res.frame
    assert int(((fr["flags"].to_numpy() & int(QualityFlag.TIME_JITTER)) != 0).sum()) == 0  # nothing lost as jitter
    (f,) = [f for f in res.findings if f.kind == "phase_shift"]
    assert not f.cut and f.channel == "t_s" and "re-timed" in f.detail
    (r,) = res.retimed
    t_raw = fr["t_raw_s"].to_numpy()
    moved = np.isfinite(t_raw) & (np.abs(fr["t_s"].to_numpy() - t_raw) > 0.004)
    # the rows between the two dropouts, moved by half a step (10 ms) and no more
    assert r[2] == int(moved.sum()) == f.n_samples > 300
    assert abs(abs(r[3]) - 0.01) < 1e-9 and np.max(np.abs(fr["t_s"] - fr["t_raw_s"])) <= 0.01 + 1e-9
    assert fl.t_nominal[607] - 0.011 <= f.t0_s <= fl.t_nominal[607] + 0.011
    assert res.n_used_rows == res.n_raw_rows  # every row recorded is used


def test_the_re_timed_rows_keep_their_values_in_order():
    _, raw = _thinned_after_dropouts()
    fr = preprocess(raw).frame
    got = fr.loc[np.isfinite(fr["t_raw_s"]), ["t_raw_s", "q_rad_s"]].to_numpy()
    assert np.array_equal(got[:, 0], raw["t_s"].to_numpy()) and np.array_equal(got[:, 1], raw["q_rad_s"].to_numpy())


def test_a_record_thinned_to_10_hz_after_dropouts_keeps_its_rate():
    """Dropouts of 2 and 5 rows, then every 10th row kept: the 10 Hz record's phase moves by
    0.2 and 0.5 of a step, in intervals of 1.2 and 1.5 steps. Counted as whole steps they read
    as 9.97 Hz and the rows drifted off the grid (the schema refused the preprocessed frame)."""
    fl = make_flight(seed=9, duration_s=40.0, faults=False, jitter=0.0)
    keep = np.ones(len(fl.raw), bool)
    keep[1200:1202] = False
    keep[2800:2805] = False
    raw = fl.raw[keep].iloc[::10].reset_index(drop=True)
    res = preprocess(raw)
    assert res.nominal_rate_hz == pytest.approx(10.0, rel=1e-9)
    assert res.n_used_rows == res.n_raw_rows
