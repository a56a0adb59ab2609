"""The diagnosis points to `aerosid design` where it cannot answer (issues 18 and 20):
an unresolved look-alike pair names the command that separates them, with both names;
a flight where nothing is significant names the command that would show an effect.
(What following that advice achieves is measured in bench/bench_follow_advice.py.)"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from aerosid.diagnosis import diagnose
from aerosid.diagnosis.lookalikes import compare
from aerosid.diagnosis.synthetic import MEASURED_NOISE, flight_data_from_truth
from aerosid.vehicles.vehicle import load_vehicle


def _cands():
    return [SimpleNamespace(name="alpha_nonlinearity", coefficient="Cm_alpha_abs_alpha", term="alpha*abs(alpha)",
                            spec_term="alpha_nonlinearity"),
            SimpleNamespace(name="control_alpha", coefficient="Cm_alpha_delta_p", term="alpha*delta_p/2",
                            spec_term="control_alpha")]


def _lookalikes(noise_sd: float, seed: int = 2):
    """Two regressors correlated at r ~ 0.97 beyond a constant; y holds a little of the first."""
    rng = np.random.default_rng(seed)
    n = 3000
    s = np.sin(np.linspace(0, 30, n))
    x1 = s + 0.25 * np.sin(np.linspace(0, 91, n))
    x2 = s + 0.25 * np.cos(np.linspace(0, 73, n))
    base = np.ones((n, 1))
    y = 0.05 * x1 + noise_sd * rng.standard_normal(n)
    return y, base, x1, x2


def test_unresolved_lookalikes_name_the_design_command_and_pooling():
    y, base, x1, x2 = _lookalikes(noise_sd=3.0)
    c = compare("Cm", y, base, ["Cm_0"], _cands(), [x1, x2])
    assert c.verdict == "unresolved" and c.recommended is None
    assert "aerosid design RUN_DIR --effect alpha_nonlinearity --versus control_alpha --out DIR" in c.message
    assert "aerosid run TELEMETRY NEW_TELEMETRY" in c.message  # pooled with the flight that could not tell


def test_separated_lookalikes_do_not_send_the_engineer_to_design():
    y, base, x1, x2 = _lookalikes(noise_sd=0.002)
    c = compare("Cm", y, base, ["Cm_0"], _cands(), [x1, x2])
    assert c.recommended == "alpha_nonlinearity"
    assert "aerosid design" not in c.message


def test_nothing_significant_names_the_design_command(reference_flight):
    vehicle = load_vehicle("seed-rlv")
    fd = flight_data_from_truth(reference_flight.truth, MEASURED_NOISE.scaled(0.25), seed=0)
    d = diagnose(fd, vehicle, localisation=False)
    assert d.nothing_significant, d.summary()
    assert "could not have detected" in d.message
    assert "aerosid design RUN_DIR --effect NAME --out DIR" in d.message


def test_unresolved_lookalikes_leave_no_spec_lines_to_paste():
    """The guess's `[Cm] add = [...]` lines would contradict 'no recommendation' (seen on seed-rlv
    seed 0 with alpha_nonlinearity hidden: the message ended with add = ["mach_cm0"])."""
    from aerosid.diagnosis.lookalikes import lookalike_message

    y, base, x1, x2 = _lookalikes(noise_sd=3.0)
    c = compare("Cm", y, base, ["Cm_0"], _cands(), [x1, x2])
    guess = ("Most likely missing: alpha_nonlinearity in Cm (non-linear static stability). It explains 2% of the "
             "Cm residual variance; add it with the lines below. Where the model is worst: Cm: t 0-10 s (x1.5)."
             '\n\n[Cm]\nadd = ["alpha_nonlinearity"]')
    msg = lookalike_message(SimpleNamespace(lookalikes=[c]), guess)
    assert "no recommendation" in msg and "Where the model is worst: Cm: t 0-10 s" in msg
    assert "add = [" not in msg


def test_run_summary_names_the_design_command_for_an_unresolved_pair(tmp_path):
    """`aerosid run` prints only the message's first sentence: the separating manoeuvre and the
    design command get a line of their own, with the run folder filled in."""
    import json

    from aerosid.cli.run_summary import verdict_lines

    pair = {"verdict": "unresolved", "in_model": None, "alternatives": [{"name": "alpha_nonlinearity"},
                                                                        {"name": "control_alpha"}],
            "separating_manoeuvre": "fly pitch-fin deflection excursions at two distinct alpha levels"}
    doc = {"message": "alpha_nonlinearity and control_alpha cannot be told apart in Cm on this flight.",
           "recommended": None, "effects": [], "lookalikes": [pair]}
    (tmp_path / "diagnosis.json").write_text(json.dumps(doc))
    text = "\n".join(verdict_lines(tmp_path))
    assert f"aerosid design {tmp_path} --effect alpha_nonlinearity --versus control_alpha --out DIR" in text
    assert "telemetry together" in text
    assert "two distinct alpha levels" in text
    # and the check that needs no flight: both fitted, both simulated
    assert 'add = ["alpha_nonlinearity"]' in text and 'add = ["control_alpha"]' in text and "[Cm]" in text
    assert f"aerosid history {tmp_path} --against TELEMETRY" in text
    # not where it cannot tell them apart: a lateral pair (history --against simulates lon), or one
    # of the two already in the model (adding each would compare a with a + b)
    for other in ({"channel": "Cl"}, {"in_model": "alpha_nonlinearity"}):
        (tmp_path / "diagnosis.json").write_text(json.dumps({**doc, "lookalikes": [{**pair, **other}]}))
        assert "--against" not in "\n".join(verdict_lines(tmp_path))
    doc.update(recommended="alpha_nonlinearity", lookalikes=[dict(pair, verdict="separated")])
    (tmp_path / "diagnosis.json").write_text(json.dumps(doc))
    assert "aerosid design" not in "\n".join(verdict_lines(tmp_path))


def test_run_summary_puts_late_vanes_before_any_model_question(tmp_path):
    """A run whose vanes lag the IMU (the airdata_delay finding in run.json): the verdict says to
    correct the air data before adding terms; without the finding it says nothing of it."""
    import json

    from aerosid.cli.run_summary import verdict_lines

    doc = {"message": "Nothing significant is missing: no candidate effect passes the rule.", "recommended": None,
           "effects": [], "lookalikes": []}
    (tmp_path / "diagnosis.json").write_text(json.dumps(doc))
    (tmp_path / "run.json").write_text(json.dumps({"findings": [{"kind": "nis_mean"}]}))
    assert "first the air data" not in "\n".join(verdict_lines(tmp_path))
    (tmp_path / "run.json").write_text(json.dumps({"findings": [{"kind": "nis_mean"}, {"kind": "airdata_delay"}]}))
    lines = verdict_lines(tmp_path)
    assert lines[0].startswith("diagnosis: Nothing significant") and lines[1].startswith("first the air data")
    assert "delay_s" in lines[1] and "vane_position_m" in lines[1]


def test_a_pooled_diagnosis_speaks_of_the_pooled_flights(reference_flight):
    """`aerosid run A B` diagnoses the pooled data: its message must not say "this flight"."""
    import pandas as pd

    vehicle = load_vehicle("seed-rlv")
    one = flight_data_from_truth(reference_flight.truth, MEASURED_NOISE.scaled(0.25), seed=0)
    two = flight_data_from_truth(reference_flight.truth, MEASURED_NOISE.scaled(0.25), seed=1)
    one["flight"], two["flight"] = "m1", "m2"
    single = diagnose(one, vehicle, localisation=False)
    pooled = diagnose(pd.concat([one, two], ignore_index=True), vehicle, localisation=False)
    assert single.n_flights == 1 and "This flight could not" in single.message
    assert pooled.n_flights == 2 and pooled.to_json()["n_flights"] == 2
    assert "this flight" not in pooled.message.lower()
    assert "These 2 pooled flights could not" in pooled.message
