"""The HTML report (aerosid.report): self-contained, complete, escaped, and robust to
missing pieces (no diagnosis, no versions, a failed segment, an empty folder).

The run folder is made once per session by the real flow (process_flight on a
30 s seed-rlv flight) plus two model versions and a diagnosis; tests that change
it work on a copy.  tests/test_report_browser.py uses the same folder.
"""
from __future__ import annotations

import json
import math
import re
import shutil
from html.parser import HTMLParser
from pathlib import Path

import pandas as pd
import pytest

pytestmark = pytest.mark.prefect

CHANNELS = ("CN", "Cm", "CY", "Cn", "Cl")
#: C_N and C_Y are identities by construction for seed-rlv (alpha, beta inverted from them)
MODELLED = ("Cm", "Cn", "Cl")
SECTIONS = ("run", "preprocessing", "segments", "coefficients", "comparison", "residuals", "diagnosis", "versions",
            "audit")
_CACHE: dict = {}


def _make_run(root: Path):
    from aerosid.diagnosis import diagnose
    from aerosid.io import write_json_atomic
    from aerosid.modelling.models import default_models, parse_term
    from aerosid.simulation import load_case, simulate
    from aerosid.vehicles.vehicle import load_vehicle
    from aerosid.modelling.versions import fit_version, latest_models, read_flight_data
    from flows.pipeline import process_flight

    simulate(load_case("seed-rlv", duration_s=30.0), seed=0).write(root / "flight")
    run_dir = root / "run"
    summary = process_flight(str(root / "flight" / "telemetry.parquet"), str(run_dir))
    assert summary["status"] in ("ok", "ok with findings", "partial"), summary["segments_failed"]
    assert [p.name for p in (run_dir / "models").iterdir()] == ["v001"]  # the run stores the default models
    models = default_models()
    models["Cm"] = models["Cm"].with_term(parse_term("pitch_damping", "Cm"))
    assert fit_version(run_dir, models, note="add pitch damping <b>").id == "v002"
    diag = diagnose(read_flight_data(run_dir), load_vehicle("seed-rlv"), latest_models(run_dir))
    doc = diag.to_json()
    doc["model"] = "v002"
    write_json_atomic(doc, run_dir / "diagnosis.json")
    truth = json.loads((root / "flight" / "truth.json").read_text())
    return run_dir, diag, truth


@pytest.fixture(scope="session")
def report_run(prefect_harness, tmp_path_factory):
    """(run folder, Diagnosis, truth.json dict); built once per session (shared with the browser test)."""
    if "run" not in _CACHE:
        _CACHE["run"] = _make_run(tmp_path_factory.mktemp("report-run"))
    return _CACHE["run"]


@pytest.fixture
def run_copy(report_run, tmp_path):
    run_dir, diag, truth = report_run
    work = tmp_path / "run"
    shutil.copytree(run_dir, work)
    return work, diag, truth


def ok_segments(run_dir: Path) -> list[str]:
    return sorted(p.parent.name for p in (run_dir / "segments").glob("*/smoothed.parquet"))


def n_plots(run_dir: Path, *, segments: int | None = None, regimes: bool = True, versions: bool = True) -> int:
    """Plots in a report: one per smoothed segment, per modelled channel a measured-vs-model and a
    residuals figure (the identities C_N, C_Y have neither), the regime map, the version tree."""
    segs = len(ok_segments(run_dir)) if segments is None else segments
    return segs + 2 * len(MODELLED) + int(regimes) + int(versions)


def assert_self_contained(doc: str) -> None:
    low = doc.lower()
    for bad in ("http://", "https://", "//cdn", "<link", "<script", "@import", "<iframe", "<object", "<embed"):
        assert bad not in low, f"{bad!r} in the report"
    for m in re.finditer(r"\b(src|href)\s*=\s*[\"']?([^\"' >]*)", doc, flags=re.I):
        attr, value = m.group(1).lower(), m.group(2)
        ok = value.startswith("data:") or (attr == "href" and value.startswith("#"))
        assert ok, f"external reference {m.group(0)!r}"
    for m in re.finditer(r"url\(([^)]*)\)", doc):
        assert m.group(1).startswith("#"), f"external url({m.group(1)})"


