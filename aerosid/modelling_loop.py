"""One step of the modelling loop on a run folder: make sure the model history has
its root version, diagnose the latest model, write diagnosis.json and report.html.

Used by the pipeline's last stage and by ``aerosid diagnose`` / ``aerosid fit``.
"""
from __future__ import annotations

from pathlib import Path

from aerosid.diagnosis import diagnose
from aerosid.io import write_json_atomic
from aerosid.models import ChannelModel
from aerosid.report import write_report
from aerosid.vehicle import load_vehicle
from aerosid.versions import fit_version, history, latest_models, read_flight_data, run_vehicle

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
    diag = diagnose(read_flight_data(run_dir), load_vehicle(run_vehicle(run_dir)), latest_models(run_dir),
                    mach_half_width=mach_half_width)
    paths = {"diagnosis": write_json_atomic(diag.to_json(), run_dir / DIAGNOSIS_NAME)}
    paths["report"] = write_report(run_dir, diagnosis=diag, truth=truth)
    return paths
