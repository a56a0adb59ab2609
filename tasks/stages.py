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

from aerosid.identification.flight_data import (build_flight_data_segments, build_pooled_flight_data, flight_air_data_sources,
                                 load_database)
from aerosid.identification.identify import default_bias_pairs, identify
from aerosid.modelling.models import default_models, load_models
from aerosid.plausibility.estimates import implausible_estimate_findings
from aerosid.plausibility.geometry import geometry_findings
from aerosid.plausibility.units import check_units
from aerosid.preprocess import PreprocessParams, preprocess
from aerosid.preprocess.segments import plan_segments
from aerosid.estimation.smoothing import smooth_segment_frame
from aerosid.vehicles.airspeed import as_true_airspeed
from aerosid.vehicles.vehicle import load_vehicle
from schemas.coefficients import Coefficients
from schemas.flight_data import FlightData
from schemas.smoothed import SmoothedSegment
from schemas.telemetry import PreprocessedTelemetry, RawTelemetry
from tasks import progress
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
def preprocess_task(raw_path: str, run_dir: str, ctx: StageContext, params: dict, vehicle: str | None = None) -> dict:
    """Preprocess the raw telemetry; with the vehicle, its units and signs are checked first
    (aerosid.plausibility.units: the same check as `aerosid run`'s pre-flight, here for the
    inbox and campaign flows too)."""
    out = Path(run_dir) / "preprocessed.parquet"

    def produce() -> Produced:
        raw = read_validated(raw_path, RawTelemetry)
        converted = ""
        if vehicle is not None:
            veh = load_vehicle(vehicle)
            raw, converted = as_true_airspeed(raw, veh.airspeed_kind)
            check_units(raw, veh, raw_path)
        result = preprocess(raw, PreprocessParams.from_dict(params), source=raw_path)
        flagged = int((result.frame["flags"] != 0).sum())
        meta = {**result.metadata(), **({"aerosid.airspeed": converted} if converted else {})}
        return Produced(result.frame, meta, rows_in=len(raw), flagged_rows=flagged,
                        note="\n".join(filter(None, (result.summary(), converted))))

    done = execute("preprocess", ctx, [raw_path], out, params, PreprocessedTelemetry, produce)
    from aerosid.io import read_parquet_metadata

    meta = read_parquet_metadata(out)  # also when the output is reused
    share = meta.get("aerosid.preprocess.usable_share")
    done = {**done, "findings": json.loads(meta.get("aerosid.findings", "[]")),
            "time_origin_s": float(meta.get("aerosid.preprocess.time_origin_s", "0.0"))}
    return {**done, "usable_share": json.loads(share)} if share else done


@task(name="plan-segments", **IO_RETRIES)
def plan_segments_task(pre_path: str, windows: list | None, min_duration_s: float) -> dict:
    """Segments of the flight (at long gaps and user windows) as plain dicts, and the
    pieces left out with the limit that left them out (``dropped``, ``note``,
    ``refusal``: messages naming min_segment_s and max_interp_gap_s)."""
    from aerosid.io import read_parquet_metadata

    meta = read_parquet_metadata(pre_path)
    gaps = json.loads(meta.get("aerosid.preprocess.long_gaps", "[]"))
    limit = json.loads(meta.get("aerosid.preprocess.params", "{}")).get("max_interp_gap_s")
    t = pd.read_parquet(pre_path, columns=["t_s"])["t_s"].to_numpy()
    plan = plan_segments(t, [tuple(g) for g in gaps], windows, min_duration_s, limit)
    progress.emit(f"plan: {Path(pre_path).parent.name}, {len(plan.segments)} segment(s)", 1.0)
    return {"segments": [s.__dict__ for s in plan.segments], "dropped": [d.__dict__ for d in plan.dropped],
            "note": plan.dropped_note(), "refusal": plan.refusal() if not plan.segments else None}


@task(name="smooth-segment", **IO_RETRIES)
def smooth_segment_task(pre_path: str, run_dir: str, ctx: StageContext, segment: dict, vehicle: str,
                        options: dict) -> dict:
    out = Path(run_dir) / "segments" / segment["segment_id"] / "smoothed.parquet"
    params = {"segment": segment, "vehicle": vehicle, "options": options}

    def produce() -> Produced:
        pre = read_validated(pre_path, PreprocessedTelemetry)
        rows = pre.iloc[segment["start"]:segment["stop"]].reset_index(drop=True)
        smoothed = smooth_segment_frame(rows, load_vehicle(vehicle), options, segment["segment_id"])
        if smoothed.lost:
            raise StageFailed(f"segment {segment['segment_id']}: {smoothed.lost_reason()}")
        findings_seen.extend(f.as_dict() for f in smoothed.findings)
        return Produced(smoothed.frame, {"aerosid.nis": smoothed.nis_record(),
                                         "aerosid.findings": json.dumps(list(findings_seen))}, rows_in=len(rows),
                        flagged_rows=int(smoothed.result.gate_flags.any(axis=1).sum()),
                        note=smoothed.result.summary())

    findings_seen: list = []
    result = execute("smooth", ctx, [pre_path, *vehicle_files(vehicle)], out, params, SmoothedSegment, produce)
    return {**result, "findings": findings_seen or stored_findings(result["path"])}