class _Checker(HTMLParser):
    """Every non-void element closed, in order (a cheap well-formedness check)."""

    VOID = {"meta", "br", "hr", "img", "input", "link", "col", "wbr", "source", "area", "base"}

    def __init__(self):
        super().__init__()
        self.stack: list[str] = []
        self.errors: list[str] = []

    def handle_starttag(self, tag, attrs):
        if tag not in self.VOID:
            self.stack.append(tag)

    def handle_startendtag(self, tag, attrs):
        pass

    def handle_endtag(self, tag):
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes <{self.stack[-1] if self.stack else None}>")
            if tag in self.stack:
                while self.stack.pop() != tag:
                    pass
        else:
            self.stack.pop()


def assert_well_formed(doc: str) -> None:
    assert doc.startswith("<!DOCTYPE html>")
    checker = _Checker()
    checker.feed(doc)
    checker.close()
    assert checker.errors == [] and checker.stack == [], (checker.errors[:5], checker.stack)


def test_full_report_is_self_contained_and_complete(run_copy):
    from aerosid.report import write_report

    run_dir, diag, truth = run_copy
    path = write_report(run_dir, diagnosis=diag, truth=truth)
    assert path == run_dir / "report.html" and path.is_file()
    doc = path.read_text()
    assert_self_contained(doc)
    assert_well_formed(doc)
    assert "could not be rendered" not in doc
    for sid in SECTIONS:
        assert f'<section id="{sid}">' in doc
    # plots: one per smoothed segment, two per modelled channel, the regime map, the version tree
    segs = ok_segments(run_dir)
    assert segs
    assert doc.count("<svg") == doc.count("</svg>") == n_plots(run_dir)
    assert "<text" not in doc  # text drawn as paths: no font needed
    # run facts: telemetry SHA-256 from the ledger, code version
    ledger = [json.loads(x) for x in (run_dir / "ledger.jsonl").read_text().splitlines()]
    pre = next(r for r in ledger if r["stage"] == "preprocess")
    assert pre["inputs"][0]["sha256"] in doc and pre["code_version"] in doc
    # preprocessing counts from the Parquet metadata
    assert 'id="preprocess-flags"' in doc and "MISSING_ROW" in doc and "Longest all-channel gap" in doc
    # NIS table per segment, seed Table 2 style
    assert doc.count("seed Table 2 style") == len(segs) and "NIS smoother" in doc
    # the coefficients table of the latest version (v002): every coefficient, per degree for angle
    # slopes, truth and error
    table = pd.read_parquet(run_dir / "models" / "v002" / "coefficients.parquet")
    assert "Cm_q" in set(table["coefficient"]) and "Model shown: model version v002 (the latest)" in doc
    coef_html = doc[doc.index('<table id="coefficients"'):]
    coef_html = coef_html[:coef_html.index("</table>")]
    for name in table["coefficient"]:
        assert f"<td>{name}</td>" in coef_html
    cm_alpha = table.set_index("coefficient").loc["Cm_alpha"]  # (C_N of seed-rlv is an identity: no number)
    assert format(cm_alpha["estimate"] * math.pi / 180, ".5g") in coef_html
    assert format(truth["coefficients"]["CN_alpha"] * math.pi / 180, ".5g") in coef_html
    assert "per degree" in doc and "deg pair" in coef_html and "error %" in coef_html
    for ch in CHANNELS:
        assert f'id="coef-{ch}"' in coef_html and f'id="cmp-{ch}"' in doc
    # the diagnosis: message, ranked effects, windows, the full regime map, whiteness
    assert 'id="diagnosis-message"' in doc and 'id="effects-table"' in doc
    assert doc.count("<tr class=\"why\">") == len(diag.effects)
    assert 'id="windows-heat"' in doc and 'id="whiteness-table"' in doc and "Ljung–Box" in doc
    assert doc.count('aria-label="Residual RMS ratio by regime bin') == 1
    heat = doc[doc.index('id="windows-heat"'):].split("</table>")[0]
    assert "<th>Cm</th>" in heat and "<th>CN</th>" not in heat and "<th>CY</th>" not in heat  # identities left out
    assert "model diagnosed: <b id=\"diagnosed-model\">v002</b>" in doc and 'id="diagnosis-stale"' not in doc
    # model versions, the note escaped
    assert 'id="versions-table"' in doc and "v002" in doc and "Cm: +pitch_damping" in doc
    assert "add pitch damping &lt;b&gt;" in doc and "pitch damping <b>" not in doc
    assert 'id="audit-table"' in doc


