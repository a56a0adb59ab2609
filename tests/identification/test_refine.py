"""aerosid refine: output-error refinement of a run's model on a manoeuvre (the command on
the small seed-rlv run of tests/identification/conftest.py, built without Prefect)."""
import json

import pandas as pd
import pytest
import pyarrow.parquet as pq
from click.testing import CliRunner

from aerosid.cli import main


def test_cli_refine_prints_both_estimates_and_writes_json(small_run):
    out = small_run["tmp"] / "refined"
    res = CliRunner().invoke(main, ["refine", str(small_run["run"]), str(small_run["other"]), "--axes", "lon",
                                    "--free", "Cm_alpha", "--free", "Cm_delta_p", "--free", "Cn_beta",
                                    "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "output-error refinement of the lon axis" in res.output and "equation error" in res.output
    assert "not refined (not in the lon axis models): ['Cn_beta']" in res.output
    doc = json.loads((out / "output_error.json").read_text())
    lon = doc["axes"]["lon"]
    assert list(lon["coefficients"]) == ["Cm_alpha", "Cm_delta_p"]
    truth = {"Cm_alpha": -0.2521, "Cm_delta_p": 0.03747}  # seed-rlv's linear truth (bench/results/generalisation.md)
    for k, c in lon["coefficients"].items():
        assert c["std_error"] >= 0.7 * c["std_error_crb"] > 0
        assert abs(c["estimate"] - truth[k]) < 4 * c["std_error"], (k, c)
    outs = lon["outputs"]
    assert set(outs) == {"alpha_rad", "q_rad_s", "az_m_s2"}
    assert all(o["tic_end"] <= o["tic_start"] + 1e-3 for o in outs.values())
    # what the simulated q cannot follow is the gyro's white noise (Table 2: 2 deg/s)
    assert abs(outs["q_rad_s"]["noise_std"] / 0.03490659 - 1) < 0.1
    # the refined model as a coefficients table validate can predict with
    table = pd.read_parquet(out / "coefficients.parquet")
    meta = pq.read_schema(out / "coefficients.parquet").metadata
    assert meta[b"aerosid.mach_half_width"] == b"0.5"  # the window validate --coefficients predicts in
    rows = table.set_index("coefficient")
    assert rows.loc["Cm_alpha", "estimate"] == lon["coefficients"]["Cm_alpha"]["estimate"]
    assert rows.loc["Cm_alpha", "method"] == "output error" and rows.loc["CN_alpha", "method"].startswith("equation")
    res = CliRunner().invoke(main, ["validate", str(small_run["run"]), str(small_run["other"]), "--axes", "lon",
                                    "--coefficients", str(out / "coefficients.parquet"), "--out", str(out / "val")])
    assert res.exit_code == 0, res.output
    doc = json.loads((out / "val" / "validation.json").read_text())
    assert doc["model"] == str(out / "coefficients.parquet")
    assert doc["model_coefficients"]["Cm_alpha"] == rows.loc["Cm_alpha", "estimate"]


def test_cli_refine_refuses_a_misspelt_coefficient_before_the_estimation(small_run, tmp_path):
    res = CliRunner().invoke(main, ["refine", str(small_run["run"]), str(small_run["other"]), "--free", "Cm_alpa",
                                    "--out", str(tmp_path / "r")])
    assert res.exit_code == 1 and "Traceback" not in res.output
    assert "['Cm_alpa'] are not in the model" in res.output and "Cm_alpha" in res.output
    assert "preprocess" not in res.output  # refused before the estimation
    assert not (tmp_path / "r").exists()


def test_cli_refine_without_attitude_names_the_columns(small_run, tmp_path):
    res = CliRunner().invoke(main, ["refine", str(small_run["run"]), str(small_run["no_attitude"]), "--axes", "lon",
                                    "--out", str(tmp_path / "r")])
    assert res.exit_code == 1 and "Traceback" not in res.output
    assert "phi_rad / theta_rad" in res.output and "attitude" in res.output
    assert "output error" not in res.output  # refused before the estimation, not after
    assert not (tmp_path / "r").exists()


def test_both_axes_keep_the_one_that_refined_when_the_other_fails(small_run, monkeypatch):
    """--axes both on seed-rlv: lon, and lat (C_Y from the preflight database, simulated, not
    refined).  An axis whose fit fails is a note, the other's result is kept; the one axis asked
    for by name fails the command; auto leaves lat out (C_Y was not identified)."""
    import aerosid.identification.refine as refine_mod

    real = refine_mod.output_error_fit
    calls = []

    def fake(model, inputs, meas, veh, ax, free=None):
        calls.append((ax, tuple(free)))
        if ax == "lat":
            raise ValueError("the lateral simulation leaves the envelope")
        return real(model, inputs, meas, veh, ax, free=free)

    monkeypatch.setattr(refine_mod, "output_error_fit", fake)
    res = refine_mod.refine(small_run["run"], small_run["other"], axes="both")
    assert [ax for ax, _ in calls] == ["lon", "lat"]
    lat_free = dict(calls)["lat"]
    assert "Cn_beta" in lat_free and not any(k.startswith("CY_") for k in lat_free)  # preflight: fixed
    assert [f.axis for f in res.fits] == ["lon"]
    assert any(n.startswith("lat axis not refined: the lateral simulation leaves the envelope") for n in res.notes)
    assert any("identities by construction" in n for n in res.notes)
    with pytest.raises(ValueError, match="leaves the envelope"):
        refine_mod.refine(small_run["run"], small_run["other"], axes="lat")
    calls.clear()
    auto = refine_mod.refine(small_run["run"], small_run["other"], axes="auto")
    assert [ax for ax, _ in calls] == ["lon"] and [f.axis for f in auto.fits] == ["lon"]
    assert any("lateral axis not simulated" in n for n in auto.notes)
