"""`aerosid simulate --input`: a designed input is flown where the case's plan goes; bad files are refused."""
from dataclasses import replace

import numpy as np
import pandas as pd
from click.testing import CliRunner

from aerosid.cli import main
from aerosid.design.io import as_case_inputs, read_input


def test_the_pitch_command_enters_the_fins_where_the_plan_would(tmp_path):
    from aerosid.simulation import load_case, simulate

    case = load_case("seed-rlv", duration_s=2.0)
    case = replace(case, faults=case.faults.without_faults())
    t = np.arange(0, 2.0001, 0.01)
    u = np.where(t >= 1.0, 0.1, 0.0)
    path = tmp_path / "in.csv"
    pd.DataFrame({"t_s": t, "delta_p_cmd_rad": u}).to_csv(path, index=False)
    flown = simulate(replace(case, inputs=as_case_inputs(read_input(path))), (), seed=0).truth
    plain = simulate(case, (), seed=0).truth
    k = 100  # the sample of the step: the state is still the same, the command is not
    d = flown["delta_p_rad"].to_numpy() - plain["delta_p_rad"].to_numpy()
    assert np.allclose(d[:k], 0.0, atol=1e-12)
    assert abs(d[k] - 0.1) < 1e-9
    # afterwards the rate-damping autopilot takes some of it back
    assert flown["q_rad_s"].iloc[-1] != plain["q_rad_s"].iloc[-1]


def test_simulate_refuses_an_input_with_unknown_columns_or_bad_rows(tmp_path):
    bad = tmp_path / "bad.csv"
    pd.DataFrame({"t_s": [0.0, 0.01], "elevator_cmd_rad": [0.0, 0.1]}).to_csv(bad, index=False)
    r = CliRunner().invoke(main, ["simulate", "--input", str(bad), "--out", str(tmp_path / "o")])
    assert r.exit_code != 0 and "elevator_cmd_rad" in r.output and "delta_p_cmd_rad" in r.output
    assert "Traceback" not in r.output
    bad2 = tmp_path / "bad2.csv"
    pd.DataFrame({"t_s": [0.0, 0.02, 0.01], "delta_p_cmd_rad": [0.0, 0.1, np.nan]}).to_csv(bad2, index=False)
    r = CliRunner().invoke(main, ["simulate", "--input", str(bad2), "--out", str(tmp_path / "o")])
    assert r.exit_code != 0 and "bad2.csv" in r.output and "rows 2" in r.output


def test_jsbsim_flies_the_elevator_command_in_radians_through_the_aircraft_scaling():
    import pytest

    pytest.importorskip("jsbsim")
    from aerosid.simulation.jsbsim_flight import simulate_jsbsim

    t = np.arange(0, 3.0001, 0.01)
    table = pd.DataFrame({"t_s": t, "elevator_cmd_rad": np.where(t >= 1.0, 0.1, 0.0)})
    truth = simulate_jsbsim("c172x", "3211", seed=0, faults=False, input_table=table).truth
    assert len(truth) == t.size
    d = truth["d1_rad"].to_numpy()
    # c172x's elevator actuator: hysteresis 0.05 rad wide, so a 0.1 rad command step from trim
    # moves the surface by 0.1 - 0.025 (lag 60/s: settled well within the 2 s)
    assert abs((d[-1] - d[50]) - 0.075) < 2e-3
