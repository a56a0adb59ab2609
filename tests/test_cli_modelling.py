"""The modelling loop as the engineer sees it (issue 18 items 4 and 6): `aerosid fit` prints
every term's estimate, sigma, t and p and warns on non-significant terms; specs add and
remove terms relative to the parent; every diagnosis candidate is addable by name; the
coefficient tables are SI per radian unless --per-degree; `aerosid run` ends with the
samples and Mach window regressed and the diagnosis verdict; progress goes through a plain
callback (the core imports no CLI library)."""
from __future__ import annotations

import io
import json
import math
import re
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from aerosid.cli.modelling import fit as fit_cmd
from aerosid.diagnosis import default_candidates
from aerosid.diagnosis.synthetic import MEASURED_NOISE, flight_data_from_truth
from aerosid.modelling.effects import CATALOGUE
from aerosid.identification.identify import format_table
from aerosid.modelling.model_specs import apply_spec, paste_lines, read_spec
from aerosid.modelling.models import (ModelSpecError, default_models, load_models, models_to_toml, parse_term,
                            signals_from_flight_data)
from aerosid.modelling.versions import fit_version, history, models_from_spec

MACH = ["--mach-half-width", "1.0"]  # the 20 s flight spans Mach 12.75..13.1


@pytest.fixture(scope="module")
def flight_data():
    """20 s of seed-rlv with control_alpha hidden in Cm, errors at a quarter of the real pipeline's."""
    from aerosid.simulation import load_case, simulate

    flight = simulate(load_case("seed-rlv", duration_s=20.0), seed=0)
    fd = flight_data_from_truth(flight.truth, MEASURED_NOISE.scaled(0.25), seed=0)
    tr = flight.truth
    fd["Cm"] = fd["Cm"] + CATALOGUE["control_alpha"].value * tr["alpha_rad"].to_numpy() * tr["delta_p_rad"].to_numpy() / 2
    return fd


@pytest.fixture
def run_dir(tmp_path, flight_data):
    d = tmp_path / "run"
    d.mkdir()
    flight_data.to_parquet(d / "flight_data.parquet", index=False)
    return d


