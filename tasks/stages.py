"""Prefect tasks, one per stage: read validated Parquet -> call the core -> write
validated Parquet atomically + a ledger record.  No numerics here.

Retries are for I/O only (``OSError``: a busy network share, a full disk being
cleared); a numerical or data failure fails at once, is recorded in the ledger
and, for a segment, leaves the other segments to go on.
"""
from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
from prefect import task

from aerosid.flight_data import build_flight_data_segments, load_database
from aerosid.identify import identify
from aerosid.models import default_models, load_models
from aerosid.preprocess import PreprocessParams, preprocess
from aerosid.segments import flag_note, no_segment_reason, split_segments
from aerosid.smoothing import smooth_segment_frame
from aerosid.vehicle import load_vehicle
from schemas.coefficients import Coefficients
from schemas.flight_data import FlightData
from schemas.smoothed import SmoothedSegment
from schemas.telemetry import PreprocessedTelemetry, RawTelemetry
from tasks.runner import Produced, StageContext, StageFailed, execute, read_validated


def retry_on_io(task, task_run, state) -> bool:
    """Prefect retry_condition_fn: retry only when the task failed with an OSError."""
    try:
        state.result()
    except OSError:
        return True
    except Exception:
        return False
    return False


def vehicle_files(vehicle: str) -> list[str]:
    """The vehicle description and its database: their content enters the cache keys."""
    veh = load_vehicle(vehicle)
    return [veh.source] + ([str(veh.database_path)] if veh.database_path is not None else [])


IO_RETRIES = {"retries": 2, "retry_delay_seconds": [0.2, 1.0], "retry_condition_fn": retry_on_io}


@task(name="preprocess", **IO_RETRIES)
def preprocess_task(raw_path: str, run_dir: str, ctx: StageContext, params: dict) -> dict:
    out = Path(run_dir) / "preprocessed.parquet"

    def produce() -> Produced:
        raw = read_validated(raw_path, RawTelemetry)
        result = preprocess(raw, PreprocessParams(**params), source=raw_path)
        counts = result.summary_counts
        flagged = int((result.frame["flags"] != 0).sum())
        return Produced(result.frame, result.metadata(), rows_in=len(raw), flagged_rows=flagged,
                        note=result.summary())

    return execute("preprocess", ctx, [raw_path], out, params, PreprocessedTelemetry, produce)


@task(name="plan-segments", **IO_RETRIES)
def plan_segments_task(pre_path: str, windows: list | None, min_duration_s: float) -> list[dict]:
    """Segments of the flight (at long gaps and user windows), as plain dicts."""
    from aerosid.io import read_parquet_metadata

    meta = read_parquet_metadata(pre_path)
    gaps = json.loads(next((v for k, v in meta.items() if k.endswith("long_gaps")), "[]"))
    t = pd.read_parquet(pre_path, columns=["t_s"])["t_s"].to_numpy()
    segs = split_segments(t, [tuple(g) for g in gaps], windows, min_duration_s)
    if not segs:
        counts = json.loads(next((v for k, v in meta.items() if k.endswith("flag_counts_by_channel")), "{}"))
        raise StageFailed(f"{pre_path}: no segment to filter: "
                          f"{no_segment_reason(t, [tuple(g) for g in gaps], windows, min_duration_s)}"
                          f"{flag_note(counts, len(t))}")
    return [s.__dict__ for s in segs]


@task(name="smooth-segment", **IO_RETRIES)
def smooth_segment_task(pre_path: str, run_dir: str, ctx: StageContext, segment: dict, vehicle: str,
                        options: dict) -> dict:
    out = Path(run_dir) / "segments" / segment["segment_id"] / "smoothed.parquet"
    params = {"segment": segment, "vehicle": vehicle, "options": options}

    def produce() -> Produced:
        pre = read_validated(pre_path, PreprocessedTelemetry)
        rows = pre.iloc[segment["start"]:segment["stop"]].reset_index(drop=True)
        smoothed = smooth_segment_frame(rows, load_vehicle(vehicle), options, segment["segment_id"])
        if smoothed.result.diverged:
            raise StageFailed(f"segment {segment['segment_id']}: filter diverged: {smoothed.divergence_note()}")
        return Produced(smoothed.frame, {"aerosid.nis": smoothed.nis_record()}, rows_in=len(rows),
                        flagged_rows=int(smoothed.result.gate_flags.any(axis=1).sum()),
                        note=smoothed.result.summary())

    return execute("smooth", ctx, [pre_path, *vehicle_files(vehicle)], out, params, SmoothedSegment, produce)


@task(name="flight-data", **IO_RETRIES)
def flight_data_task(pre_path: str, smoothed_paths: list[str], run_dir: str, ctx: StageContext, vehicle: str) -> dict:
    out = Path(run_dir) / "flight_data.parquet"

    def produce() -> Produced:
        veh = load_vehicle(vehicle)
        db = load_database(veh)
        pre = read_validated(pre_path, PreprocessedTelemetry)
        smoothed = [read_validated(path, SmoothedSegment) for path in smoothed_paths]
        frame = build_flight_data_segments(pre, smoothed, veh, db, ctx.flight)
        return Produced(frame, {}, rows_in=sum(len(sm) for sm in smoothed))

    return execute("flight_data", ctx, [pre_path, *smoothed_paths, *vehicle_files(vehicle)], out,
                   {"vehicle": vehicle, "flight": ctx.flight}, FlightData, produce)


@task(name="regression", **IO_RETRIES)
def regression_task(flight_data_paths: list[str], run_dir: str, ctx: StageContext, vehicle: str,
                    model_spec: str | None, mach_half_width: float | None) -> dict:
    out = Path(run_dir) / "coefficients.parquet"
    inputs = list(flight_data_paths) + ([model_spec] if model_spec else []) + vehicle_files(vehicle)
    params = {"vehicle": vehicle, "mach_half_width": mach_half_width, "model_spec": bool(model_spec)}

    def produce() -> Produced:
        veh = load_vehicle(vehicle)
        fd = pd.concat([read_validated(p, FlightData) for p in flight_data_paths], ignore_index=True)
        models = load_models(model_spec, base=default_models(veh)) if model_spec else None
        ident = identify(fd, veh, models, mach_half_width)
        return Produced(ident.table(), {"aerosid.summary": ident.summary()}, rows_in=len(fd), note=ident.summary())

    return execute("regression", ctx, inputs, out, params, Coefficients, produce)
