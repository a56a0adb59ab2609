"""The report shows one model version everywhere (the latest, or the one asked for),
draws the versions as a tree, marks the identity channels, plots partial residuals,
and renders the diagnosis fields other stages add (recommended, floor, look-alikes,
localisation) escaped and only when present.

Uses the shared run folder of tests/test_report.py (v001 = default models, v002 =
+ pitch damping, diagnosis of v002)."""
from __future__ import annotations

import json
import math
import re
import shutil

import numpy as np
import pandas as pd
import pytest

from tests.test_report import MODELLED, assert_self_contained, assert_well_formed, report_run  # noqa: F401

pytestmark = pytest.mark.prefect


def _coef_table(doc: str) -> str:
    return doc[doc.index('<table id="coefficients"'):].split("</table>")[0]


def _cm_alpha_per_degree(run_dir, version: str) -> str:
    table = pd.read_parquet(run_dir / "models" / version / "coefficients.parquet").set_index("coefficient")
    return f'<td class="n">{table.loc["Cm_alpha", "estimate"] * math.pi / 180:.5g}</td>'


def test_the_chosen_version_is_shown_everywhere_and_a_stale_diagnosis_says_so(report_run):
    from aerosid.report import build_report
    from aerosid.modelling.versions import VersionError

    run_dir, _, _ = report_run
    a1, a2 = _cm_alpha_per_degree(run_dir, "v001"), _cm_alpha_per_degree(run_dir, "v002")
    assert a1 != a2  # adding pitch damping moves Cm_alpha: the table tells the versions apart
    latest = build_report(run_dir)
    assert a2 in _coef_table(latest) and "<td>Cm_q</td>" in _coef_table(latest)
    assert 'id="diagnosis-stale"' not in latest
    old = build_report(run_dir, version="v001")
    assert_well_formed(old)
    coef = _coef_table(old)
    assert a1 in coef and a2 not in coef and "<td>Cm_q</td>" not in coef
    assert "model version v001 (chosen; the latest is v002)" in old
    # measured vs model and the residual plots are of v001 too
    assert 'aria-label="Cm: measured vs model v001' in old and 'aria-label="Cm, model v001: partial residuals' in old
    # the diagnosis is of v002: said, with the command that diagnoses v001
    assert 'id="diagnosis-stale"' in old and "aerosid diagnose RUN_DIR --version v001" in old
    assert "◀ shown" in old.split('id="versions-table"')[1].split("</table>")[0].split("v001")[1].split("</tr>")[0]
    with pytest.raises(VersionError, match="v009.*v001, v002"):
        build_report(run_dir, version="v009")


def test_versions_are_a_tree_siblings_are_not_joined(report_run, tmp_path):
    from aerosid.modelling.models import default_models, parse_term
    from aerosid.report import build_report
    from aerosid.report.sections_versions import tree_edges, tree_order
    from aerosid.modelling.versions import fit_version, history

    run_dir, _, _ = report_run
    work = tmp_path / "run"
    shutil.copytree(run_dir, work)
    models = default_models()
    models["Cm"] = models["Cm"].with_term(parse_term("Cm_aa = alpha*abs(alpha)", "Cm"))
    v3 = fit_version(work, models, parent="v001", note="sibling of v002")  # v001 -> v002, v001 -> v003
    v4 = fit_version(work, {**models, "Cm": models["Cm"].with_term(parse_term("pitch_damping", "Cm"))},
                     parent="v002", note="child of v002")
    h = history(work)
    assert (v3.id, v4.id) == ("v003", "v004")
    assert [(p.id, c.id) for p, c in tree_edges(h.versions)] == [("v001", "v002"), ("v001", "v003"),
                                                                  ("v002", "v004")]  # no v002 - v003 line
    assert [(v.id, d) for v, d in tree_order(h.versions)] == [("v001", 0), ("v002", 1), ("v004", 2), ("v003", 1)]
    doc = build_report(work)
    rows = re.findall(r"<tr><td>(.*?)</td>", doc.split('id="versions-table"')[1].split("</table>")[0])
    assert [re.sub(r"<.*?>|&nbsp;|└─|◀ shown|\s", "", r) for r in rows] == ["v001", "v002", "v004", "v003"]
    assert "model version v004 (the latest)" in doc


