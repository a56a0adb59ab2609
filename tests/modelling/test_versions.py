"""Model versions (aerosid.modelling.versions) and the modelling-loop commands (aerosid.cli.modelling)."""
from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
from click.testing import CliRunner

from aerosid.cli.modelling import diagnose as diagnose_cmd
from aerosid.cli.modelling import fit as fit_cmd
from aerosid.cli.modelling import history as history_cmd
from aerosid.diagnosis.synthetic import MEASURED_NOISE, flight_data_from_truth
from aerosid.modelling.effects import CATALOGUE
from aerosid.modelling.models import ModelSpecError, default_models, parse_term
from aerosid.modelling.versions import (VersionError, _claim, fit_version, history, latest_models, models_from_spec,
                              run_vehicle)

SPEC_CONTROL_ALPHA = """\
[Cm]
terms = ["Cm_0 = 1", "Cm_alpha = alpha", "Cm_delta_p = delta_p/2", "control_alpha"]
"""


@pytest.fixture(scope="module")
def flight_data(reference_flight):
    """Flight data with control_alpha added along the reference trajectory (open loop)."""
    fd = flight_data_from_truth(reference_flight.truth, MEASURED_NOISE.scaled(0.25), seed=0)
    tr = reference_flight.truth
    e = CATALOGUE["control_alpha"]
    fd["Cm"] = fd["Cm"] + e.value * tr["alpha_rad"].to_numpy() * tr["delta_p_rad"].to_numpy() / 2
    return fd


@pytest.fixture
def run_dir(tmp_path, flight_data):
    d = tmp_path / "run"
    d.mkdir()
    flight_data.to_parquet(d / "flight_data.parquet", index=False)
    return d


def _hash(path):
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(path.iterdir())}


def test_versions_grow_with_parent_links_and_the_error_falls(run_dir):
    assert len(history(run_dir)) == 0
    v = fit_version(run_dir, note="baseline")  # default models -> v001 only
    assert v.id == "v001" and v.parent is None
    frozen = _hash(run_dir / "models" / "v001")
    assert set(frozen) == {"spec.toml", "metrics.json", "coefficients.parquet", "parent"}

    models = default_models()
    models["Cm"] = models["Cm"].with_term(parse_term("control_alpha", "Cm"))
    v2 = fit_version(run_dir, models, note="add control-alpha")
    assert (v2.id, v2.parent) == ("v002", "v001")
    bad = {**models, "Cm": models["Cm"].with_term(parse_term("Cm_junk = sin(t)", "Cm"))}
    v3 = fit_version(run_dir, bad, parent="v002", note="try a junk term")
    assert (v3.id, v3.parent) == ("v003", "v002")
    assert _hash(run_dir / "models" / "v001") == frozen  # immutable

    h = history(run_dir)
    assert [x.id for x in h.versions] == ["v001", "v002", "v003"]
    tab = h.table()
    assert list(tab["version"]) == ["v001", "v002", "v003"]
    assert list(tab["parent"]) == ["", "v001", "v002"]
    assert tab.loc[1, "changes"] == "Cm: +control_alpha"
    assert tab.loc[0, "changes"] == "default models"
    assert {"rms_Cm", "r2_Cm", "pse_Cm", "rms_Cl"} <= set(tab.columns)
    # the error falls when the missing effect is added (measured residual, a quarter of the real
    # pipeline's errors as in tests/test_diagnosis.py)
    assert tab.loc[1, "rms_Cm"] < 0.5 * tab.loc[0, "rms_Cm"]
    assert tab.loc[1, "rms_CN"] == tab.loc[0, "rms_CN"]
    plot = h.plot_data()
    assert set(plot.columns) >= {"version", "number", "channel", "rms"} and len(plot) == 3 * 5
    metrics = json.loads((run_dir / "models" / "v002" / "metrics.json").read_text())
    cm = metrics["channels"]["Cm"]
    assert {"rms_residual", "r2", "pse", "f_stat", "f_stat_corrected", "coefficients"} <= set(cm)
    assert cm["coefficients"]["Cm_alpha_delta_p"]["std_error"] > 0
    # the Cramer-Rao bound travels with each coefficient, as in coefficients.parquet
    coefs = json.loads((run_dir / "models" / "v002" / "metrics.json").read_text())["channels"]["Cm"]["coefficients"]
    table = __import__("pandas").read_parquet(run_dir / "models" / "v002" / "coefficients.parquet")
    for name, c in coefs.items():
        want = float(table.loc[table["coefficient"] == name, "crb_std"].iloc[0])
        assert (c["crb_std"] is None) == (not np.isfinite(want))
        if c["crb_std"] is not None:
            assert c["crb_std"] == pytest.approx(want)
    assert cm["identity"] is False
    assert abs(cm["coefficients"]["Cm_alpha_delta_p"]["estimate"] / CATALOGUE["control_alpha"].value - 1) < 0.1
    assert "v002" in h.summary() and "control_alpha" in h.summary()
    assert latest_models(run_dir)["Cm"].names[-1] == "Cm_junk"


