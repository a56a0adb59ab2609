"""The order of the stages for one or many flights, submitted to the running
flow's task runner (threads by default, Dask in a campaign).  No numerics."""
from __future__ import annotations

import hashlib
import json
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
from tasks.stages import (flight_data_task, plan_segments_task, pooled_flight_data_task, preprocess_task,
                          regression_task, smooth_segment_task)
from tasks.summary import markdown_table, write_run_summary_task

FLIGHT_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,99}$")


def check_flight_id(flight: str) -> str:
    """A flight id names a folder: letters, digits, '_', '.', '-' only, no '..' (no path traversal)."""
    if not FLIGHT_ID.match(flight) or ".." in flight:
        raise ValueError(f"flight identifier {flight!r} is not allowed: use letters, digits, '_', '.', '-' "
                         "(it names an output folder and must not leave it)")
    return flight


def flight_id_from_path(path: str | Path) -> str:
    """A safe flight id from a telemetry file name (telemetry.parquet -> its folder's name).

    A name that is already a valid id is kept as it is; any other name (spaces,
    non-ASCII letters, '..', more than 100 characters) is sanitised and given the first
    8 hex digits of the SHA-256 of the original name, so two different names never
    share an id (``a b`` -> ``a_b-c8687a08``, ``a_b`` -> ``a_b``, ``航班`` -> ``flight-32875d4f``),
    and the same name keeps its id when its content changes."""
    p = Path(path)
    stem = p.parent.name if p.stem == "telemetry" and p.parent.name else p.stem
    if FLIGHT_ID.match(stem) and ".." not in stem:
        return stem
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", stem).replace("..", "_").strip("._-")[:80].strip("._-") or "flight"
    digest = hashlib.sha256(stem.encode("utf-8", "surrogateescape")).hexdigest()[:8]
    return check_flight_id(f"{safe}-{digest}")


def inbox_flight_ids(paths: list[Path], inbox: Path, owners: dict[str, str]) -> tuple[dict[Path, str], dict[Path, str]]:
    """The flight id of each inbox file, and the files refused because they would share a
    run folder with another (the reason names both).  `owners`: flight id -> the inbox
    file (relative name) an earlier scan processed under that id; it keeps it."""
    groups: dict[str, list[Path]] = {}
    for p in paths:
        groups.setdefault(flight_id_from_path(p), []).append(p)
    ids, refused = {}, {}
    for fid, group in groups.items():
        names = {p: inbox_name(p, inbox) for p in group}
        owner = owners.get(fid)
        for p in group:
            others = [names[q] for q in group if q != p]
            if owner is not None and names[p] != owner:
                refused[p] = (f"{names[p]!r} maps to flight id {fid!r}, which belongs to {owner!r} (processed "
                              f"earlier into {fid}/): rename {names[p]!r}")
            elif owner is None and others:
                refused[p] = (f"{names[p]!r} and {', '.join(map(repr, others))} map to the same flight id {fid!r} "
                              "(it names the run folder): rename one")
            else:
                ids[p] = fid
    return ids, refused


def inbox_name(path: Path, inbox: Path) -> str:
    """A file's name relative to the inbox (what the ledger's inbox records call `source`)."""
    try:
        return Path(path).relative_to(inbox).as_posix()
    except ValueError:
        return Path(path).name


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
    min_segment_s: float | None = None  # None: the vehicle's [preprocess] min_segment_s, else 5 s
    ledger_path: str | None = None

    def preprocess_settings(self) -> tuple[dict, float]:
        """The preprocessing parameters (the vehicle file's [preprocess] table with this
        job's own on top) and the minimum segment length [s]."""
        from aerosid.preprocess import DEFAULT_MIN_SEGMENT_S, merge_settings
        from aerosid.vehicles.vehicle import load_vehicle

        if self.vehicle is None:  # an unreadable telemetry file names none: its preprocessing reports it
            return dict(self.preprocess_params or {}), float(self.min_segment_s or DEFAULT_MIN_SEGMENT_S)
        veh = load_vehicle(self.vehicle)
        params = merge_settings(veh.preprocess, self.preprocess_params or {})
        min_seg = next(v for v in (self.min_segment_s, veh.min_segment_s, DEFAULT_MIN_SEGMENT_S) if v is not None)
        return params, float(min_seg)

    def context(self, segment: str = "") -> StageContext:
        ledger = self.ledger_path or str(Path(self.run_dir) / LEDGER_NAME)
        return StageContext(ledger, str(flow_run.get_id() or "local"), self.flight, segment)


