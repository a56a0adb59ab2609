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
