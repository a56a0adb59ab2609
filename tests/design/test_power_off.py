"""A designed input's throttle_cmd_norm: the c172x flight is trimmed and flown as a glide at that
fixed throttle (0 = idle, power-off); bad throttle columns are refused naming file and column."""
import math

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from aerosid.cli import main
from aerosid.design.io import InputFileError, read_input
from aerosid.design.power import power_hint


def _idle_flight(throttle, duration_s=4.0):
    pytest.importorskip("jsbsim")
    from aerosid.simulation.jsbsim_flight import simulate_jsbsim

    t = np.arange(0, duration_s + 1e-9, 0.01)
    table = pd.DataFrame({"t_s": t, "elevator_cmd_rad": np.zeros_like(t)})
    if throttle is not None:
        table["throttle_cmd_norm"] = throttle
    return simulate_jsbsim("c172x", "3211", seed=0, faults=False, input_table=table)


def test_idle_throttle_is_honoured_and_the_trim_is_a_steady_glide():
    f = _idle_flight(0.0)
    powered = _idle_flight(None)
    tr, T = f.info["trim"], f.truth
    assert tr["throttle_cmd_norm"] == 0.0 and "fixed throttle 0" in tr["power"]
    assert powered.info["trim"]["throttle_cmd_norm"] > 0.1  # JSBSim's own trim holds the speed with the throttle
    # idle: the windmilling propeller drags, and more than at the powered trim; the glide is steeper
    assert T["thrust_N"].max() < 0.0 and T["thrust_N"].mean() < powered.truth["thrust_N"].mean() - 50.0
    assert tr["gamma_deg"] < powered.info["trim"]["gamma_deg"] - 0.3
    # steady: no pitch rate, speed and alpha hold, and the height falls at V sin(gamma)
    assert np.max(np.abs(T["q_rad_s"])) < 2e-3
    assert np.ptp(T["V_m_s"]) < 0.1 and np.ptp(T["alpha_rad"]) < math.radians(0.1)
    sink = -np.polyfit(T["t_s"], T["h_m"], 1)[0]
    assert sink == pytest.approx(-tr["V_m_s"] * math.sin(math.radians(tr["gamma_deg"])), rel=0.02)


@pytest.mark.parametrize("values, words", [
    ([0.0, 1.5, 0.0], ["column throttle_cmd_norm", "outside 0..1", "rows 1"]),
    ([0.0, 0.0, 0.3], ["column throttle_cmd_norm", "must be constant", "rows 2"]),
])
def test_a_bad_throttle_column_is_refused_naming_file_column_and_rows(tmp_path, values, words):
    path = tmp_path / "des.csv"
    pd.DataFrame({"t_s": [0.0, 0.01, 0.02], "elevator_cmd_rad": 0.0, "throttle_cmd_norm": values}).to_csv(path,
                                                                                                       index=False)
    with pytest.raises(InputFileError) as err:
        read_input(path)
    assert str(path) in str(err.value) and all(w in str(err.value) for w in words)
    r = CliRunner().invoke(main, ["simulate", "--jsbsim", "c172x", "--input", str(path), "--out", str(tmp_path / "o")])
    assert r.exit_code != 0 and "des.csv" in r.output and "throttle_cmd_norm" in r.output
    assert "Traceback" not in r.output


def test_the_throttle_is_a_jsbsim_column_only(tmp_path):
    path = tmp_path / "rlv.csv"
    pd.DataFrame({"t_s": [0.0, 0.01], "delta_p_cmd_rad": 0.0, "throttle_cmd_norm": 0.0}).to_csv(path, index=False)
    r = CliRunner().invoke(main, ["simulate", "--input", str(path), "--out", str(tmp_path / "o")])
    assert r.exit_code != 0 and "throttle_cmd_norm" in r.output and "rlv.csv" in r.output


def test_the_design_proposes_power_off_only_when_the_model_error_stops_the_separation():
    class Jsb:
        throttle = None

    # noise small enough, model error too large: propose it
    hint = power_hint({"Cm_q": 9.7, "Cm_alpha_dot": 2.4}, {"Cm_q": 1.0, "Cm_alpha_dot": 2.0}, "trim", Jsb())
    assert "--power idle" in hint and "Cm_q +9.7 %" in hint and "Cm_alpha_dot" not in hint
    # already power-off, or the noise is what fails, or no throttle to set: no proposal
    assert power_hint({"Cm_q": 9.7}, {"Cm_q": 1.0}, "idle", Jsb()) == ""
    assert power_hint({"Cm_q": 3.0}, {"Cm_q": 6.0}, "trim", Jsb()) == ""
    # the powered c172x design: Cm_q's model error dominates although Cm_alpha_dot's 2 sigma is 16 %
    hint = power_hint({"Cm_q": 9.7, "Cm_alpha_dot": 2.4}, {"Cm_q": 0.8, "Cm_alpha_dot": 7.9}, "trim", Jsb())
    assert "Cm_q +9.7 %" in hint and "Cm_alpha_dot" not in hint
    assert power_hint({"Cm_q": 9.7}, {"Cm_q": 1.0}, "trim", object()) == ""
    assert power_hint({"Cm_q": 3.0}, {"Cm_q": 1.0}, "trim", Jsb()) == ""