def test_report_reads_diagnosis_json_when_no_diagnosis_is_given(report_run):
    from aerosid.report import build_report

    run_dir, _, _ = report_run
    doc = build_report(run_dir)
    assert_self_contained(doc)
    assert_well_formed(doc)
    assert "could not be rendered" not in doc
    assert "diagnosis.json" in doc and 'model diagnosed: <b id="diagnosed-model">v002</b>' in doc
    assert 'id="effects-table"' in doc and 'id="whiteness-table"' in doc
    assert 'aria-label="Residual RMS ratio by regime bin' in doc  # diagnosis.json keeps the whole regime map
    assert doc.count("<svg") == n_plots(run_dir)
    assert "truth" not in doc[doc.index('<table id="coefficients"'):].split("</table>")[0]
    # the path of a diagnosis.json works as well (a dict takes the same route)
    assert 'id="effects-table"' in build_report(run_dir, diagnosis=run_dir / "diagnosis.json")


def test_report_survives_missing_diagnosis_and_versions(run_copy):
    from aerosid.report import build_report

    run_dir, _, _ = run_copy
    (run_dir / "diagnosis.json").unlink()
    shutil.rmtree(run_dir / "models")
    doc = build_report(run_dir)
    assert_self_contained(doc)
    assert_well_formed(doc)
    assert "could not be rendered" not in doc
    assert "No diagnosis yet" in doc and "aerosid diagnose" in doc
    assert "No model versions yet" in doc
    # the comparison plots still come from coefficients.parquet
    assert doc.count("<svg") == n_plots(run_dir, regimes=False, versions=False)
    assert "coefficients.parquet (Mach window of the fit)" in doc


def test_flight_id_and_messages_are_escaped(run_copy):
    from aerosid.report import build_report

    run_dir, _, _ = run_copy
    state = json.loads((run_dir / "run.json").read_text())
    state["flight"] = "<script>alert('x')</script>&"
    state["segments_failed"] = [{"segment": "segX", "error": "boom <img src=x onerror=alert(1)>"}]
    state["segments"] = state["segments"] + ["segX"]
    (run_dir / "run.json").write_text(json.dumps(state))
    doc = build_report(run_dir)
    assert "<script" not in doc.lower() and "<img" not in doc.lower()
    assert "&lt;script&gt;alert(&#x27;x&#x27;)&lt;/script&gt;&amp;" in doc
    assert "boom &lt;img src=x onerror=alert(1)&gt;" in doc
    assert_well_formed(doc)


def test_failed_and_missing_segments_are_reported(run_copy):
    from aerosid.report import build_report

    run_dir, _, _ = run_copy
    segs = ok_segments(run_dir)
    (run_dir / "segments" / segs[0] / "smoothed.parquet").unlink()
    doc = build_report(run_dir)
    assert "could not be rendered" not in doc
    assert f"Segment {segs[0]}" in doc and "No smoothed data for this segment" in doc
    assert doc.count("<svg") == n_plots(run_dir, segments=len(segs) - 1)
    state = json.loads((run_dir / "run.json").read_text())
    for failed in state["segments_failed"]:  # a segment whose filter diverged says why
        assert failed["segment"] in doc


def test_minimal_and_empty_folders(report_run, tmp_path):
    from aerosid.report import build_report, write_report

    run_dir, _, _ = report_run
    # only the core's outputs (no run.json, no ledger, no metadata): what the core alone leaves
    minimal = tmp_path / "minimal"
    minimal.mkdir()
    for name in ("flight_data.parquet", "coefficients.parquet"):
        shutil.copy(run_dir / name, minimal / name)
    doc = build_report(minimal)
    assert_self_contained(doc)
    assert_well_formed(doc)
    assert "could not be rendered" not in doc
    assert doc.count("<svg") == n_plots(minimal, segments=0, regimes=False, versions=False)
    assert 'id="coefficients"' in doc
    assert "No preprocessed.parquet" in doc and "No ledger.jsonl" in doc and "No segments" in doc
    # an empty folder: every section says it has nothing, nothing crashes
    empty = tmp_path / "empty"
    empty.mkdir()
    doc = build_report(empty)
    assert_well_formed(doc)
    assert "could not be rendered" not in doc and "<svg" not in doc
    assert "No coefficients.parquet" in doc and "nothing to compare" in doc
    # write_report: atomic, no temporary file left, overwrites
    p1 = write_report(empty)
    p2 = write_report(empty)
    assert p1 == p2 == empty / "report.html"
    assert sorted(x.name for x in empty.iterdir()) == ["report.html"]
    with pytest.raises(FileNotFoundError):
        build_report(tmp_path / "no-such-run")