def _check_ids(jobs: list[FlightJob]) -> None:
    check_unique_flights(jobs)


def _start(jobs: list[FlightJob]):
    """Submit every job's preprocessing, then its segments' smoothing: returns the
    preprocessing futures, their results (None where it failed), plans and smoothing futures."""
    for job in jobs:
        Path(job.run_dir).mkdir(parents=True, exist_ok=True)
    settings = [j.preprocess_settings() for j in jobs]
    pre_futures = [preprocess_task.submit(j.telemetry, j.run_dir, j.context(), params, j.vehicle)
                   for j, (params, _) in zip(jobs, settings)]
    plans, seg_futures, pre = [], [], []
    for job, fut, (_, min_seg) in zip(jobs, pre_futures, settings):
        fut.wait()
        if not fut.state.is_completed():
            pre.append(None), plans.append(None), seg_futures.append([])
            continue
        p = fut.result()
        plan = plan_segments_task(p["path"], job.windows, min_seg)
        pre.append(p), plans.append(plan)
        seg_futures.append([smooth_segment_task.submit(p["path"], job.run_dir, job.context(s["segment_id"]), s,
                                                       job.vehicle, job.smoothing_options) for s in plan["segments"]])
    return pre_futures, pre, plans, seg_futures


def _flight_summary(job: FlightJob, p: dict | None, plan: dict | None) -> dict:
    segs = plan["segments"] if plan else []
    summary = {"job": asdict(job), "flight": job.flight, "telemetry": job.telemetry, "vehicle": job.vehicle,
               "preprocess": p, "usable_share": (p or {}).get("usable_share"),
               "segments": [s["segment_id"] for s in segs], "segments_ok": [], "segments_failed": [],
               "segments_dropped": plan["dropped"] if plan else [], "status": "failed"}
    if plan and plan["note"]:
        summary["segments_note"] = plan["note"]
    return summary


def _collect_segments(job: FlightJob, plan: dict, futures: list, summary: dict, logger) -> list[dict]:
    """Wait for a flight's segments; record which were smoothed and which failed."""
    done, failed = summary["segments_ok"], summary["segments_failed"]
    for seg, fut in zip(plan["segments"], futures):
        fut.wait()
        if fut.state.is_completed():
            done.append(fut.result())
        else:
            err = fut.state.message or "failed"
            failed.append({"segment": seg["segment_id"], "error": err})
            logger.warning("flight %s segment %s failed: %s", job.flight, seg["segment_id"], err)
    summary["status"] = "failed" if not done else ("partial" if failed else "ok")
    return done


def _own_findings(p: dict, done: list[dict]) -> list:
    """A flight's findings before its flight data: its preprocessing's and its segments'."""
    return list(p.get("findings", [])) + [f for d in done for f in d.get("findings", [])]


def _record_findings(summary: dict, findings, inherited: bool = False) -> None:
    """summary["findings"] = findings; a run with findings (timestamps off the grid, sensor faults,
    gated runs, NIS out of band, database edge, departures), or whose manoeuvres have some
    (`inherited`, a pool), is not "ok"."""
    summary["findings"] = list(findings)
    if (summary["findings"] or inherited) and summary["status"] == "ok":
        summary["status"] = "ok with findings"


def _air_data(flight_data_path: str) -> dict:
    """flight -> where its density, temperature, Mach and dynamic pressure came from."""
    from aerosid.io import read_parquet_metadata

    return json.loads(read_parquet_metadata(flight_data_path).get("aerosid.air_data", "{}"))


def run_flights(jobs: list[FlightJob], isolate: bool = False) -> list[dict]:
    """Every stage of every job; segments of all flights are submitted together so a
    parallel task runner can spread them.  A failed segment is recorded and left out;
    the flight goes on with the others.  With `isolate` (campaigns, inbox scans) a
    flight whose preprocessing, flight data or regression fails is recorded as failed
    in its run.json and the other flights go on; otherwise the error is raised after
    run.json says so."""
    logger = get_run_logger()
    check_unique_flights(jobs)
    pre_futures, pre, plans, seg_futures = _start(jobs)
    summaries = []
    for job, p, plan, futures, pre_future in zip(jobs, pre, plans, seg_futures, pre_futures):
        summary = _flight_summary(job, p, plan)
        try:
            if p is None:
                summary["error"] = {"stage": "preprocess", "message": pre_future.state.message or "failed"}
                pre_future.result()  # raises the stage's own error
            if not plan["segments"]:
                summary["error"] = {"stage": "plan-segments", "message": plan["refusal"]}
                logger.error("flight %s: %s", job.flight, plan["refusal"])
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


