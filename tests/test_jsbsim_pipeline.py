"""The pipeline against an engine nobody here wrote: JSBSim's c172x, flown by
aerosid.simulation.jsbsim_flight, through the same core, flows and CLI as seed-rlv.
Skipped cleanly without the extra (pip install "aerosid[jsbsim]")."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("jsbsim")

from click.testing import CliRunner  # noqa: E402

from aerosid.diagnosis import diagnose  # noqa: E402
from aerosid.ebm import process_telemetry  # noqa: E402
from aerosid.identification.identify import identify  # noqa: E402
from aerosid.modelling.models import ChannelModel, default_models, parse_term  # noqa: E402
from aerosid.simulation.jsbsim_flight import simulate_jsbsim  # noqa: E402
from aerosid.vehicles.vehicle import load_vehicle  # noqa: E402

#: issue bars: |error| of Cm_alpha and Cm_delta_p <= 5 %, of the damping Cm_q + Cm_alpha_dot <= 10 %
BARS = {"Cm_alpha": 0.05, "Cm_delta_p": 0.05}
DAMPING_BAR = 0.10


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle("c172x")


@pytest.fixture(scope="module")
def flight():
    return simulate_jsbsim("c172x", "3211", seed=0)


@pytest.fixture(scope="module")
def run(flight, vehicle):
    return process_telemetry(flight.telemetry, vehicle, mach_half_width=None)


def test_pitch_derivatives_within_the_bars_with_intervals(run, flight):
    tab = run.identification.table().set_index("coefficient")
    for name, bar in BARS.items():
        est, truth = tab.loc[name, "estimate"], flight.coefficients[name]
        assert abs(est / truth - 1) <= bar, (name, est, truth)
        assert tab.loc[name, "ci_low"] < est < tab.loc[name, "ci_high"]
        assert tab.loc[name, "std_error"] > 0
    # a short-period manoeuvre measures the combined damping; each part alone is poorly determined
    est, se, lo, hi = run.identification.fits["Cm"].combination({"Cm_q": 1.0, "Cm_alpha_dot": 1.0})
    truth = flight.coefficients["Cm_q_plus_alpha_dot"]
    assert abs(est / truth - 1) <= DAMPING_BAR, (est, truth)
    # the sum is better determined than the worse of its collinear parts (with the vane-noise
    # correction's own error in each part's sigma, not always better than the better one)
    assert lo < est < hi and se < max(tab.loc["Cm_q", "std_error"], tab.loc["Cm_alpha_dot", "std_error"])


def _without_damping(models: dict) -> dict:
    out = dict(models)
    out["Cm"] = ChannelModel("Cm", tuple(t for t in models["Cm"].terms
                                         if t.effect != "pitch_damping" and t.coefficient != "Cm_alpha_dot"))
    return out


def test_diagnosis_finds_the_missing_pitch_damping_and_adding_it_makes_the_error_fall(run, vehicle, flight):
    full = default_models(vehicle)
    assert {"Cm_q", "Cm_alpha_dot"} <= set(full["Cm"].names)
    no_damping = _without_damping(full)
    assert not {"Cm_q", "Cm_alpha_dot"} & set(no_damping["Cm"].names)
    d = diagnose(run.flight_data, vehicle, no_damping, mach_half_width=None)
    assert d.top.name == "pitch_damping" and d.top.significant, d.summary()
    assert d.top.channel == "Cm" and d.top.estimate < 0
    # adding what the diagnosis names (pitch_damping) makes the error fall
    with_it = dict(no_damping)
    with_it["Cm"] = no_damping["Cm"].with_term(parse_term(d.top.spec_term, "Cm"))
    before = identify(run.flight_data, vehicle, no_damping, None).fits["Cm"]
    after = identify(run.flight_data, vehicle, with_it, None).fits["Cm"]
    assert after.rms_residual < 0.95 * before.rms_residual
    assert after.pse < before.pse
    # with damping in the model the diagnosis no longer asks for it
    d2 = diagnose(run.flight_data, vehicle, with_it, mach_half_width=None)
    assert d2.rank_of("pitch_damping") is None


@pytest.mark.prefect
def test_c172x_runs_through_the_same_cli_and_flow(tmp_path):
    from aerosid.cli import main

    runner = CliRunner()
    sim = runner.invoke(main, ["simulate", "--jsbsim", "c172x", "--manoeuvre", "3211", "--out", str(tmp_path / "f")])
    assert sim.exit_code == 0, sim.output
    truth = json.loads((tmp_path / "f" / "truth.json").read_text())
    assert truth["case"] == "c172x" and "Cm_q" in truth["coefficients"]
    # no --vehicle: the telemetry's metadata names c172x
    res = runner.invoke(main, ["run", str(tmp_path / "f" / "telemetry.parquet"), "--out", str(tmp_path / "run")])
    assert res.exit_code == 0, res.output
    run_doc = json.loads((tmp_path / "run" / "run.json").read_text())
    assert run_doc["vehicle"] == "c172x"
    coef = pd.read_parquet(tmp_path / "run" / "coefficients.parquet").set_index("coefficient")
    assert {"Cm_alpha", "Cm_delta_p", "Cm_q", "Cl_p", "Cn_r"} <= set(coef.index)
    assert np.isfinite(coef.loc["Cm_q", "estimate"]) and coef.loc["Cm_q", "estimate"] < 0
    assert (tmp_path / "run" / "report.html").is_file() and (tmp_path / "run" / "diagnosis.json").is_file()


def test_unknown_aircraft_and_manoeuvre_are_clear_errors():
    with pytest.raises(ValueError, match="c172x"):
        simulate_jsbsim("no-such-aircraft", "3211")
    with pytest.raises(ValueError, match="3211"):
        simulate_jsbsim("c172x", "barrel-roll")