def test_broken_inputs_are_reported_not_fatal(run_copy):
    from aerosid.report import build_report

    run_dir, _, _ = run_copy
    (run_dir / "diagnosis.json").write_text("{not json")
    (run_dir / "models" / "v002" / "coefficients.parquet").write_bytes(b"not parquet")  # the version shown
    doc = build_report(run_dir)
    assert_well_formed(doc)
    assert "not valid JSON" in doc and "cannot read" in doc
    assert "No diagnosis yet" in doc


def test_scatter_panel_svg_is_compact():
    """The context dots are one embedded image (not one <use> per dot) and coordinates carry
    at most five significant digits: the partial-residual figures made reports of 1.7-2.6 MB."""
    import numpy as np

    from aerosid.report.plots import _figure, _svg, scatter_panel

    rng = np.random.default_rng(0)
    x = rng.normal(size=5000)
    fig, axes = _figure((3, 2))
    scatter_panel(axes[0], x * 1e-4, 0.3 * x + rng.normal(size=5000), xlabel="q_hat", ylabel="Cm residual",
                  line=(np.array([-3e-4, 3e-4]), np.array([-1.0, 1.0])))
    svg = _svg(fig, "t", "test")
    assert svg.count("<image") == 1
    markers = [u for u in re.findall(r"<use\b[^>]*>", svg) if "DejaVu" not in u]
    assert len(markers) < 30  # tick marks only
    long = re.findall(r"(?<![\w#.])-?\d+\.\d{4,}", svg)
    assert long and all(len(n.lstrip("-").replace(".", "").lstrip("0")) <= 5 for n in long)


def test_a_wrong_sign_damping_term_is_marked_in_the_coefficients_table(run_copy):
    """The run's wrong_sign column (identify's flag, term_report.wrong_sign) shows as a mark on
    that coefficient's interval, once, and not as 'not determined'."""
    import html

    import pandas as pd

    from aerosid.identification.term_report import UNDETERMINED_NOTE, WRONG_SIGN_NOTE
    from aerosid.report import build_report

    run_dir, _, _ = run_copy
    shutil.rmtree(run_dir / "models")  # the table then comes from coefficients.parquet
    path = run_dir / "coefficients.parquet"
    table = pd.read_parquet(path)
    name = str(table["coefficient"].iloc[-1])
    table["wrong_sign"] = table["coefficient"] == name
    table.to_parquet(path)
    doc = build_report(run_dir)
    assert doc.count(html.escape(WRONG_SIGN_NOTE)) == 1
    row = next(r for r in doc.split("<tr") if f">{name}<" in r and html.escape(WRONG_SIGN_NOTE) in r)
    assert html.escape(UNDETERMINED_NOTE) not in row


def test_the_smoother_note_is_read_with_and_without_the_white_floor_column():
    """The report reads the smoother's per-channel table from its summary text: runs written before
    the white floor column (7 tokens) and after it (8; NaN when the floor is unknown)."""
    from aerosid.report.sections_run import _nis_from_note
    old = "ax      m/s^2     0.003298   0.006596    0.01282    0.068        0.088"
    new = "q       rad/s     0.000225  0.0004501  0.0004628   1.337e-05    0.265        0.144"
    unknown = "r       rad/s     0.0002016  0.0002381  0.0002012       nan    1.163        0.998"
    rows = _nis_from_note("\n".join([old, new, unknown, "total   1 2 3"]))
    assert rows["ax"] == {"used": 0.003298, "dispersion": 0.006596, "seed": 0.01282, "nis_filter": 0.068,
                          "nis_smoother": 0.088}
    assert rows["q"]["floor"] == 1.337e-05 and rows["q"]["nis_filter"] == 0.265 and rows["q"]["nis_smoother"] == 0.144
    assert math.isnan(rows["r"]["floor"]) and rows["r"]["nis_smoother"] == 0.998
    assert set(rows) == {"ax", "q", "r"}
