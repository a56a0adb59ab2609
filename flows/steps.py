"""The order of the stages for one or many flights, submitted to the running
flow's task runner (threads by default, Dask in a campaign).  No numerics."""
from __future__ import annotations

import re
from dataclasses import asdict, dataclass, field
from pathlib import Path

import pandas as pd
from prefect import get_run_logger
from prefect.artifacts import create_markdown_artifact
from prefect.runtime import flow_run

from tasks.ledger import LEDGER_NAME
from tasks.report import report_task, truth_next_to
from tasks.runner import StageContext
from tasks.stages import (flight_data_task, plan_segments_task, preprocess_task, regression_task,
                          smooth_segment_task)
from tasks.summary import markdown_table, write_run_summary_task

FLIGHT_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,99}$")


def check_flight_id(flight: str) -> str:
    """A flight id names a folder: letters, digits, '_', '.', '-' only, no '..' (no path traversal)."""
    if not FLIGHT_ID.match(flight) or ".." in flight:
        raise ValueError(f"flight identifier {flight!r} is not allowed: use letters, digits, '_', '.', '-' "
                         "(it names an output folder and must not leave it)")
    return flight


def flight_id_from_path(path: str | Path) -> str:
    """A safe flight id from a telemetry file name (telemetry.parquet -> its folder's name)."""
    p = Path(path)
    stem = p.parent.name if p.stem == "telemetry" and p.parent.name else p.stem
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", stem).strip("._-") or "flight"
    return check_flight_id(safe.replace("..", "_"))


@dataclass
class FlightJob:
    """One flight going through the stages (paths are strings: Prefect/Dask-friendly)."""

    telemetry: str
    run_dir: str
    flight: str
    vehicle: str = "seed-rlv"
    windows: list | None = None
    model_spec: str | None = None
    preprocess_params: dict = field(default_factory=dict)
    smoothing_options: dict = field(default_factory=dict)
    mach_half_width: float | None = 0.5
    min_segment_s: float = 5.0
    ledger_path: str | None = None

    def context(self, segment: str = "") -> StageContext:
        ledger = self.ledger_path or str(Path(self.run_dir) / LEDGER_NAME)
        return StageContext(ledger, str(flow_run.get_id() or "local"), self.flight, segment)


def run_flights(jobs: list[FlightJob], isolate: bool = False) -> list[dict]:
    """Every stage of every job; segments of all flights are submitted together so a
    parallel task runner can spread them.  A failed segment is recorded and left out;
    the flight goes on with the others.  With `isolate` (campaigns, inbox scans) a
    flight whose preprocessing, flight data or regression fails is recorded as failed
    in its run.json and the other flights go on; otherwise the error is raised after
    run.json says so."""
    logger = get_run_logger()
    ids = [check_flight_id(job.flight) for job in jobs]
    if len(set(ids)) < len(ids):
        dup = sorted({i for i in ids if ids.count(i) > 1})
        raise ValueError(f"two telemetry files map to the same flight id {dup}: rename one (the id names the run folder)")
    for job in jobs:
        Path(job.run_dir).mkdir(parents=True, exist_ok=True)
    pre_futures = [preprocess_task.submit(j.telemetry, j.run_dir, j.context(), j.preprocess_params) for j in jobs]
    plans, seg_futures, pre, plan_errors = [], [], [], {}
    for job, fut in zip(jobs, pre_futures):
        fut.wait()
        if not fut.state.is_completed():
            pre.append(None), plans.append([]), seg_futures.append([])
            continue
        p = fut.result()
        try:
            plan = plan_segments_task(p["path"], job.windows, job.min_segment_s)
        except Exception as exc:  # no segment (too short, all flagged): this flight fails, with the reason
            plan_errors[job.flight] = exc
            plan = []
        pre.append(p), plans.append(plan)
        seg_futures.append([smooth_segment_task.submit(p["path"], job.run_dir, job.context(s["segment_id"]), s,
                                                       job.vehicle, job.smoothing_options) for s in plan])
    summaries = []
    for job, p, plan, futures, pre_future in zip(jobs, pre, plans, seg_futures, pre_futures):
        summary = {"job": asdict(job), "flight": job.flight, "telemetry": job.telemetry, "vehicle": job.vehicle,
                   "preprocess": p, "segments": [s["segment_id"] for s in plan], "segments_ok": [],
                   "segments_failed": [], "status": "failed"}
        try:
            if p is None:
                summary["error"] = {"stage": "preprocess", "message": pre_future.state.message or "failed"}
                pre_future.result()  # raises the stage's own error
            if job.flight in plan_errors:
                summary["error"] = {"stage": "plan", "message": str(plan_errors[job.flight])}
                raise plan_errors[job.flight]
            _finish_flight(job, p, plan, futures, summary, logger)
        except Exception as exc:
            summary["status"] = "failed"
            summary.setdefault("error", {"stage": "flight", "message": f"{type(exc).__name__}: {exc}"})
            write_run_summary_task(job.run_dir, summary)
            if not isolate:
                raise
            logger.error("flight %s failed: %s", job.flight, summary["error"]["message"])
        summaries.append(summary)
    return summaries


def _finish_flight(job: FlightJob, p: dict, plan: list, futures: list, summary: dict, logger) -> None:
    done, failed = summary["segments_ok"], summary["segments_failed"]
    for seg, fut in zip(plan, futures):
        fut.wait()
        if fut.state.is_completed():
            done.append(fut.result())
        else:
            err = fut.state.message or "failed"
            failed.append({"segment": seg["segment_id"], "error": err})
            logger.warning("flight %s segment %s failed: %s", job.flight, seg["segment_id"], err)
    summary["status"] = "failed" if not done else ("partial" if failed else "ok")
    if done:
        fd = flight_data_task(p["path"], [d["path"] for d in done], job.run_dir, job.context(), job.vehicle)
        coeffs = regression_task([fd["path"]], job.run_dir, job.context(), job.vehicle, job.model_spec,
                                 job.mach_half_width)
        summary.update(flight_data=fd, coefficients=coeffs)
        _artifacts(job, summary)
    write_run_summary_task(job.run_dir, summary)
    if done:
        summary["report"] = report_task(job.run_dir, job.context(), [fd["path"], coeffs["path"]], job.model_spec,
                                        truth_next_to(job.telemetry), job.mach_half_width)
        write_run_summary_task(job.run_dir, summary)


def _artifacts(job: FlightJob, summary: dict) -> None:
    """Markdown tables of the results in Prefect's UI (keys: lowercase, digits, dashes)."""
    key = re.sub(r"[^a-z0-9-]+", "-", job.flight.lower()).strip("-") or "flight"
    table = pd.read_parquet(summary["coefficients"]["path"])
    md = [f"# Coefficients of flight `{job.flight}`", "",
          "SI per radian, moments about the CG; sigma corrected for coloured residuals.", "",
          markdown_table(table[["channel", "coefficient", "estimate", "std_error", "std_error_ols", "ci_low",
                                "ci_high", "reference"]])]
    segs = [f"| {s} | {'ok' if any(d['segment'] == s for d in summary['segments_ok']) else 'failed'} |"
            for s in summary["segments"]]
    md += ["", "## Segments", "", "| segment | status |", "|---|---|", *segs]
    create_markdown_artifact("\n".join(md), key=f"coefficients-{key}", description=f"EBM results of {job.flight}")