def _spec(tmp_path, text, name="spec.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def _fit(run_dir, *args):
    result = CliRunner().invoke(fit_cmd, [str(run_dir), *MACH, *args])
    assert result.exit_code == 0, result.output
    return result.output


def _term_line(output: str, coefficient: str) -> list[str]:
    line = next(li for li in output.splitlines() if re.match(rf"^\s+\+?{coefficient}\s", li))
    return line.split()


# --------------------------------------------------------------------------- fit prints the terms
def test_fit_prints_every_terms_estimate_sigma_t_and_p(run_dir, tmp_path):
    out = _fit(run_dir, "--model", str(_spec(tmp_path, '[Cm]\nadd = ["control_alpha"]\n')))
    table = pd.read_parquet(history(run_dir).latest.path / "coefficients.parquet")
    shown = 0
    for _, row in table[table["identifiable"]].iterrows():
        cells = _term_line(out, row["coefficient"])
        assert cells[0].lstrip("+") == row["coefficient"]
        assert cells[1] == format(row["estimate"], ".5g")
        assert cells[2] == format(row["std_error"], ".3g")
        assert cells[3] == format(row["t_value"], ".3g")
        assert cells[4] == format(row["p_value"], ".2g")
        assert cells[5] == ("yes" if row["p_value"] < 1e-3 else "NO")
        assert math.isclose(row["t_value"], row["estimate"] / row["std_error"], rel_tol=1e-9)
        shown += 1
    assert shown == int(table["identifiable"].sum()) == 4 + 3 + 4  # Cm (with the new term), Cn, Cl
    # the new term is marked, and the hidden effect is found at its true size
    assert _term_line(out, "Cm_alpha_delta_p")[0] == "+Cm_alpha_delta_p"
    est = table.set_index("coefficient").loc["Cm_alpha_delta_p"]
    assert abs(est["estimate"] - CATALOGUE["control_alpha"].value) < 3 * est["std_error"]
    # CN and CY are identities (alpha, beta inverted from them): said so, no numbers
    assert re.search(r"^\[CN\].*an identity", out, re.M) and not re.search(r"^\s+CN_alpha\s", out, re.M)


def test_a_non_significant_term_gets_the_warning_and_only_those_do(run_dir, tmp_path):
    out = _fit(run_dir, "--model", str(_spec(tmp_path, '[Cm]\nadd = ["control_alpha", "Cm_a3 = alpha**3"]\n')))
    table = pd.read_parquet(history(run_dir).latest.path / "coefficients.parquet").set_index("coefficient")
    a3 = table.loc["Cm_a3"]
    assert a3["p_value"] >= 1e-3  # alpha**3 is not in this flight (and nearly collinear with alpha)
    assert (f"warning: Cm_a3: t = {a3['t_value']:.2g}, not significant at p < 0.001 (p = {a3['p_value']:.2g}) — "
            'consider removing it ([Cm] remove = ["Cm_a3"])') in out
    warned = set(re.findall(r"^warning: (\w+): t = ", out, re.M))
    expected = {c for c, r in table.iterrows() if r["identifiable"] and r["p_value"] >= 1e-3 and r["expression"] != "1"}
    assert warned == expected and "Cm_alpha_delta_p" not in warned


# --------------------------------------------------------------------------- add / remove / terms
def test_add_and_remove_keep_the_parents_other_terms(run_dir, tmp_path):
    _fit(run_dir, "--model", str(_spec(tmp_path, '[Cm]\nadd = ["control_alpha", "Cm_a3 = alpha**3"]\n')))
    h = history(run_dir)
    v2 = h.latest
    assert v2.id == "v002" and v2.models["Cm"].names == ("Cm_0", "Cm_alpha", "Cm_delta_p", "Cm_alpha_delta_p", "Cm_a3")
    out = _fit(run_dir, "--parent", "v002", "--model",
               str(_spec(tmp_path, '[Cm]\nremove = ["Cm_a3"]\nadd = ["mach_cm0"]\n[Cl]\nadd = ["roll_damping"]\n',
                         "second.toml")))
    v3 = history(run_dir).latest
    assert v3.parent == "v002"
    assert v3.models["Cm"].names == ("Cm_0", "Cm_alpha", "Cm_delta_p", "Cm_alpha_delta_p", "Cm_0_mach")
    assert v3.models["Cl"].names == v2.models["Cl"].names + ("Cl_p",)
    for ch in ("CN", "CY", "Cn"):
        assert v3.models[ch].terms == v2.models[ch].terms
    assert "changes vs v002: Cm: +Cm_0_mach = (mach - 12.4), -Cm_a3; Cl: +Cl_p = p_hat" in out
    assert "warning: [" not in out  # add/remove drop nothing


def test_terms_replacing_the_model_says_which_parent_terms_it_drops(run_dir, tmp_path):
    _fit(run_dir)  # v001
    out = _fit(run_dir, "--model", str(_spec(tmp_path, '[Cm]\nterms = ["Cm_0 = 1", "mach_cm_alpha"]\n')))
    assert ("warning: [Cm] terms = [...] replaces the parent's model and drops Cm_alpha, Cm_delta_p; to keep them "
            "and only add terms, write add = [...] instead of terms = [...]") in out
    assert history(run_dir).latest.models["Cm"].names == ("Cm_0", "Cm_alpha_mach")


@pytest.mark.parametrize("text, fragment", [
    ('[Cm]\nremove = ["Cm_q"]', "'Cm_q' is not a term of the model (its terms: Cm_0 = 1, Cm_alpha = alpha"),
    ('[Cm]\nadd = ["Cm_alpha = alpha**2"]', "coefficient Cm_alpha is already in the model"),
    ('[Cm]\nremove = ["Cm_0", "Cm_alpha", "Cm_delta_p"]', "without terms"),
    ('[Cm]\nadds = ["control_alpha"]', "unknown key(s) ['adds']"),
    ('[Cm]\nadd = "control_alpha"', "needs add = ["),
    ('[Cm]\nadd = ["roll_damping"]', "belongs to channel Cl"),
    ('[Cm]\nadd = ["no_such_effect"]', "mach_cm0"),  # the error lists every name a spec takes
])
def test_bad_add_remove_is_refused_naming_file_channel_and_term(tmp_path, text, fragment):
    path = _spec(tmp_path, text)
    with pytest.raises(ModelSpecError) as err:
        read_spec(path, default_models())
    assert str(path) in str(err.value) and "[Cm]" in str(err.value) and fragment in str(err.value)


def test_adding_a_term_the_parent_has_changes_nothing_and_says_so():
    base = default_models()
    base["Cm"] = base["Cm"].with_term(parse_term("control_alpha", "Cm"))
    res = apply_spec({"Cm": {"add": ["control_alpha"]}}, base)
    assert res.models["Cm"] == base["Cm"]
    assert res.warnings() == ["note: [Cm] add: control_alpha already in the parent's model (nothing added)"]


# --------------------------------------------------------------------------- every candidate is addable
@pytest.mark.parametrize("mach_reference, vehicle_class", [(12.4, "finned"), (0.3, "aircraft")])
def test_every_candidate_the_diagnosis_can_name_is_addable_by_name(flight_data, tmp_path, mach_reference,
                                                                  vehicle_class):
    sig = signals_from_flight_data(flight_data, 0.5)
    candidates = default_candidates(mach_reference, vehicle_class)
    assert len(candidates) >= 13
    for c in candidates:
        assert c.spec_term == c.name  # what the diagnosis prints to paste
        res = apply_spec({c.channel: {"add": [c.spec_term]}}, default_models(), mach_reference=mach_reference)
        term = res.models[c.channel].terms[-1]
        assert (term.coefficient, term.expression, term.effect) == (c.coefficient, c.term, c.name)
        assert res.models[c.channel].names[:-1] == default_models()[c.channel].names  # nothing dropped
        x = res.models[c.channel].regressors(sig)[c.coefficient].to_numpy()
        np.testing.assert_allclose(x, c.regressor(sig))
        # stored and read back (spec.toml of a version): the same term, whatever the reference Mach
        path = tmp_path / f"{c.name}.toml"
        path.write_text(models_to_toml(res.models))
        back = load_models(path, base={})[c.channel].terms[-1]
        assert (back.coefficient, back.expression) == (c.coefficient, c.term)


def test_every_candidate_fits_as_a_new_version(run_dir, tmp_path):
    for c in default_candidates():
        spec = _spec(tmp_path, paste_lines(c.channel, c.spec_term) + "\n", f"{c.name}.toml")
        v = fit_version(run_dir, models_from_spec(spec, run_dir, "v001" if history(run_dir).versions else None),
                        parent="v001" if history(run_dir).versions else None, mach_half_width=1.0)
        coef = v.metrics["channels"][c.channel]["coefficients"][c.coefficient]
        assert coef["std_error"] is not None and coef["std_error"] > 0, c.name
    assert len(history(run_dir)) == 1 + len(default_candidates())


def test_the_diagnosis_message_ends_with_the_lines_to_paste(flight_data):
    from aerosid.diagnosis import diagnose
    from aerosid.vehicles.vehicle import load_vehicle

    d = diagnose(flight_data, load_vehicle("seed-rlv"), mach_half_width=1.0)
    # the look-alikes are compared first (aerosid.diagnosis.lookalikes); the message still ends
    # with the lines that add the recommended term
    assert d.recommended == "control_alpha"
    assert d.message.endswith('\n\n[Cm]\nadd = ["control_alpha"]')
    pasted = apply_spec(__import__("tomllib").loads(d.message.rsplit("\n\n", 1)[1]), default_models())
    assert pasted.models["Cm"].names[-1] == "Cm_alpha_delta_p" and len(pasted.models["Cm"].terms) == 4


# --------------------------------------------------------------------------- units
def test_per_degree_converts_by_pi_over_180_per_power_of_angle(run_dir, tmp_path):
    from aerosid.identification.coefficient_units import angle_power, per_degree_factor

    assert per_degree_factor("alpha") == math.pi / 180
    assert per_degree_factor("q_hat") == math.pi / 180  # damping like slopes
    assert per_degree_factor("delta_p/2") == math.pi / 180  # per degree pair
    assert per_degree_factor("alpha*abs(alpha)") == (math.pi / 180) ** 2
    assert per_degree_factor("alpha_r**2*sin(4*phi_r)") == (math.pi / 180) ** 2
    assert per_degree_factor("alpha*(mach - 12.4)") == math.pi / 180
    assert per_degree_factor("cos(4*phi_r)") == per_degree_factor("1") == per_degree_factor("mach - 12.4") == 1.0
    assert angle_power("alpha + mach") is None and per_degree_factor("alpha + mach") == 1.0

    spec = str(_spec(tmp_path, '[Cm]\nadd = ["control_alpha", "pitch_damping"]\n'))
    rad = _fit(run_dir, "--model", spec)
    deg = _fit(run_dir, "--model", spec, "--per-degree")
    assert "SI per radian" in rad and "PER DEGREE (--per-degree)" in deg and "PER DEGREE" not in rad
    table = pd.read_parquet(history(run_dir).latest.path / "coefficients.parquet")
    for _, row in table[table["identifiable"]].iterrows():
        k = per_degree_factor(row["expression"])
        assert _term_line(rad, row["coefficient"])[1] == format(row["estimate"], ".5g")
        assert _term_line(deg, row["coefficient"])[1] == format(row["estimate"] * k, ".5g")
        assert _term_line(deg, row["coefficient"])[2] == format(row["std_error"] * k, ".3g")
        assert _term_line(deg, row["coefficient"])[3] == _term_line(rad, row["coefficient"])[3]  # t is unitless
    assert _term_line(deg, "Cm_q")[-1] == "/deg" and _term_line(rad, "Cm_alpha_delta_p")[-1] == "/rad^2"
    # the run's coefficient table: per radian by default, slopes and damping alike
    text_rad, text_deg = format_table(table), format_table(table, per_degree=True)
    assert "SI per radian" in text_rad.splitlines()[0] and "PER DEGREE" in text_deg.splitlines()[0]
    for name in ("Cm_alpha", "Cm_q", "Cl_delta_r"):
        row = table.set_index("coefficient").loc[name]
        assert _term_line(text_rad, name)[2] == format(row["estimate"], ".5g")
        assert _term_line(text_deg, name)[2] == format(row["estimate"] * math.pi / 180, ".5g")


# --------------------------------------------------------------------------- what `aerosid run` says
def test_run_ends_with_the_samples_and_mach_window_and_the_verdict(run_dir, flight_data):
    from aerosid.cli.run_summary import run_outcome_lines

    mach = flight_data["mach"].to_numpy()
    inside = np.abs(mach - 12.4) <= 0.5
    doc = {"message": "Most likely missing: control_alpha in Cm (fin effectiveness). It explains 74 % of it.\n\n"
                      '[Cm]\nadd = ["control_alpha"]',
           "effects": [{"name": "alpha_nonlinearity", "channel": "Cm", "spec_term": "alpha_nonlinearity",
                        "significant": False},
                       {"name": "control_alpha", "channel": "Cm", "spec_term": "control_alpha", "significant": True}]}
    (run_dir / "diagnosis.json").write_text(json.dumps(doc))
    lines = run_outcome_lines(run_dir, 0.5)
    n = f"{int(inside.sum()):,}".replace(",", " ")
    total = f"{len(mach):,}".replace(",", " ")
    assert lines[0] == (f"regressed {n} of {total} samples, Mach {mach[inside].min():.2f}–{mach[inside].max():.2f} "
                        "(|M − 12.4| ≤ 0.5, --mach-half-width)")
    assert lines[1] == "diagnosis: Most likely missing: control_alpha in Cm (fin effectiveness)."
    assert lines[3:5] == ["  [Cm]", '  add = ["control_alpha"]']
    # the contract's `recommended` (null: nothing to add) wins over the significant flags
    (run_dir / "diagnosis.json").write_text(json.dumps({**doc, "recommended": None,
                                                        "message": "Nothing significant is missing: no. Strongest"}))
    lines = run_outcome_lines(run_dir, 0.5)
    assert lines[1] == "diagnosis: Nothing significant is missing: no." and not any("add = [" in li for li in lines)
    # nothing from the catalogue, but the localisation finds a term: its lines (with its main effect) to paste,
    # the strongest significant one
    loc = {"Cn": [{"id": "trend:Cn_beta:alpha", "channel": "Cn", "variable": "alpha", "significant": True,
                   "t_value": 5.4, "spec_line": "Cn_beta_alpha = beta*(alpha + 0.0066)",
                   "evidence": {"main_effect": "Cn_alpha"}},
                  {"id": "shape:Cn:beta", "channel": "Cn", "variable": "beta", "significant": False, "t_value": 9.0,
                   "spec_line": "Cn_beta2 = beta**2", "evidence": {}}],
           "Cl": [{"id": "shape:Cl:beta", "channel": "Cl", "variable": "beta", "significant": True, "t_value": -3.9,
                   "spec_line": "Cl_abs_beta = abs(beta)", "evidence": {}}]}
    (run_dir / "diagnosis.json").write_text(json.dumps({**doc, "recommended": None, "localisation": loc,
                                                        "message": "No catalogue effect is missing, but no."}))
    lines = run_outcome_lines(run_dir, 0.5)
    assert "the localisation's strongest term (Cn: trend:Cn_beta:alpha)" in lines[2]
    assert lines[3:5] == ["  [Cn]", '  add = ["Cn_beta_alpha = beta*(alpha + 0.0066)", "Cn_alpha = alpha"]']


# --------------------------------------------------------------------------- progress
def test_progress_without_a_terminal_writes_one_line_per_stage():
    from aerosid.cli.progress import RunProgress, StageProgress

    stream = io.StringIO()
    with StageProgress("simulate", stream=stream) as progress:
        for k in range(50):
            progress("integrate", k / 49)
        progress("write", 0.0)
    lines = stream.getvalue().splitlines()
    assert len(lines) == 2 and lines[0].endswith("] integrate") and lines[1].endswith("] write")

    stream = io.StringIO()
    with RunProgress(stream=stream) as progress:
        for ev in ("preprocess: f", "plan: run, 2 segment(s)", "smooth: f segment s0", "smooth: f segment s1"):
            progress(ev, 0.0)
            progress(ev, 1.0)
    assert progress._total == RunProgress.FIXED_STAGES + 2
    assert [li.split("] ")[1] for li in stream.getvalue().splitlines()] == [
        "preprocess: f", "plan: run, 2 segment(s)", "smooth: f segment s0", "smooth: f segment s1"]


def test_the_simulator_reports_progress_through_a_plain_callback():
    from aerosid.simulation import load_case, simulate

    seen = []
    simulate(load_case("seed-rlv", duration_s=2.0), seed=0, progress=lambda stage, f: seen.append((stage, f)))
    fractions = [f for s, f in seen if s == "integrate"]
    assert fractions[0] == 0.0 and fractions == sorted(fractions) and 0.9 < fractions[-1] < 1.0


def test_the_tasks_progress_registry_reaches_listeners_and_ignores_broken_ones():
    from tasks.progress import emit, listening

    got = []

    def broken(stage, fraction):
        raise RuntimeError("a display error")

    with listening(broken), listening(lambda s, f: got.append((s, f))):
        emit("smooth: f segment s0", 0.0)
    emit("after", 1.0)
    assert got == [("smooth: f segment s0", 0.0)]


def test_the_core_imports_no_cli_library():
    import pkgutil

    import aerosid

    core = [m.name for m in pkgutil.walk_packages(aerosid.__path__, "aerosid.")
            if not m.name.split(".")[1].startswith("cli")]
    code = ("import importlib, sys\n" + "".join(f"importlib.import_module({m!r})\n" for m in core)
            + "print(sorted(m for m in ('rich', 'click') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout


def test_the_readme_specs_apply_to_the_version_after_control_alpha():
    import tomllib
    from pathlib import Path

    text = (Path(__file__).parents[1] / "README.md").read_text()
    blocks = re.findall(r"```toml\n(.*?)```", text, re.S)
    assert len(blocks) >= 2
    parent = default_models()
    parent["Cm"] = parent["Cm"].with_term(parse_term("control_alpha", "Cm"))
    first = apply_spec(tomllib.loads(blocks[0]), default_models())
    assert first.models["Cm"] == parent["Cm"] and not first.warnings()
    second = apply_spec(tomllib.loads(blocks[1]), parent)
    assert second.models["Cm"].names == ("Cm_0", "Cm_alpha", "Cm_delta_p", "Cm_a3", "Cm_q")
    assert second.models["Cl"].names[-1] == "Cl_p" and "drops Cl_cos4phi" in second.warnings()[0]


def test_diagnose_with_a_replacing_spec_names_the_dropped_terms(run_dir, tmp_path):
    from aerosid.cli.modelling import diagnose as diagnose_cmd

    spec = _spec(tmp_path, '[Cl]\nterms = ["Cl_0 = 1", "Cl_delta_r = delta_r"]\n')
    result = CliRunner().invoke(diagnose_cmd, [str(run_dir), "--model", str(spec), "--quiet", *MACH])
    assert result.exit_code == 0, result.output
    assert "warning: [Cl] terms = [...] replaces the parent's model and drops Cl_alpha_r, Cl_cos4phi" in result.output
    assert json.loads((run_dir / "diagnosis.json").read_text())["channels"]["Cl"]["terms"] == ["Cl_0", "Cl_delta_r"]


def test_a_candidate_added_by_name_is_removed_by_name_after_a_round_trip_to_disk(tmp_path):
    added = apply_spec({"Cm": {"add": ["mach_cm0"]}}, default_models()).models
    path = tmp_path / "spec.toml"
    path.write_text(models_to_toml(added))
    stored = load_models(path, base={})
    assert stored["Cm"].terms[-1].effect is None  # stored as its expression
    assert apply_spec({"Cm": {"remove": ["mach_cm0"]}}, stored).models["Cm"] == default_models()["Cm"]