def check_unique_flights(jobs: list[FlightJob]) -> None:
    """Two jobs never share a flight id (it names the run folder): an error naming both files."""
    seen: dict[str, str] = {}
    for job in jobs:
        check_flight_id(job.flight)
        if job.flight in seen:
            raise ValueError(f"telemetry files {seen[job.flight]} and {job.telemetry} map to the same flight id "
                             f"{job.flight!r} (it names the run folder): rename one")
        seen[job.flight] = job.telemetry


def _finish_flight(job: FlightJob, p: dict, plan: dict, futures: list, summary: dict, logger) -> None:
    done = _collect_segments(job, plan, futures, summary, logger)
    if done:
        fd = flight_data_task(p["path"], [d["path"] for d in done], job.run_dir, job.context(), job.vehicle)
        coeffs = regression_task([fd["path"]], job.run_dir, job.context(), job.vehicle, job.model_spec,
                                 job.mach_half_width)
        summary.update(flight_data=fd, coefficients=coeffs, air_data=_air_data(fd["path"]))
        _record_findings(summary, _own_findings(p, done) + list(fd.get("findings", []))
                         + list(coeffs.get("findings", [])))
        _artifacts(job, summary)
    write_run_summary_task(job.run_dir, summary)
    if done:
        summary["report"] = report_task(job.run_dir, job.context(), [fd["path"], coeffs["path"]], job.model_spec,
                                        truth_next_to(job.telemetry), job.mach_half_width)
        write_run_summary_task(job.run_dir, summary)


def _artifacts(job, summary: dict) -> None:
    """Markdown tables of the results in Prefect's UI (keys: lowercase, digits, dashes)."""
    key = re.sub(r"[^a-z0-9-]+", "-", job.flight.lower()).strip("-") or "flight"
    md = artifact_markdown(job.flight, pd.read_parquet(summary["coefficients"]["path"]), summary)
    create_markdown_artifact(md, key=f"coefficients-{key}", description=f"EBM results of {job.flight}")


def artifact_markdown(flight: str, table: pd.DataFrame, summary: dict) -> str:
    """The run's artifact in Markdown: the coefficients, each segment's status and the findings
    (a pooled run's segments and findings named with their manoeuvre)."""
    md = [f"# Coefficients of flight `{flight}`", "",
          "SI per radian, moments about the CG; sigma corrected for coloured residuals.", "",
          markdown_table(table[["channel", "coefficient", "estimate", "std_error", "std_error_ols", "ci_low",
                                "ci_high", "reference"]])]
    parts = [(f"{f['flight']}/", f) for f in summary["flights"]] if "flights" in summary else [("", summary)]
    segs = [f"| {pre}{s} | {'ok' if any(d['segment'] == s for d in fs['segments_ok']) else 'failed'} |"
            for pre, fs in parts for s in fs["segments"]]
    md += ["", "## Segments", "", "| segment | status |", "|---|---|", *segs]
    found = [(pre, f) for pre, fs in parts if "flights" in summary for f in fs.get("findings", [])] + [
        ("", f) for f in summary.get("findings", [])]
    if found:
        md += ["", f"## Findings (status: {summary.get('status')})", "",
               "| segment | finding | channel | time span [s] | samples | action | detail |",
               "|---|---|---|---|---|---|---|", *(_finding_row(pre, f) for pre, f in found)]
    return "\n".join(md)


def _finding_row(prefix: str, f: dict) -> str:
    cells = [prefix + str(f.get("segment", "")), f.get("kind", ""), f.get("channel", ""),
             f"{float(f.get('t0_s', float('nan'))):.2f}–{float(f.get('t1_s', float('nan'))):.2f}",
             f.get("n_samples", ""), "cut" if f.get("cut") else "reported", f.get("detail", "")]
    return "| " + " | ".join(str(c).replace("|", "\\|").replace("\n", " ") for c in cells) + " |"


# ------------------------------------------------------------- several manoeuvres, one model
POOLED_FLIGHTS_DIR = "flights"


