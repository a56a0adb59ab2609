"""The report names every finding of the run with its span (issue 16: a finding is in the run's
summary and report), escaped."""
import json

from aerosid.report import build_report
from aerosid.report.sections_run import _findings_table

FINDINGS = [
    {"kind": "time_jitter", "segment": "preprocess", "channel": "t_s", "t0_s": 0.01, "t1_s": 11.0,
     "n_samples": 393, "cut": True, "detail": "393 timestamp(s) lie off the grid"},
    {"kind": "nis_mean", "segment": "seg00", "channel": "", "t0_s": 0.0, "t1_s": 8.0, "n_samples": 401,
     "cut": False, "detail": "mean NIS <3.43> below its band & co"},
]


def test_each_finding_is_a_row_with_its_span_and_action_and_the_text_is_escaped():
    html = _findings_table(FINDINGS)
    assert 'id="run-findings"' in html and html.count("<tr><td>") == 2
    assert "0.01–11.00 s" in html and "cut from the regression" in html and "reported" in html
    assert "&lt;3.43&gt;" in html and "&amp; co" in html and "<3.43>" not in html
    assert _findings_table([]) == ""


def test_the_report_of_a_run_with_findings_lists_them_in_its_run_section(tmp_path):
    (tmp_path / "run.json").write_text(json.dumps({"flight": "f", "status": "ok with findings",
                                                   "findings": FINDINGS}))
    html = build_report(tmp_path)
    run_section = html[html.index('<section id="run"'):]
    run_section = run_section[:run_section.index("</section>")]
    assert 'id="run-findings"' in run_section and "time_jitter" in run_section and "nis_mean" in run_section