def test_identity_channels_are_marked_and_left_out(report_run):
    from aerosid.report import build_report

    run_dir, diag, _ = report_run
    assert diag.identities == ("CN", "CY")
    doc = build_report(run_dir, diagnosis=diag)
    coef = _coef_table(doc)
    for ch in ("CN", "CY"):
        assert re.search(rf'id="coef-{ch}">{ch}: identity by construction', coef)
        assert f'id="res-{ch}"' not in doc and f'aria-label="{ch}: measured vs model' not in doc
    for ch in MODELLED:
        assert f'id="res-{ch}"' in doc
    assert 'id="diagnosis-identities"' in doc and "Left out: CN, CY" in doc
    flagged = doc.split('id="regimes-flagged"')[1].split("</table>")[0] if 'id="regimes-flagged"' in doc else ""
    assert "<td>CN</td>" not in flagged and "<td>CY</td>" not in flagged


def test_plotted_model_is_the_versions_coefficients_and_least_squares_bounds_it(report_run):
    """The series behind the comparison and partial-residual plots: the model is the table's
    estimates times their regressors; the least-squares fit minimises the residual, so the
    plotted residual (of the possibly angle-noise-corrected estimates) cannot be smaller."""
    from aerosid.report.rundir import _Run, shown_model
    from aerosid.report.sections_model import model_series

    run_dir, _, _ = report_run
    run = _Run.load(run_dir)
    for version in ("v001", "v002"):
        shown = shown_model(run, version)
        s = model_series(run, shown)
        table = shown.table
        for ch in MODELLED:
            c = s["channels"][ch]
            names = [t[0] for t in c["terms"]]
            assert names == list(table.loc[table["channel"] == ch, "coefficient"])
            assert np.allclose(sum(t[2] * t[3] for t in c["terms"]), c["model"])
            assert np.allclose(c["measured"] - c["model"], c["residual"])
            rms = float(np.sqrt(np.mean(c["residual"] ** 2)))
            # above by a margin: SIMEX-corrected estimates leave the least-squares optimum by their
            # correction (Cn of this flight: 1.12x)
            assert c["rms"] * (1 - 1e-9) <= rms <= 1.3 * c["rms"], (version, ch, rms, c["rms"])
        assert ("Cm_q" in [t[0] for t in s["channels"]["Cm"]["terms"]]) == (version == "v002")


def test_fields_added_by_other_stages_render_escaped_and_only_when_present(report_run):
    from aerosid.report import build_report

    run_dir, _, _ = report_run
    doc = json.loads((run_dir / "diagnosis.json").read_text())
    for key in ("recommended", "floor", "lookalikes", "localisation"):  # a diagnosis written before them
        doc.pop(key, None)
    plain = build_report(run_dir, diagnosis=doc)
    for anchor in ('id="diagnosis-recommended"', 'id="floor-table"', 'id="lookalikes"', 'id="localisation"'):
        assert anchor not in plain
    doc.update({
        "recommended": "control_alpha<script>",
        "floor": {"Cm": {"residual_rms": 7.2e-4, "floor_rms": 6.0e-4, "excess_rms": 3.98e-4,
                         "coefficient_floor_rms": 3.6e-4, "angle_floor_rms": 4.8e-4},
                  "Cn": {"residual_rms": None}},
        "lookalikes": {"candidates": [{"name": "alpha_nonlinearity", "heldout_rms": 1.23e-4, "verdict": "<b>no</b>"},
                                      {"name": "control_alpha", "heldout_rms": 1.01e-4}],
                       "decided": True, "manoeuvre": None},
        "localisation": {"Cm": [{"shape": "alpha**3", "expression": "Cm_a3 = alpha**3", "score": float("inf")}]},
    })
    html = build_report(run_dir, diagnosis=doc)
    assert_self_contained(html)
    assert_well_formed(html)
    assert "could not be rendered" not in html
    assert "Recommended: <b>control_alpha&lt;script&gt;</b>" in html and "<script" not in html.lower()
    floor = html.split('id="floor-table"')[1].split("</table>")[0]
    assert "0.00072" in floor and "0.0006" in floor and "55 %" in floor  # excess / residual = 3.98 / 7.2
    assert "0.00036" in floor and "0.00048" in floor  # the floor's two parts
    look = html.split('id="lookalikes"')[1]
    assert "alpha_nonlinearity" in look and "&lt;b&gt;no&lt;/b&gt;" in look and "0.000123" in look
    assert "Cm_a3 = alpha**3" in html.split('id="localisation"')[1]
    doc["recommended"] = None
    assert "No recommendation: the evidence does not separate" in build_report(run_dir, diagnosis=doc)
