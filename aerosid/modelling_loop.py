"""One step of the modelling loop on a run folder: make sure the model history has
its root version, diagnose a version (the latest by default), write diagnosis.json
(its ``model`` field names the version) and report.html showing that version.

Used by the pipeline's last stage and by ``aerosid diagnose`` / ``aerosid fit``.
"""
from __future__ import annotations

import json
from pathlib import Path

from aerosid.diagnosis import diagnose
from aerosid.io import write_json_atomic
from aerosid.modelling.models import ChannelModel
from aerosid.report import write_report
from aerosid.vehicles.vehicle import load_vehicle
from aerosid.modelling.versions import fit_version, history, read_flight_data, run_default_models, run_vehicle

DIAGNOSIS_NAME = "diagnosis.json"


def refresh(run_dir: str | Path, models: dict[str, ChannelModel] | None = None, truth=None,
            mach_half_width: float | None = 0.5) -> dict[str, Path]:
    """Root version if none (with `models` as v002 when given), diagnosis of the latest
    version, then the report.  Returns the paths written."""
    run_dir = Path(run_dir)
    if history(run_dir).latest is None:
        fit_version(run_dir, None, note="default models", mach_half_width=mach_half_width)
        if models is not None:
            fit_version(run_dir, models, note="--model given to aerosid run", mach_half_width=mach_half_width)
    return diagnose_and_report(run_dir, truth=truth, mach_half_width=mach_half_width)


def diagnose_and_report(run_dir: str | Path, version: str | None = None, *, truth=None,
                        mach_half_width: float | None = 0.5, n_windows: int = 8) -> dict[str, Path]:
    """Diagnose a stored version (default: the latest; the default models when there is
    none), write RUN_DIR/diagnosis.json with ``model`` = its id, and RUN_DIR/report.html
    showing that version everywhere.  `truth` defaults to the truth.json beside the run's
    telemetry (a simulated flight), as the pipeline's report uses it."""
    run_dir = Path(run_dir)
    h = history(run_dir)
    v = h.get(version) if version is not None else h.latest
    models = dict(v.models) if v is not None else run_default_models(run_dir)
    diag = diagnose(read_flight_data(run_dir), load_vehicle(run_vehicle(run_dir)), models,
                    mach_half_width=mach_half_width, n_windows=n_windows)
    doc = diag.to_json()
    doc["model"] = v.id if v is not None else "default models"
    path = write_json_atomic(doc, run_dir / DIAGNOSIS_NAME)
    if truth is None:
        truth = run_truth(run_dir)
    report = write_report(run_dir, diagnosis=path, truth=truth, version=v.id if v is not None else None)
    return {"diagnosis": path, "report": report}


def run_truth(run_dir: str | Path) -> Path | None:
    """The truth.json beside the run's telemetry (run.json ``telemetry``), if there is one."""
    try:
        doc = json.loads((Path(run_dir) / "run.json").read_text())
    except (OSError, ValueError):
        return None
    telemetry = doc.get("telemetry") if isinstance(doc, dict) else None
    if not isinstance(telemetry, str):
        return None
    candidate = Path(telemetry).with_name("truth.json")
    return candidate if candidate.is_file() else None