@task(name="flight-data", **IO_RETRIES)
def flight_data_task(pre_path: str, smoothed_paths: list[str], run_dir: str, ctx: StageContext, vehicle: str) -> dict:
    out = Path(run_dir) / "flight_data.parquet"

    def produce() -> Produced:
        veh = load_vehicle(vehicle)
        db = load_database(veh)
        pre = read_validated(pre_path, PreprocessedTelemetry)
        smoothed = [read_validated(path, SmoothedSegment) for path in smoothed_paths]
        frame = build_flight_data_segments(pre, smoothed, veh, db, ctx.flight)
        findings_seen.extend(frame.attrs.get("findings", []))
        timing_seen.extend(frame.attrs.get("vane_timing", []))
        sources = {ctx.flight: flight_air_data_sources(pre.columns, veh.airspeed_kind)}
        return Produced(frame, {"aerosid.air_data": sources,
                                "aerosid.findings": json.dumps(list(findings_seen)),
                                "aerosid.vane_timing": json.dumps(list(timing_seen))},
                        rows_in=sum(len(sm) for sm in smoothed))

    findings_seen: list = []
    timing_seen: list = []
    result = execute("flight_data", ctx, [pre_path, *smoothed_paths, *vehicle_files(vehicle)], out,
                     {"vehicle": vehicle, "flight": ctx.flight}, FlightData, produce)
    return {**result, "findings": findings_seen or stored_findings(result["path"]),
            "vane_timing": timing_seen or stored_findings(result["path"], "aerosid.vane_timing")}


def stored_findings(path: str, key: str = "aerosid.findings") -> list:
    """The findings (or another list under key, e.g. the vanes' timing) a stage recorded in its
    Parquet file's metadata (a reused output)."""
    from aerosid.io import read_parquet_metadata

    return json.loads(read_parquet_metadata(path).get(key, "[]"))


@task(name="pooled-flight-data", **IO_RETRIES)
def pooled_flight_data_task(flights: list[dict], run_dir: str, ctx: StageContext, vehicle: str) -> dict:
    """Flight data of several manoeuvres in one file: ``flights`` holds per manoeuvre
    ``{"flight", "preprocessed", "smoothed": [paths]}`` (aerosid.identification.flight_data.build_pooled_flight_data)."""
    out = Path(run_dir) / "flight_data.parquet"
    inputs = [p for f in flights for p in (f["preprocessed"], *f["smoothed"])]

    def produce() -> Produced:
        veh = load_vehicle(vehicle)
        pooled, sources = [], {}
        for f in flights:
            pre = read_validated(f["preprocessed"], PreprocessedTelemetry)
            pooled.append((f["flight"], pre, [read_validated(p, SmoothedSegment) for p in f["smoothed"]]))
            sources[f["flight"]] = flight_air_data_sources(pre.columns, veh.airspeed_kind)
        frame = build_pooled_flight_data(pooled, veh, load_database(veh))
        findings_seen.extend(frame.attrs.get("findings", []))
        timing_seen.extend(frame.attrs.get("vane_timing", []))
        return Produced(frame, {"aerosid.air_data": sources, "aerosid.findings": json.dumps(list(findings_seen)),
                                "aerosid.vane_timing": json.dumps(list(timing_seen))},
                        rows_in=sum(len(sm) for _, _, s in pooled for sm in s))

    findings_seen: list = []
    timing_seen: list = []
    result = execute("flight_data", ctx, [*inputs, *vehicle_files(vehicle)], out,
                     {"vehicle": vehicle, "flights": [f["flight"] for f in flights]}, FlightData, produce)
    return {**result, "findings": findings_seen or stored_findings(result["path"]),
            "vane_timing": timing_seen or stored_findings(result["path"], "aerosid.vane_timing")}


@task(name="regression", **IO_RETRIES)
def regression_task(flight_data_paths: list[str], run_dir: str, ctx: StageContext, vehicle: str,
                    model_spec: str | None, mach_half_width: float | None) -> dict:
    out = Path(run_dir) / "coefficients.parquet"
    inputs = list(flight_data_paths) + ([model_spec] if model_spec else []) + vehicle_files(vehicle)
    # the estimator-bias check's setting changes the sigma: part of the cache key and the lineage
    pairs = default_bias_pairs()
    params = {"vehicle": vehicle, "mach_half_width": mach_half_width, "model_spec": bool(model_spec),
              "bias_pairs": pairs}

    def produce() -> Produced:
        veh = load_vehicle(vehicle)
        fd = pd.concat([read_validated(p, FlightData) for p in flight_data_paths], ignore_index=True)
        models = load_models(model_spec, base=default_models(veh), mach_reference=veh.mach_reference) \
            if model_spec else None
        ident = identify(fd, veh, models, mach_half_width, bias_pairs=pairs)
        table = ident.table()
        findings_seen.extend(implausible_estimate_findings(table, fd["t_s"]) + geometry_findings(veh, fd["t_s"]))
        return Produced(table, {"aerosid.summary": ident.summary(), "aerosid.findings": json.dumps(findings_seen)},
                        rows_in=len(fd), note=ident.summary())

    findings_seen: list = []
    result = execute("regression", ctx, inputs, out, params, Coefficients, produce)
    return {**result, "findings": findings_seen or stored_findings(result["path"])}
