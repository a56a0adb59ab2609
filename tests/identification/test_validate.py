"""aerosid validate: the identified model of a run folder, coefficient prediction, spans,
the attitude input, and the command on a small run (built without Prefect)."""
import json
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from aerosid.cli import main
from aerosid.identification.identified import ModelSourceError, load_identified_model, model_from_table
from aerosid.identification.output_prediction import theil_inequality
from aerosid.identification.validate import attitude_on, predict_coefficients, spans_of
from aerosid.io import write_parquet_atomic
from aerosid.simulation import load_case, simulate

def test_run_coefficients_are_the_model_and_a_version_takes_over(small_run, tmp_path):
    import shutil

    from aerosid.modelling.versions import fit_version, models_from_spec

    run = tmp_path / "run"
    shutil.copytree(small_run["run"], run)
    m = load_identified_model(run)
    table = pd.read_parquet(run / "coefficients.parquet")
    assert m.source.endswith("coefficients.parquet")
    assert m.values["Cm_alpha"] == table.set_index("coefficient").loc["Cm_alpha", "estimate"]
    assert m.models["Cm"].names == ("Cm_0", "Cm_alpha", "Cm_delta_p")
    spec = tmp_path / "cmq.toml"
    spec.write_text('[Cm]\nterms = ["Cm_0 = 1", "Cm_alpha = alpha", "Cm_delta_p = delta_p/2", "pitch_damping"]\n')
    fit_version(run, models_from_spec(spec, run), note="add pitch damping")
    latest = load_identified_model(run)
    assert latest.source.endswith("models/v002") and "Cm_q" in latest.values
    assert latest.models["Cm"].terms[-1].expression == "q_hat"
    assert "Cm_q" not in load_identified_model(run, "v001").values
    with pytest.raises(ModelSourceError, match="v009"):
        load_identified_model(run, "v009")


def test_a_table_without_expressions_is_refused():
    with pytest.raises(ModelSourceError, match=r"old\.parquet.*expression"):
        model_from_table(pd.DataFrame({"channel": ["Cm"], "coefficient": ["Cm_0"], "estimate": [0.1]}), "old.parquet")


def test_spans_split_at_segments_holes_and_the_window():
    t = np.r_[np.arange(0, 3, 0.01), np.arange(3.5, 6, 0.01), np.arange(6, 8, 0.01)]
    fd = pd.DataFrame({"t_s": t, "segment": ["a"] * 550 + ["b"] * 200})
    keep = np.ones(len(t), bool)
    keep[100:110] = False          # out of the Mach window: 0..1 s and 1.1..3 s
    keep[300:350] = False          # 3.5..4.0 out: 4.0..6 remains (a 2 s span)
    span = spans_of(fd, keep, min_span_s=1.0)
    assert (span[:110] == -1).all()  # 0..0.99 s is shorter than 1 s: dropped
    assert (span[110:300] == 0).all()
    assert (span[300:350] == -1).all()
    assert (span[350:550] == 1).all()
    assert (span[550:] == 2).all()  # a new segment starts a new span even without a hole


def test_coefficient_prediction_of_the_true_model_is_exact_up_to_the_linearisation(clean_truth):
    veh, tr, model = clean_truth
    fd = tr.assign(flight="f", segment="s")
    span = np.zeros(len(fd), int)
    _, metrics = predict_coefficients(model, fd, veh, span, "none")
    tic = {m.name: m.tic for m in metrics}
    assert max(tic.values()) < 0.01, tic
    wrong = model.with_values(Cm_alpha=1.2 * model.values["Cm_alpha"])
    _, metrics = predict_coefficients(wrong, fd, veh, span, "none")
    assert {m.name: m.tic for m in metrics}["Cm"] > 10 * tic["Cm"]


def test_attitude_in_degrees_is_refused(small_run):
    raw = pd.read_parquet(small_run["degrees"])
    with pytest.raises(ValueError, match="f3: column '(phi|theta)_rad'.*it must be radians"):
        attitude_on(raw, raw["t_s"].to_numpy(), "f3")
    assert attitude_on(raw.drop(columns=["phi_rad"]), raw["t_s"].to_numpy(), "f3") is None


