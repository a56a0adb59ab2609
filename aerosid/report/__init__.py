"""A self-contained HTML report of one run folder (``RUN_DIR/report.html``).

    >>> from aerosid.report import build_report, write_report
    >>> write_report("runs/reference/run")                      # -> runs/reference/run/report.html
    >>> write_report(run_dir, diagnosis=diag, truth=json.load(open("truth.json")), version="v002")

The document holds everything an engineer hands to a colleague: what was
processed (flight, vehicle, telemetry file and its SHA-256, code version),
preprocessing, the filter/smoother consistency per segment, the coefficients of
the model version shown (the latest, or ``version``), measured vs model and the
residuals against each regressor for that version, the diagnosis and the model
versions as a tree.  The page is rendered from the jinja2 templates in
``aerosid/report/templates`` with autoescaping on; plots are matplotlib SVG with
the text drawn as paths, inlined in the page; there is no script, no stylesheet,
font or image to fetch: the file opens the same on an air-gapped machine.
Sections without data (no diagnosis yet, a failed segment, no model versions)
say so.  Read only: the report never computes a new diagnosis or fit.  See
``docs/report.md``.

Modules: ``html`` (escaping, tables, the template environment), ``plots`` (SVG),
``rundir`` (reading the run folder, the version shown), ``sections_*`` (one per
group of sections).
"""
from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

# the helpers aerosid.identification.validation_report shares with this report
from aerosid.report.html import _e, _note, _p, _table, css, html_safe, render  # noqa: F401
from aerosid.report.plots import _figure, _gaps, _svg, _thin  # noqa: F401
from aerosid.report.rundir import _Run, _diagnosis_inputs, _per_flight, _truth_coefficients, shown_model
from aerosid.report.sections_diagnosis import _s_diagnosis
from aerosid.report.sections_model import _s_coefficients, _s_comparison, _s_residuals, model_series
from aerosid.report.sections_run import _s_header, _s_preprocessing, _s_segments
from aerosid.report.sections_versions import _s_audit, _s_versions

__all__ = ["build_report", "write_report", "REPORT_NAME"]

REPORT_NAME = "report.html"


def __getattr__(name: str):
    if name == "_CSS":  # the stylesheet, for pages that share the report's look
        return css()
    raise AttributeError(name)


_SECTIONS = (
    ("run", "Run"),
    ("preprocessing", "Preprocessing"),
    ("segments", "Filter and smoother, per segment"),
    ("coefficients", "Aerodynamic coefficients"),
    ("comparison", "Measured vs model"),
    ("residuals", "Residuals against the regressors"),
    ("diagnosis", "Diagnosis"),
    ("versions", "Model versions"),
    ("audit", "Audit trail"),
)

_INTROS = {
    "run": "What was processed, from which file (its SHA-256 identifies the exact bytes), by which code, and when.",
    "preprocessing": "The raw telemetry is put on a uniform time grid; dropouts, NaNs, spikes and frozen values are "
                     "flagged; short gaps are interpolated, long ones are left empty and split the flight into "
                     "segments.",
    "segments": "Each segment is run through the 21-state extended Kalman filter and the Modified Bryson–Frazier "
                "smoother. The table checks the filter's consistency; the plot shows the smoothed pitch rate with "
                "its uncertainty.",
    "coefficients": "The flight estimates of the aerodynamic coefficients from the multiple linear regression, "
                    "next to the preflight database (seed Table 3 style).",
    "comparison": "How well the fitted model reproduces the flight-derived coefficients (seed Figs. 6, 9, 10 "
                  "style).",
    "residuals": "Where in each regressor's range the model misses: a straight, structure-free cloud is a good "
                 "term; a curve or a step points at the shape of the missing term.",
    "diagnosis": "Where the model fails (time windows, regimes), whether the residual is white, and which "
                 "physical effect is most likely missing.",
    "versions": "The modelling loop: every model that was fitted, what changed, and how the error moved.",
    "audit": "Every stage execution is recorded in the append-only ledger.",
}


def _guard(fn: Callable[[], str], what: str) -> str:
    try:
        return fn()
    except Exception as exc:  # one broken section must not lose the rest of the report
        return _note(f"The {what} section could not be rendered: {type(exc).__name__}: {exc}")


def build_report(run_dir: str | Path, *, diagnosis=None, truth=None, version: str | None = None) -> str:
    """The HTML report of RUN_DIR as one self-contained document (str).

    diagnosis: an :class:`aerosid.diagnosis.Diagnosis` (full regime map), a
    ``diagnosis.json`` dict or its path; default: ``RUN_DIR/diagnosis.json`` when
    present, else the section says there is no diagnosis yet.
    truth: a ``truth.json`` dict (or its path) of a simulated flight: adds the
    true values and the error % to the coefficients table.
    version: the model version whose coefficients, comparison and residual plots
    are shown ("v003"); default the latest (RUN_DIR/coefficients.parquet when the
    run has no versions yet).  An unknown version raises
    :class:`aerosid.modelling.versions.VersionError` naming the versions there are.
    Reads the run folder only; never writes.
    """
    import matplotlib  # noqa: F401  (fail early and clearly if the plotting library is missing)

    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise FileNotFoundError(f"{run_dir}: no such run folder")
    run = _Run.load(run_dir)
    shown = shown_model(run, version)
    doc, diag, source = _diagnosis_inputs(run, diagnosis)
    truth_c = _truth_coefficients(truth)
    generated = datetime.now(timezone.utc).isoformat(timespec="seconds")
    series: dict = {}

    def series_once():
        if "v" not in series:
            series["v"] = model_series(run, shown)
        return series["v"]

    bodies = {
        "preprocessing": lambda: _per_flight(run, _s_preprocessing),
        "segments": lambda: _per_flight(run, _s_segments),
        "coefficients": lambda: _s_coefficients(run, shown, truth_c),
        "comparison": lambda: _s_comparison(run, shown, series_once(), doc, diag),
        "residuals": lambda: _s_residuals(run, shown, series_once()),
        "diagnosis": lambda: _s_diagnosis(doc, diag, source, run, shown),
        "versions": lambda: _s_versions(run, shown),
        "audit": lambda: _s_audit(run),
    }
    rendered = {sid: _guard(fn, sid) for sid, fn in bodies.items()}
    rendered["run"] = _guard(lambda: _s_header(run, generated), "run")  # last: lists the files found unreadable
    sections = [{"id": sid, "title": title, "intro": _INTROS[sid], "body": html_safe(rendered[sid])}
                for sid, title in _SECTIONS]
    return render("report.html.j2", title=f"aerosid report — flight {run.flight}", vehicle=run.vehicle,
                  generated=generated, run_dir=str(run_dir), shown=shown.label, css=html_safe(css()),
                  sections=sections)


def write_report(run_dir: str | Path, *, diagnosis=None, truth=None, path: str | Path | None = None,
                 version: str | None = None) -> Path:
    """Build the report and write it atomically to RUN_DIR/report.html (or `path`); returns the path."""
    from aerosid.io import write_text_atomic

    text = build_report(run_dir, diagnosis=diagnosis, truth=truth, version=version)
    return write_text_atomic(text, Path(path) if path is not None else Path(run_dir) / REPORT_NAME)
