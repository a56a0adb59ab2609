"""Prefect flows of aerosid: process_flight, process_manoeuvres, reprocess_inbox, retry_failed, campaign.

Flows hold the order of work only; every number is computed in ``aerosid`` and
every file is read and written by ``tasks``.
"""
from __future__ import annotations

import fcntl
import os
import time
from contextlib import contextmanager
from pathlib import Path

from prefect import flow, get_run_logger

from aerosid.io import telemetry_vehicle
from aerosid.provenance import sha256_file
from flows.steps import (FlightJob, PoolJob, check_flight_id, flight_id_from_path, inbox_flight_ids, inbox_name,
                         run_flights, run_pooled)
from tasks import ledger
from tasks.ledger import LEDGER_NAME


@flow(name="process-flight", log_prints=True)
def process_flight(telemetry: str, out_dir: str, vehicle: str | None = None, flight: str | None = None,
                   windows: list | None = None, model_spec: str | None = None,
                   preprocess_params: dict | None = None, smoothing_options: dict | None = None,
                   mach_half_width: float | None = 0.5, min_segment_s: float | None = None) -> dict:
    """One telemetry file -> segments -> every stage -> coefficients (and run.json, ledger).
    vehicle: a built-in name or a vehicle file; None = the one the file's metadata names
    (aerosid.io.telemetry_vehicle: an error when it names none).
    preprocess_params: PreprocessParams keyword arguments on top of the vehicle file's [preprocess]
    table; min_segment_s: shortest segment smoothed [s] (None: the vehicle's, else 5 s)."""
    job = FlightJob(str(telemetry), str(out_dir), check_flight_id(flight or flight_id_from_path(telemetry)),
                    vehicle or telemetry_vehicle(telemetry), windows, model_spec, preprocess_params or {},
                    smoothing_options or {}, mach_half_width, min_segment_s)
    return run_flights([job])[0]


def pooled_vehicle(telemetry_files: list[str], vehicle: str | None = None) -> str:
    """The one vehicle of pooled manoeuvres: `vehicle` if given, else the vehicle every
    file names (aerosid.io.telemetry_vehicle); files naming different vehicles (by the
    content of their vehicle files) are refused."""
    if vehicle:
        return vehicle
    from aerosid.vehicles.vehicle import resolve_vehicle_path

    # an unreadable file names nothing (None): its preprocessing reports it
    named = {str(t): v for t in telemetry_files if (v := telemetry_vehicle(t)) is not None}
    content = {t: resolve_vehicle_path(v).read_bytes() for t, v in named.items()}
    if len(set(content.values())) > 1:
        listing = "; ".join(f"{t}: {v}" for t, v in named.items())
        raise ValueError(f"the telemetry files name different vehicles ({listing}): pool manoeuvres of one "
                         "aircraft, or give the vehicle (--vehicle NAME_OR_FILE)")
    return next(iter(named.values()), None)


@flow(name="process-manoeuvres", log_prints=True)
def process_manoeuvres(telemetry_files: list[str], out_dir: str, vehicle: str | None = None, name: str | None = None,
                       windows: list | None = None, model_spec: str | None = None,
                       preprocess_params: dict | None = None, smoothing_options: dict | None = None,
                       mach_half_width: float | None = 0.5, min_segment_s: float | None = None) -> dict:
    """Several manoeuvres of one aircraft -> one identification: each file preprocessed
    and smoothed on its own (its own flight id and segments, under OUT/flights/<id>/),
    their flight data pooled into OUT/flight_data.parquet, one regression.  vehicle: as
    for process_flight, and every file must name the same one.  name: the pooled
    identification's id in the ledger (default: the run folder's name)."""
    pool = PoolJob([str(t) for t in telemetry_files], str(out_dir),
                   check_flight_id(name or flight_id_from_path(out_dir)),
                   pooled_vehicle([str(t) for t in telemetry_files], vehicle), windows, model_spec,
                   preprocess_params or {}, smoothing_options or {}, mach_half_width, min_segment_s)
    return run_pooled(pool)


@flow(name="campaign", log_prints=True)
def campaign(telemetry_files: list[str], out_root: str, vehicle: str | None = None,
             smoothing_options: dict | None = None, mach_half_width: float | None = 0.5) -> list[dict]:
    """Many flights; their segments are submitted together so that a Dask task runner
    (see ``campaign_runner``) spreads them over workers."""
    jobs = []
    for path in telemetry_files:
        fid = flight_id_from_path(path)
        jobs.append(FlightJob(str(path), str(Path(out_root) / fid), fid, vehicle or telemetry_vehicle(path),
                              smoothing_options=smoothing_options or {}, mach_half_width=mach_half_width,
                              ledger_path=str(Path(out_root) / LEDGER_NAME)))
    return run_flights(jobs, isolate=True)