@dataclass
class PoolJob:
    """Several manoeuvres of one aircraft identified together: each telemetry file is
    preprocessed and smoothed on its own under ``run_dir/flights/<flight id>/``; the
    pooled flight data, coefficients, report and run.json are in ``run_dir``."""

    telemetry: list
    run_dir: str
    name: str
    vehicle: str
    windows: list | None = None
    model_spec: str | None = None
    preprocess_params: dict = field(default_factory=dict)
    smoothing_options: dict = field(default_factory=dict)
    mach_half_width: float | None = 0.5
    min_segment_s: float | None = None
    ledger_path: str | None = None

    @property
    def flight(self) -> str:  # the pooled identification's name (ledger records, artifacts)
        return self.name

    def flight_jobs(self) -> list[FlightJob]:
        ledger = self.ledger_path or str(Path(self.run_dir) / LEDGER_NAME)
        jobs = []
        for path in self.telemetry:
            fid = flight_id_from_path(path)
            jobs.append(FlightJob(str(path), str(Path(self.run_dir) / POOLED_FLIGHTS_DIR / fid), fid, self.vehicle,
                                  self.windows, self.model_spec, dict(self.preprocess_params),
                                  dict(self.smoothing_options), self.mach_half_width, self.min_segment_s, ledger))
        return jobs

    def context(self) -> StageContext:
        ledger = self.ledger_path or str(Path(self.run_dir) / LEDGER_NAME)
        return StageContext(ledger, str(flow_run.get_id() or "local"), self.name, "")


def _pooled_truth(telemetry: list[str]) -> str | None:
    """The truth.json of simulated manoeuvres when every file has one and they hold the
    same coefficients (the same vehicle and effects); else None."""
    paths = [truth_next_to(t) for t in telemetry]
    if not paths or None in paths:
        return None
    docs = [json.loads(Path(p).read_text()).get("coefficients") for p in paths]
    return paths[0] if all(d == docs[0] for d in docs) else None


def run_pooled(pool: PoolJob) -> dict:
    """Every stage of a pooled identification (see PoolJob).  A file whose
    preprocessing fails fails the run (run.json says so first); a failed segment, or a
    manoeuvre none of whose segments could be smoothed, is left out and the run is
    ``partial``.  Per-manoeuvre summaries go to ``flights/<id>/run.json`` (with
    ``pooled_into``) and into the pooled run.json's ``flights``."""
    logger = get_run_logger()
    check_flight_id(pool.name)
    jobs = pool.flight_jobs()
    _check_ids(jobs)
    Path(pool.run_dir).mkdir(parents=True, exist_ok=True)
    summary = {"pool": asdict(pool), "flight": pool.name, "telemetry": [j.telemetry for j in jobs],
               "vehicle": pool.vehicle, "flights": [], "status": "failed"}
    try:
        pre_futures, pre, plans, seg_futures = _start(jobs)
        groups = []
        for job, p, plan, futures, pre_future in zip(jobs, pre, plans, seg_futures, pre_futures):
            fs = {**_flight_summary(job, p, plan), "pooled_into": pool.run_dir}
            summary["flights"].append(fs)
            if p is None:
                fs["error"] = {"stage": "preprocess", "message": pre_future.state.message or "failed"}
                write_run_summary_task(job.run_dir, fs)
                pre_future.result()  # raises the stage's own error
            done = _collect_segments(job, plan, futures, fs, logger)
            # each manoeuvre's own findings; the pooled flight data's are the pool's (below), so
            # nothing is listed twice
            _record_findings(fs, _own_findings(p, done))
            write_run_summary_task(job.run_dir, fs)
            if done:
                groups.append({"flight": job.flight, "preprocessed": p["path"], "smoothed": [d["path"] for d in done]})
        states = [fs["status"] for fs in summary["flights"]]
        summary["status"] = ("failed" if not groups else "ok" if all(s in ("ok", "ok with findings") for s in states)
                             else "partial")
        if groups:
            fd = pooled_flight_data_task(groups, pool.run_dir, pool.context(), pool.vehicle)
            coeffs = regression_task([fd["path"]], pool.run_dir, pool.context(), pool.vehicle, pool.model_spec,
                                     pool.mach_half_width)
            summary.update(flight_data=fd, coefficients=coeffs, air_data=_air_data(fd["path"]))
            _record_findings(summary, list(fd.get("findings", [])) + list(coeffs.get("findings", [])),
                             inherited=any(fs.get("findings") for fs in summary["flights"]))
            _artifacts(pool, summary)
        write_run_summary_task(pool.run_dir, summary)
        if groups:
            summary["report"] = report_task(pool.run_dir, pool.context(), [fd["path"], coeffs["path"]],
                                            pool.model_spec, _pooled_truth(summary["telemetry"]),
                                            pool.mach_half_width)
            write_run_summary_task(pool.run_dir, summary)
    except Exception as exc:
        summary["status"] = "failed"
        summary.setdefault("error", {"stage": "pool", "message": f"{type(exc).__name__}: {exc}"})
        write_run_summary_task(pool.run_dir, summary)
        raise
    return summary
