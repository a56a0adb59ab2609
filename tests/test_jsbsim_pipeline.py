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


def test_the_diagnosis_names_a_missing_sideslip_pitching_moment_and_a_spec_can_add_it(tmp_path):
    """An aircraft's layout term the default model leaves out: c182's drag acts below its
    aerodynamic reference point's height off the CG, so C_m grows with |beta| (its generated
    vehicle file carries Cm_abs_beta).  The same flight analysed with the aircraft default models
    (a vehicle file written by hand) gets cm_abs_beta recommended, and a model spec adds it by that
    name; a finned vehicle is not offered it."""
    import re

    from aerosid.diagnosis.candidates import default_candidates
    from aerosid.simulation.jsbsim_aircraft import simulate_aircraft

    fl = simulate_aircraft("c182", 0)
    text = fl.files["vehicle.toml"]
    assert "Cm_abs_beta = abs(beta)" in text
    (tmp_path / "v.toml").write_text(re.sub(r"\n\[models\]\n(?:.*\n)*?(?=\n\[|\Z)", "\n", text + "\n"))
    by_hand = load_vehicle(tmp_path / "v.toml")
    assert "Cm_abs_beta" not in default_models(by_hand)["Cm"].names
    run = process_telemetry(fl.telemetry, by_hand)
    d = diagnose(run.flight_data, by_hand, localisation=False)
    assert d.recommended == "cm_abs_beta", d.summary()
    term = parse_term("cm_abs_beta", "Cm")
    assert (term.coefficient, term.expression) == ("Cm_abs_beta", "abs(beta)")
    assert "cm_abs_beta" not in {c.name for c in default_candidates(12.4, "finned")}


def test_the_localisation_names_the_dhc6_roll_moment_in_abs_beta_where_its_biased_vane_puts_the_kink(tmp_path):
    """JSBSim's DHC-6 rolls with 0.41 |beta| at the flight's alpha (its C_l(beta) table is even in
    beta below alpha = 4 deg), which no linear model holds (C_l R^2 0.32, C_l,p -0.06 for -0.50).
    The generated vanes carry a -0.3 deg beta bias the user does not know: the localisation names
    abs(beta) with its kink moved there, and the suggested term brings C_l,p and the aileron's
    C_l within 5 % and 3 sigma of the truth (docs/localisation.md).  Formed from the low-passed beta
    (the band path's order before 2026-11-29: |LP(beta)| where C_l holds LP(|beta|)), C_l,p was
    -15 % and 6.5 sigma off."""
    from aerosid.simulation.jsbsim_aircraft import simulate_aircraft

    fl = simulate_aircraft("DHC6", 0)
    (tmp_path / "v.toml").write_text(fl.files["vehicle.toml"])
    veh = load_vehicle(tmp_path / "v.toml")
    run = process_telemetry(fl.telemetry, veh)
    d = diagnose(run.flight_data, veh)
    cl = [f for f in d.localisation["Cl"] if f.significant and f.kind == "shape" and f.variable == "beta"]
    assert cl and cl[0].suggested_coefficient == "Cl_abs_beta", d.summary()
    assert cl[0].evidence["kink_at"] == pytest.approx(-np.radians(0.3), abs=0.0015)
    models = default_models(veh)
    term = parse_term(cl[0].spec_line, "Cl")
    cl_model = ChannelModel("Cl", models["Cl"].terms + (term,))
    fit = identify(run.flight_data, veh, models={**models, "Cl": cl_model}).fits["Cl"]
    est, se = dict(zip(fit.names, fit.estimate)), dict(zip(fit.names, fit.std_error))
    for name in ("Cl_p", "Cl_delta_r"):  # Cl_delta_r: the roll control, the aileron
        truth = fl.coefficients[name]
        assert abs(est[name] / truth - 1) <= 0.05, (name, est[name], truth)
        assert abs(est[name] - truth) <= 3 * se[name], (name, est[name], se[name], truth)