def campaign_runner(dask_address: str | None = None, n_workers: int | None = None):
    """The campaign flow on Dask when given a scheduler address or a worker count,
    on the default task runner otherwise."""
    if dask_address is None and not n_workers:
        return campaign
    from prefect_dask import DaskTaskRunner

    runner = (DaskTaskRunner(address=dask_address) if dask_address
              else DaskTaskRunner(cluster_kwargs={"n_workers": int(n_workers), "threads_per_worker": 1,
                                                  "processes": True, "dashboard_address": None}))
    return campaign.with_options(task_runner=runner)


# ----------------------------------------------------------------------- inbox
STATE_FILE = "run.json"


def _stable(path: Path, wait_s: float) -> bool:
    """A file still being written changes size or mtime within wait_s."""
    a = path.stat()
    time.sleep(wait_s)
    b = path.stat()
    return (a.st_size, a.st_mtime_ns) == (b.st_size, b.st_mtime_ns) and a.st_size > 0


@contextmanager
def _claim(lock_path: Path):
    """Exclusive, non-blocking claim of a flight: yields True if this process holds it."""
    lock_path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            yield False
            return
        try:
            yield True
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


def _processed_shas(records: list[dict]) -> dict[str, str]:
    """flight -> SHA-256 of the telemetry whose processing last *finished* (an inbox
    'done' record, written after every stage; a run killed half way leaves none, so
    the next scan processes the file again and reuses what the killed run finished)."""
    done = {}
    for rec in records:
        if rec.get("stage") == "inbox" and rec.get("status") == "done":
            done[rec["flight"]] = rec["inputs"][0]["sha256"]
    return done


def _owners(records: list[dict]) -> dict[str, str]:
    """flight id -> the inbox file that first had it (its first started, done, failed or
    unchanged record; a skipped file never owns an id)."""
    owners: dict[str, str] = {}
    for rec in records:
        if rec.get("stage") == "inbox" and rec.get("source") and rec.get("flight") and \
                rec.get("status") in ("started", "done", "failed", "unchanged"):
            owners.setdefault(rec["flight"], rec["source"])
    return owners


@flow(name="reprocess-inbox", log_prints=True)
def reprocess_inbox(inbox: str, out_root: str, vehicle: str | None = None, pattern: str = "*.parquet",
                    settle_s: float = 0.5) -> dict:
    """Process every telemetry file in `inbox` that is new or whose content changed
    (by SHA-256, not by name or time); skip the rest.  Files still being written
    (size or mtime changing over settle_s) wait for the next scan; hidden names
    (uploads in progress) and folders are not telemetry; a flight another run is
    processing is skipped (a file lock); two files whose names map to one flight id
    are refused (naming both).  Every file the pattern matches gets an inbox record
    in the ledger saying what became of it."""
    logger = get_run_logger()
    root, inbox_dir = Path(out_root), Path(inbox)
    led = root / LEDGER_NAME
    if not inbox_dir.is_dir():
        raise FileNotFoundError(f"inbox {inbox} is not an existing folder")
    report = {"processed": [], "unchanged": [], "busy": [], "not_ready": [], "failed": [], "errors": {},
              "skipped": {}}

    def record(path: Path, flight: str, status: str, sha: str | None = None, **extra) -> None:
        ledger.append(led, {"run_id": "inbox", "flight": flight, "segment": "", "stage": "inbox",
                            "status": status, "source": inbox_name(path, inbox_dir),
                            "inputs": [{"path": os.path.abspath(path), "sha256": sha}] if sha else [],
                            "outputs": [], "error": None, **extra})

    def skip(path: Path, flight: str, reason: str, sha: str | None = None) -> None:
        record(path, flight, "skipped", sha, reason=reason)
        report["skipped"][str(path)] = reason
        logger.info("inbox file %s skipped: %s", path, reason)

    matched = sorted(inbox_dir.glob(pattern))
    if not matched:
        logger.info("inbox %s: no telemetry files matching %s", inbox, pattern)
    files = []
    for p in matched:
        if p.name.startswith("."):
            skip(p, "", "a hidden name (an upload in progress, or not telemetry): processed once it has its final name")
        elif not p.is_file():
            skip(p, "", "not a regular file")
        else:
            files.append(p)
    records = ledger.read(led)
    done = _processed_shas(records)
    ids, refused = inbox_flight_ids(files, inbox_dir, _owners(records))
    for path in files:
        if path in refused:
            skip(path, flight_id_from_path(path), refused[path])
            continue
        flight = ids[path]
        try:
            if not _stable(path, settle_s):
                report["not_ready"].append(str(path))
                skip(path, flight, f"not ready: still being written (size or modification time changed within "
                                   f"{settle_s} s, or empty); the next scan looks again")
                continue
            sha = sha256_file(path)
        except OSError as exc:  # vanished or unreadable between the listing and now
            skip(path, flight, f"cannot be read: {exc.strerror or exc}")
            continue
        if done.get(flight) == sha:
            record(path, flight, "unchanged", sha)
            report["unchanged"].append(flight)
            continue
        with _claim(root / ".locks" / f"{flight}.lock") as mine:
            if not mine:
                report["busy"].append(flight)
                skip(path, flight, "busy: another run is processing this flight (its lock is held)", sha)
                continue
            latest = ledger.read(led)
            if _processed_shas(latest).get(flight) == sha:  # done by a concurrent run meanwhile
                record(path, flight, "unchanged", sha)
                report["unchanged"].append(flight)
                continue
            owner = _owners(latest).get(flight)
            if owner is not None and owner != inbox_name(path, inbox_dir):  # claimed by another file meanwhile
                skip(path, flight, f"flight id {flight!r} belongs to {owner!r}: rename {path.name!r}", sha)
                continue
            if owner is None:
                record(path, flight, "started", sha)
            try:  # a file naming no vehicle fails alone, like a bad file
                job = FlightJob(str(path), str(root / flight), flight, vehicle or telemetry_vehicle(path),
                                ledger_path=str(led))
                summary = run_flights([job])[0]
            except Exception as exc:  # a bad file (the ledger has it) must not stop the scan of the others
                logger.error("inbox file %s failed: %s", path, exc)
                report["failed"].append(flight)
                report["errors"][flight] = f"{type(exc).__name__}: {exc}"
                record(path, flight, "failed", sha, error=report["errors"][flight])
                continue
            if summary["status"] != "failed":
                report["processed"].append(flight)
                record(path, flight, "done", sha)
            else:
                report["failed"].append(flight)
                report["errors"][flight] = "; ".join(f"{f['segment']}: {f['error']}"
                                                     for f in summary["segments_failed"])
                record(path, flight, "failed", sha, error=report["errors"][flight])
    logger.info("inbox scan: %s", {k: len(v) for k, v in report.items()})
    return report


