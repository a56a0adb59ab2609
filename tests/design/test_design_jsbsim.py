"""aerosid design on a JSBSim aircraft aerosid generates (not only c172x): the candidate shapes
and the lateral doublets are sized from the aircraft's own flight design, and a limit the flight
already uses without the designed input (the doublets against an assumed rate limit) does not
shrink the designed input."""
from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("jsbsim")

from click.testing import CliRunner  # noqa: E402

from aerosid.cli import main  # noqa: E402
from aerosid.design.core import DesignError  # noqa: E402
from aerosid.design.flyers import C172X_INPUT_SIZES, jsbsim_input_sizes, lateral_doublets  # noqa: E402
from aerosid.design.io import read_input  # noqa: E402
from aerosid.simulation.jsbsim_design import flight_design  # noqa: E402
from aerosid.simulation.jsbsim_flight import _import_jsbsim  # noqa: E402


def test_input_sizes_come_from_the_aircrafts_flight_design():
    assert jsbsim_input_sizes("c172x") == C172X_INPUT_SIZES
    d = flight_design(_import_jsbsim(), "pa28")
    sizes = jsbsim_input_sizes("pa28")
    # the steps pa28's own flight commands (after the travel limit and the command's rounding)
    assert sizes["elevator_rad"] == pytest.approx(abs(d.manoeuvre["elevator_amplitudes_norm"][0] * d.gains["pitch"]))
    assert sizes["elevator_rad"] == pytest.approx(abs(d.manoeuvre["surface_steps_rad"]["elevator"]), rel=0.05)
    assert sizes["half_s"] == pytest.approx(d.manoeuvre["aileron_half_s"])
    with pytest.raises(DesignError, match="f16"):  # closed-loop pitch: JSBSim's reason is passed on
        jsbsim_input_sizes("f16")
    # c172x's doublets are what they were: aileron 1 s after the elevator input, rudder 7 s later
    t = np.arange(0, 40.0, 0.01)
    lat = lateral_doublets(t, 20.0)
    assert t[np.argmax(lat["aileron_cmd_rad"].to_numpy() > 1e-9)] == pytest.approx(21.0, abs=0.02)
    assert t[np.argmax(lat["rudder_cmd_rad"].to_numpy() > 1e-9)] == pytest.approx(28.0, abs=0.02)
    assert lat["aileron_cmd_rad"].max() == pytest.approx(0.04)


def test_design_on_a_generated_aircraft(tmp_path):
    runner = CliRunner()
    sim = runner.invoke(main, ["simulate", "--jsbsim", "pa28", "--out", str(tmp_path / "f")])
    assert sim.exit_code == 0, sim.output
    run = runner.invoke(main, ["run", str(tmp_path / "f" / "telemetry.parquet"), "--vehicle",
                               str(tmp_path / "f" / "vehicle.toml"), "--out", str(tmp_path / "run")])
    assert run.exit_code == 0, run.output
    res = runner.invoke(main, ["design", str(tmp_path / "run"), "--effect", "Cm_alpha_dot", "--size", "-3",
                               "--no-refine", "--quiet", "--out", str(tmp_path / "d")])
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "d" / "design.json").read_text())
    table = read_input(tmp_path / "d" / "input.parquet")
    assert {"elevator_cmd_rad", "aileron_cmd_rad", "rudder_cmd_rad"} <= set(table.columns)
    sizes = jsbsim_input_sizes("pa28")
    assert np.max(np.abs(table["aileron_cmd_rad"])) == pytest.approx(sizes["aileron_rad"], rel=1e-6)
    use = doc["limit_use"]
    assert use["surface"] <= 1.0 and use["alpha"] <= 1.0 and use["load_factor"] <= 1.0
    # the doublets break the assumed 1 rad/s rate without any designed input; the design says so
    # and keeps its amplitude (before: backed off four times to 0.035 rad)
    assert use["surface_rate"] > 1.0 and "already uses the surface rate" in res.output
    assert doc["manoeuvre"]["amplitude_rad"] > 0.1
    before, after = doc["before"]["Cm_alpha_dot"]["sigma"], doc["after"]["Cm_alpha_dot"]["sigma"]
    assert after < 0.5 * before


def test_a_vehicle_file_of_ones_own_is_not_flown_in_a_jsbsim_model_of_the_same_name(tmp_path):
    from types import SimpleNamespace

    from aerosid.design.flyers import default_flyer, generated_for_jsbsim

    mine = SimpleNamespace(name="DHC6", description="our Twin Otter, from the flight-test programme",
                           source="twin.toml")
    assert not generated_for_jsbsim(mine)
    with pytest.raises(DesignError, match="happens to share its name"):
        default_flyer(mine, None, {}, None, 1.0, lambda m: None)
    gen = SimpleNamespace(name="DHC6", description="JSBSim DHC6 (propeller), symmetric loading, generated flight "
                                                   "design", source="v.toml")
    assert generated_for_jsbsim(gen)