def test_a_vane_noise_left_out_of_the_vehicle_file_is_measured_from_the_vanes(run, flight, vehicle, tmp_path):
    """A vehicle file written by hand may leave out [air_data] noise_rad: it is then measured on
    the vanes (their third differences), not taken as 0 -- which switched the errors-in-variables
    correction off (c182 seed 0: C_m,alpha -10 % instead of -7 %, C_m,q +11 % instead of +7 %)."""
    import math

    from aerosid.vehicles.vehicle import resolve_vehicle_path

    text = resolve_vehicle_path("c172x").read_text()
    line = next(ln for ln in text.splitlines() if ln.startswith("noise_rad"))
    (tmp_path / "v.toml").write_text(text.replace(line + "\n", ""))
    unstated = load_vehicle(tmp_path / "v.toml")
    assert math.isnan(unstated.vane_noise_rad) and vehicle.vane_noise_rad == pytest.approx(0.0026)
    measured = process_telemetry(flight.telemetry, unstated, mach_half_width=None)
    for c in ("eiv_sigma_alpha_rad", "eiv_sigma_beta_rad"):  # the flight's vanes carry 0.15 deg of noise
        assert measured.flight_data[c].median() == pytest.approx(vehicle.vane_noise_rad, rel=0.15), c
    a = run.identification.table().set_index("coefficient")
    b = measured.identification.table().set_index("coefficient")
    for name in ("CN_alpha", "Cm_alpha", "Cm_delta_p", "Cm_q", "Cl_p", "Cn_r"):
        assert abs(b.loc[name, "estimate"] - a.loc[name, "estimate"]) < 0.3 * a.loc[name, "std_error"], name


def test_a_lift_slope_or_roll_damping_no_wing_gives_is_reported_loudly(run, vehicle):
    """An aircraft without preflight values: its C_N,alpha and C_l,p are checked against what
    a wing can give.  Nothing on c172x as flown; with every coefficient x1/10.76 -- what a wing
    area written in ft^2 does (c182 ran to "ok" that way) -- both are reported, in the table
    and as run findings."""
    from aerosid.identification.identify import format_table
    from aerosid.plausibility.estimates import implausible_estimate_findings

    fd = run.flight_data
    good = identify(fd, vehicle, bias_pairs=0).table()
    assert (good["preflight_warning"] == "").all(), good.loc[good["preflight_warning"] != "", "preflight_warning"]
    assert implausible_estimate_findings(good, fd["t_s"]) == []
    ft2 = fd.assign(**{c: fd[c] / 10.7639 for c in ("CN", "CY", "CA", "Cl", "Cm", "Cn")})
    bad = identify(ft2, vehicle, bias_pairs=0).table()
    warned = bad.set_index("coefficient")["preflight_warning"]
    assert "cn_alpha_per_rad" in warned["CN_alpha"] and "S_m2 (ft^2" in warned["CN_alpha"]
    assert "cl_p_per_rad" in warned["Cl_p"] and "span_m" in warned["Cl_p"]
    assert (warned.drop(["CN_alpha", "Cl_p"]) == "").all()
    found = implausible_estimate_findings(bad, ft2["t_s"])
    assert {(f["kind"], f["channel"]) for f in found} == {("implausible_estimate", "CN"), ("implausible_estimate", "Cl")}
    assert all(f["t0_s"] == fd["t_s"].min() and f["n_samples"] > 0 and not f["cut"] for f in found)
    assert "!! WARNING CN_alpha: its 95 % interval" in format_table(bad)


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
    assert not any(f["kind"] in ("implausible_estimate", "vehicle_geometry") for f in run_doc["findings"])
    # the same flight with the vehicle file's wing area written in ft^2: the run says so, not "ok"
    from aerosid.vehicles.vehicle import resolve_vehicle_path

    text = resolve_vehicle_path("c172x").read_text()
    assert text.count("S_m2 = 16.1651") == 1
    (tmp_path / "ft2.toml").write_text(text.replace("S_m2 = 16.1651", "S_m2 = 174.0"))
    res = runner.invoke(main, ["run", str(tmp_path / "f" / "telemetry.parquet"), "--vehicle", str(tmp_path / "ft2.toml"),
                               "--out", str(tmp_path / "run_ft2")])
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "run_ft2" / "run.json").read_text())
    assert doc["status"] == "ok with findings"
    assert {f["channel"] for f in doc["findings"] if f["kind"] == "implausible_estimate"} == {"CN", "Cl"}
    assert any(f["kind"] == "vehicle_geometry" and "S_m2 in ft^2" in f["detail"] for f in doc["findings"])
    assert "regression CN: implausible_estimate" in res.output and "!! WARNING CN_alpha" in res.output


def test_unknown_aircraft_and_manoeuvre_are_clear_errors():
    with pytest.raises(ValueError, match="c172x"):
        simulate_jsbsim("no-such-aircraft", "3211")
    with pytest.raises(ValueError, match="3211"):
        simulate_jsbsim("c172x", "barrel-roll")