@flow(name="retry-failed", log_prints=True)
def retry_failed(out_root: str) -> dict:
    """Re-run the flights whose latest smoothing of some segment failed, as recorded in
    the ledger(s) under out_root.  Every other stage reuses its cached output (same
    inputs, same code), so only the failed segments are computed again."""
    import json

    root = Path(out_root)
    latest: dict[tuple, dict] = {}
    ledgers = [root / LEDGER_NAME] + [p for p in root.glob(f"*/{LEDGER_NAME}")]
    for led in ledgers:
        for rec in ledger.read(led):
            if rec.get("stage") == "smooth":
                latest[(str(led), rec["flight"], rec["segment"])] = rec
    failed = {(led, flight) for (led, flight, _), rec in latest.items() if rec["status"] == "failed"}
    results, errors, pools_done = [], {}, set()
    for led, flight in sorted(failed):
        # the failed record's own input is RUN_DIR/preprocessed.parquet: its folder is the run
        rec = next(r for (lp, fl, _), r in latest.items() if lp == led and fl == flight and r["status"] == "failed")
        run_dir = Path(rec["inputs"][0]["path"]).parent
        try:
            state = json.loads((run_dir / STATE_FILE).read_text())
            if state.get("pooled_into"):  # a manoeuvre of a pooled identification: re-run the pool
                pool_dir = run_dir.parent.parent  # POOL/flights/<id>/
                if pool_dir in pools_done:
                    continue
                pools_done.add(pool_dir)
                pool = PoolJob(**{**json.loads((pool_dir / STATE_FILE).read_text())["pool"], "ledger_path": led})
                with _claim(root / ".locks" / f"{pool.name}.lock") as mine:
                    if not mine:
                        errors[pool.name] = "busy: another run holds this pooled identification"
                        continue
                    try:
                        results.append(run_pooled(pool))
                    except Exception as exc:  # recorded in the pool's run.json and ledger; the others go on
                        errors[pool.name] = f"{type(exc).__name__}: {exc}"
                continue
            job = FlightJob(**{**state["job"], "ledger_path": led})
            with _claim(root / ".locks" / f"{flight}.lock") as mine:
                if not mine:
                    errors[flight] = "busy: another run holds this flight"
                    continue
                results.append(run_flights([job], isolate=True)[0])
        except (OSError, ValueError, KeyError) as exc:
            errors[flight] = f"{type(exc).__name__}: {exc}"
    return {"retried": [r["flight"] for r in results], "results": results, "errors": errors}