def test_cli_validate_prints_and_writes_the_report(small_run):
    out = small_run["tmp"] / "val"
    res = CliRunner().invoke(main, ["validate", str(small_run["run"]), str(small_run["other"]), "--axes", "lon",
                                    "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "output prediction" in res.output and "TIC" in res.output
    doc = json.loads((out / "validation.json").read_text())
    assert [m["name"] for m in doc["outputs"]] == ["alpha_rad", "q_rad_s", "az_m_s2"]
    assert [m["name"] for m in doc["coefficients"]] == ["CN", "Cm", "CY", "Cn", "Cl"]
    assert doc["sources"]["attitude"].startswith("telemetry phi_rad")
    assert doc["n_spans"] == 2  # the simulated flight's sync gap splits it
    frame = pd.read_parquet(out / "validation.parquet")
    rows = frame[frame["span"] >= 0]
    for m in doc["outputs"]:  # the printed/recorded numbers are those of the written time histories
        o = m["name"]
        assert 0 < m["tic"] < 1
        ok = rows[f"measured_{o}"].notna() & rows[f"predicted_{o}"].notna()
        y, yhat = rows.loc[ok, f"measured_{o}"], rows.loc[ok, f"predicted_{o}"]
        assert m["tic"] == pytest.approx(theil_inequality(y, yhat))
        assert f"{m['tic']:.3f}" in res.output
    html = (out / "validation.html").read_text()
    assert html.count("<svg") == 2  # the lon outputs and the coefficients
    assert "<script" not in html and "http://" not in html and "https://" not in html
    assert 'id="output-metrics"' in html and "q_rad_s" in html


def test_cli_without_attitude_predicts_the_coefficients_and_says_why_not_the_outputs(small_run):
    out = small_run["tmp"] / "val-noatt"
    res = CliRunner().invoke(main, ["validate", str(small_run["run"]), str(small_run["no_attitude"]), "--out",
                                    str(out)])
    assert res.exit_code == 0, res.output
    assert "no output prediction" in res.output and "phi_rad / theta_rad" in res.output
    doc = json.loads((out / "validation.json").read_text())
    assert doc["outputs"] == [] and len(doc["coefficients"]) == 5


def test_cli_errors_are_one_clear_line(small_run, tmp_path):
    res = CliRunner().invoke(main, ["validate", str(tmp_path / "nope"), str(small_run["other"])])
    assert res.exit_code == 1 and "no such run folder" in res.output and "Traceback" not in res.output
    res = CliRunner().invoke(main, ["validate", str(small_run["run"]), str(small_run["degrees"]), "--out",
                                    str(tmp_path / "v")])
    assert res.exit_code == 1 and "_rad' is outside" in res.output and "radians" in res.output
    assert not (tmp_path / "v").exists()


def test_the_other_manoeuvre_s_units_and_signs_are_checked_as_the_run_s_own(small_run, tmp_path):
    """validate (and refine) read a second telemetry file that no pre-flight had checked: a pitch
    gyro in deg/s there was estimated and predicted as if it were rad/s. Refused naming it."""
    raw = pd.read_parquet(small_run["other"])
    bad = tmp_path / "q_deg_s.parquet"
    write_parquet_atomic(raw.assign(q_rad_s=raw["q_rad_s"] * 57.29577951308232), bad,
                         metadata={"aerosid.case": "seed-rlv"})
    res = CliRunner().invoke(main, ["validate", str(small_run["run"]), str(bad), "--out", str(tmp_path / "v")])
    assert res.exit_code == 1 and "Traceback" not in res.output, res.output
    assert "column 'q_rad_s'" in res.output and "look like deg/s" in res.output and "q_deg_s.parquet" in res.output
    assert not (tmp_path / "v").exists()


def test_a_manoeuvre_outside_the_mach_window_is_refused_naming_the_window(small_run, tmp_path):
    case = load_case("seed-rlv", duration_s=8.0)
    fast = simulate(replace(case, faults=case.faults.without_faults()), seed=4)  # M 13.1..13.0: above 12.4 + 0.5
    write_parquet_atomic(fast.telemetry, tmp_path / "fast.parquet", metadata={"aerosid.case": "seed-rlv"})
    res = CliRunner().invoke(main, ["validate", str(small_run["run"]), str(tmp_path / "fast.parquet"), "--out",
                                    str(tmp_path / "v")])
    assert res.exit_code == 1 and "Traceback" not in res.output
    assert "Mach window 12.4 +- 0.5" in res.output and "spans Mach 13" in res.output


def test_identity_channels_are_simulated_with_the_preflight_database(small_run):
    """seed-rlv's alpha and beta are inverted from C_N and C_Y: the run cannot identify those
    channels, and the simulation takes the preflight database's values for them.  With them at 0
    (before) the predicted a_z had no lift and its error was the whole a_z motion; with the
    database it is the accelerometer's own noise (seed Table 2: 2 m/s^2)."""
    from aerosid.identification.identified import with_preflight_identities
    from aerosid.identification.output_error import free_coefficients
    from aerosid.identification.validate import validate
    from aerosid.modelling.aeromodel import AeroModel
    from aerosid.vehicles.vehicle import load_vehicle

    veh = load_vehicle("seed-rlv")
    model = load_identified_model(small_run["run"])
    assert set(model.unidentified()) == {"CN_0", "CN_alpha", "CN_delta_p", "CY_0", "CY_beta", "CY_delta_y"}
    sim, notes = with_preflight_identities(model, veh)
    refs = AeroModel.preflight(veh).linear_truth()
    assert set(sim.preflight) == set(model.unidentified()) and not sim.unidentified()
    assert all(sim.values[k] == refs[k] for k in sim.preflight)
    assert sim.values["Cm_alpha"] == model.values["Cm_alpha"] and sim.path == model.path
    assert "CN/CY" in notes[0] and "preflight force database" in notes[0]
    assert "CN_alpha" not in free_coefficients(sim, "lon") and "Cm_alpha" in free_coefficients(sim, "lon")
    with pytest.raises(ValueError, match=r"\['CN_alpha'\] are the preflight database's"):
        free_coefficients(sim, "lon", ["Cm_alpha", "CN_alpha"])
    result = validate(small_run["run"], small_run["other"], axes="lon")
    az = {m.name: m for m in result.outputs}["az_m_s2"]
    accel_noise = load_case("seed-rlv").sensors.accel_noise_m_s2[2]
    assert az.rms < 1.15 * accel_noise, az.rms
    assert any("identities by construction" in n for n in result.notes)
    # the model reported (and its coefficient prediction) stays the run's: NaN where not identified
    assert np.isnan(result.model.values["CN_alpha"])


def test_history_against_a_manoeuvre_simulates_every_version(small_run, tmp_path):
    """`aerosid history RUN --against TELEMETRY`: each version simulated on the manoeuvre as
    validate does (the same numbers), the lowest RMS per output starred."""
    import shutil

    from aerosid.identification.validate import compare_versions, validate
    from aerosid.modelling.versions import fit_version, models_from_spec

    run = tmp_path / "run"
    shutil.copytree(small_run["run"], run)
    spec = tmp_path / "damping.toml"
    spec.write_text('[Cm]\nadd = ["pitch_damping"]\n')
    fit_version(run, models_from_spec(spec, run), note="add pitch damping")
    frame = compare_versions(run, small_run["other"], ["v001", "v002"])
    assert list(frame["version"]) == ["v001", "v002"]
    direct = validate(run, small_run["other"], version="v002", axes="lon")
    for m in direct.outputs:
        assert frame.set_index("version").loc["v002", f"{m.name}_rms"] == m.rms
    res = CliRunner().invoke(main, ["history", str(run), "--against", str(small_run["other"])])
    assert res.exit_code == 0, res.output
    text = res.output[res.output.index("simulated on"):]
    assert "alpha [deg]" in text and "Cm: +pitch_damping" in text
    best = frame["alpha_rad_rms"].idxmin()
    line = next(ln for ln in text.splitlines() if ln.strip().startswith(frame.loc[best, "version"]))
    assert f"{np.degrees(frame.loc[best, 'alpha_rad_rms']):.4g}*" in line
    assert f"{np.degrees(frame.loc[best, 'q_rad_s_rms']):.4g}" in text  # q in deg/s
    assert (frame["alpha_rad_n"] == direct.outputs[0].n).all()
    # without the attitude: one clear error before any estimation, not an empty table
    res = CliRunner().invoke(main, ["history", str(run), "--against", str(small_run["no_attitude"])])
    assert res.exit_code == 1 and "phi_rad / theta_rad" in res.output and "Traceback" not in res.output
