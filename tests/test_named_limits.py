"""Every limit that can refuse data is named in the message that refuses, with its
value and how to change it: the minimum segment length, the long-gap limit, the
longest time gap, the Mach window."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from aerosid.cli import main
from aerosid.preprocess import PreprocessParams, TelemetryError, preprocess, write_raw_parquet
from aerosid.preprocess.segments import plan_segments
from tests.preprocess.test_preprocess import make_flight

T = np.round(np.arange(0, 401) * 0.02, 10)  # 8 s at 50 Hz, like the Twin Otter manoeuvre 018


def test_a_window_shorter_than_the_minimum_segment_length_names_the_limit():
    plan = plan_segments(T, [], [(0, 4.5)], 5.0)
    assert plan.segments == ()
    msg = plan.refusal()
    assert "0.00..4.48 s (window 0..4.5 s): 4.48 s long, shorter than min_segment_s = 5 s" in msg
    assert "--min-segment-s" in msg and "[preprocess]" in msg
    assert [s.t_start_s for s in plan_segments(T, [], [(0, 4.5)], 4.0).segments] == [0.0]


def test_pieces_cut_short_by_long_gaps_name_the_gap_limit_too():
    plan = plan_segments(T, [(3.0, 3.4), (6.0, 6.5)], None, 5.0, max_interp_gap_s=0.2)
    assert plan.segments == () and len(plan.dropped) == 3
    msg = plan.refusal()
    assert "shorter than min_segment_s = 5 s (cut at a long gap)" in msg
    assert "max_interp_gap_s = 0.2 s" in msg and "--preprocess max_interp_gap_s=SECONDS" in msg
    assert "3.00..3.40 s" in msg
    # a window outside the record
    msg = plan_segments(T, [], [(20, 30)], 5.0).refusal()
    assert "no samples there (the record spans 0.00..8.00 s)" in msg
    # some pieces kept: the note lists the dropped one
    plan = plan_segments(np.arange(0, 1201) * 0.01, [(2.0, 2.5)], None, 5.0, 0.5)
    assert [s.segment_id for s in plan.segments] == ["seg00"] and "0.00..1.99 s" in plan.dropped_note()


def test_the_whole_method_refuses_a_short_window_with_the_named_limit():
    from aerosid.ebm import process_telemetry
    from aerosid.vehicles.vehicle import load_vehicle

    raw = make_flight(seed=71, duration_s=10.0, faults=False).raw
    with pytest.raises(ValueError, match=r"shorter than min_segment_s = 5 s.*--min-segment-s"):
        process_telemetry(raw, load_vehicle("seed-rlv"), windows=[(100.0, 104.5)])


def test_a_clock_jump_names_max_time_gap_s_and_how_to_raise_it():
    raw = make_flight(seed=72, duration_s=2.0, faults=False).raw
    raw.loc[100:, "t_s"] += 700.0
    with pytest.raises(TelemetryError, match=r"max_time_gap_s = 600 s .*--preprocess max_time_gap_s=SECONDS"):
        preprocess(raw)
    assert preprocess(raw, PreprocessParams(max_time_gap_s=800.0, nominal_rate_hz=100.0)).n_raw_rows == len(raw)


def test_the_mach_window_refusal_names_mach_half_width_and_the_option():
    from aerosid.identification.identify import identify
    from aerosid.vehicles.vehicle import load_vehicle

    fd = pd.DataFrame({"flight": "f", "t_s": np.arange(200) * 0.01, "mach": np.full(200, 0.9)})
    veh = load_vehicle("c172x")
    with pytest.raises(ValueError) as err:
        identify(fd, veh, mach_half_width=0.05)
    msg = str(err.value)
    assert "only 0 samples inside the Mach window |M - 0.1495| <= mach_half_width = 0.05" in msg
    assert "--mach-half-width" in msg and "at least 50 are needed" in msg and "span Mach 0.9..0.9" in msg


def _telemetry(tmp_path):
    path = tmp_path / "telemetry.parquet"
    write_raw_parquet(make_flight(seed=73, duration_s=8.0, rate_hz=50.0, faults=False).raw, path)
    return path


def test_cli_refuses_a_short_window_before_the_flow_starts_naming_the_limit(tmp_path):
    path = _telemetry(tmp_path)
    out = tmp_path / "run"
    res = CliRunner().invoke(main, ["run", str(path), "--vehicle", "seed-rlv", "--out", str(out),
                                    "--window", "100", "104.5"])
    assert res.exit_code == 1, res.output
    assert "shorter than min_segment_s = 5 s" in res.output and "--min-segment-s" in res.output
    assert "Traceback" not in res.output and not out.exists()


def test_cli_rejects_an_unknown_or_bad_preprocess_setting(tmp_path):
    path = _telemetry(tmp_path)
    for item, words in (("V_m_s.resolutoin=1", "unknown sensor setting"), ("false_alarm=2", "must be in (0, 1]"),
                        ("max_interp_gap_s", "KEY=VALUE")):
        res = CliRunner().invoke(main, ["run", str(path), "--out", str(tmp_path / "r"), "--preprocess", item])
        assert res.exit_code == 2 and words in res.output and "--preprocess" in res.output, res.output