def test_first_fit_with_a_new_model_also_stores_the_default_root(run_dir):
    models = default_models()
    models["Cm"] = models["Cm"].with_term(parse_term("control_alpha", "Cm"))
    v = fit_version(run_dir, models)
    assert (v.id, v.parent) == ("v002", "v001")
    assert history(run_dir).get("v001").models["Cm"].names == default_models()["Cm"].names


def test_ids_are_claimed_atomically_and_unfinished_versions_ignored(run_dir):
    fit_version(run_dir)
    a, b = _claim(run_dir / "models"), _claim(run_dir / "models")  # e.g. two concurrent fits
    assert (a.name, b.name) == ("v002", "v003")
    assert [v.id for v in history(run_dir).versions] == ["v001"]  # no metrics.json: not a version
    assert fit_version(run_dir).id == "v004"


def test_errors_name_the_file(tmp_path, run_dir):
    with pytest.raises(VersionError, match="flight_data.parquet"):
        fit_version(tmp_path)
    spec = tmp_path / "bad.toml"
    spec.write_text('[Cm]\nterms = ["Cm_0 = 1", "Cm_x = alpha +* 2"]\n')
    with pytest.raises(ModelSpecError, match="bad.toml"):
        models_from_spec(spec, run_dir)
    with pytest.raises(VersionError, match="v009"):
        fit_version(run_dir, parent="v009")


def test_vehicle_from_run_json(tmp_path):
    assert run_vehicle(tmp_path) == "seed-rlv"
    (tmp_path / "run.json").write_text(json.dumps({"vehicle": "seed-rlv", "flight": "x"}))
    assert run_vehicle(tmp_path) == "seed-rlv"
    (tmp_path / "run.json").write_text("{not json")
    with pytest.raises(VersionError, match="run.json"):
        run_vehicle(tmp_path)


def test_cli_loop_diagnose_fit_history(run_dir, tmp_path):
    runner = CliRunner()
    r = runner.invoke(diagnose_cmd, [str(run_dir)])
    assert r.exit_code == 0, r.output
    doc = json.loads((run_dir / "diagnosis.json").read_text())
    assert doc["effects"][0]["name"] == "control_alpha" and doc["effects"][0]["significant"]
    assert doc["model"] == "default models"
    assert "Most likely missing: control_alpha" in r.output

    spec = tmp_path / "cm.toml"
    spec.write_text(SPEC_CONTROL_ALPHA)
    r = runner.invoke(fit_cmd, [str(run_dir), "--model", str(spec), "--note", "add control-alpha"])
    assert r.exit_code == 0, r.output
    assert "created v001, v002" in r.output and "Cm   residual RMS" in r.output
    # the fit diagnoses the version it made, and its report shows that version
    assert "diagnosis of v002" in r.output
    doc = json.loads((run_dir / "diagnosis.json").read_text())
    assert doc["model"] == "v002" and not [e for e in doc["effects"] if e["channel"] == "Cm" and e["significant"]]
    html = (run_dir / "report.html").read_text()
    assert 'model diagnosed: <b id="diagnosed-model">v002</b>' in html and "model version v002 (the latest)" in html

    r = runner.invoke(diagnose_cmd, [str(run_dir), "--quiet"])
    assert r.exit_code == 0, r.output
    doc = json.loads((run_dir / "diagnosis.json").read_text())
    assert doc["model"] == "v002"
    assert not [e for e in doc["effects"] if e["channel"] == "Cm" and e["significant"]]

    csv = tmp_path / "h.csv"
    r = runner.invoke(history_cmd, [str(run_dir), "--csv", str(csv)])
    assert r.exit_code == 0, r.output
    assert "v001" in r.output and "v002" in r.output and "Cm: +control_alpha" in r.output
    assert csv.read_text().startswith("version,parent,changes,note")


def test_cli_errors_are_clear(tmp_path, run_dir):
    runner = CliRunner()
    empty = tmp_path / "empty"
    empty.mkdir()
    r = runner.invoke(diagnose_cmd, [str(empty)])
    assert r.exit_code == 1 and "flight_data.parquet" in r.output
    r = runner.invoke(fit_cmd, [str(run_dir), "--model", str(tmp_path / "missing.toml")])
    assert r.exit_code == 1 and "missing.toml" in r.output
    r = runner.invoke(history_cmd, [str(tmp_path / "nope")])
    assert r.exit_code == 1 and "no such run folder" in r.output
    for cmd in (diagnose_cmd, fit_cmd, history_cmd):
        r = runner.invoke(cmd, ["--help"])
        assert r.exit_code == 0 and "RUN_DIR" in r.output
