"""The last stage: diagnosis.json and report.html for a flight's run folder."""
from __future__ import annotations

import os
import time
from pathlib import Path

from prefect import task

from aerosid.modelling.models import load_models
from aerosid.vehicles.vehicle import load_vehicle
from aerosid.modelling.versions import run_default_models, run_vehicle
from aerosid.modelling.loop import refresh
from aerosid.provenance import sha256_file
from tasks import ledger, progress
from tasks.runner import StageContext, base_record
from tasks.stages import IO_RETRIES


@task(name="diagnose-and-report", **IO_RETRIES)
def report_task(run_dir: str, ctx: StageContext, inputs: list[str], model_spec: str | None,
                truth_path: str | None, mach_half_width: float | None = 0.5) -> dict:
    params = {"model_spec": model_spec, "truth": truth_path, "mach_half_width": mach_half_width}
    files = [p for p in [*inputs, model_spec, truth_path] if p]
    base = base_record("report", ctx, files, [sha256_file(p) for p in files], params)
    started = time.perf_counter()
    shown = progress.label("report", ctx.flight)
    progress.emit(shown, 0.0)
    try:
        models = (load_models(model_spec, base=run_default_models(run_dir),
                              mach_reference=load_vehicle(run_vehicle(run_dir)).mach_reference)
                  if model_spec else None)
        paths = refresh(run_dir, models, truth=truth_path, mach_half_width=mach_half_width)
    except Exception as exc:
        ledger.append(ctx.ledger_path, {**base, "status": "failed", "outputs": [], "error": f"{type(exc).__name__}: {exc}",
                                        "duration_s": time.perf_counter() - started})
        raise
    finally:
        progress.emit(shown, 1.0)
    outputs = [{"path": os.path.abspath(p), "sha256": sha256_file(p)} for p in paths.values()]
    ledger.append(ctx.ledger_path, {**base, "status": "ok", "outputs": outputs, "error": None,
                                    "duration_s": time.perf_counter() - started})
    return {k: str(v) for k, v in paths.items()}


def truth_next_to(telemetry: str) -> str | None:
    """A simulated flight's truth.json beside its telemetry, if there is one."""
    candidate = Path(telemetry).with_name("truth.json")
    return str(candidate) if candidate.is_file() else None
