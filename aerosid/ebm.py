"""The whole method in memory, without orchestration: raw telemetry -> coefficients.

The Prefect flow (flows/pipeline.py) runs exactly these stage functions, one task
each, with Parquet files in between; this function is the reference it must
reproduce (a test checks that it does, to the last bit).
"""
from __future__ import annotations

from dataclasses import dataclass

import pandas as pd

from aerosid.estimation.findings import Finding
from aerosid.identification.flight_data import build_flight_data_segments, build_pooled_flight_data, load_database
from aerosid.identification.identify import Identification, identify
from aerosid.modelling.models import ChannelModel
from aerosid.preprocess import (DEFAULT_MIN_SEGMENT_S, PreprocessParams, PreprocessResult, merge_settings,
                                preprocess)
from aerosid.preprocess.segments import plan_segments
from aerosid.estimation.smoothing import SmoothedSegmentResult, smooth_segment_frame
from aerosid.vehicles.airspeed import as_true_airspeed
from aerosid.vehicles.vehicle import Vehicle


@dataclass(frozen=True)
class EBMRun:
    preprocessed: PreprocessResult
    smoothed: tuple[SmoothedSegmentResult, ...]
    flight_data: pd.DataFrame
    identification: Identification

    @property
    def findings(self) -> list[dict]:
        """Every finding of the run (aerosid.estimation.findings): the preprocessing's (timestamps
        off the grid, sensor faults), the smoother's and the flight data's, in segment order (as
        the flow's run.json)."""
        return ([f.as_dict() for f in self.preprocessed.findings]
                + [f.as_dict() for s in self.smoothed for f in s.findings]
                + list(self.flight_data.attrs.get("findings", [])))

    def summary(self) -> str:
        found = [Finding(**f).summary() for f in self.findings]
        return "\n\n".join([self.preprocessed.summary(), *(s.result.summary() for s in self.smoothed),
                            *(["findings:\n  " + "\n  ".join(found)] if found else []),
                            self.identification.summary()])


@dataclass(frozen=True)
class EBMFlightData:
    """The estimation half of the method: preprocessed telemetry, smoothed segments and
    the flight data the regression reads.  failed: (segment id, reason) of segments
    left out (only with ``skip_failed``)."""

    preprocessed: PreprocessResult
    smoothed: tuple[SmoothedSegmentResult, ...]
    flight_data: pd.DataFrame
    failed: tuple[tuple[str, str], ...] = ()

    def summary(self) -> str:
        failed = [f"segment {s} left out: {why}" for s, why in self.failed]
        return "\n\n".join([self.preprocessed.summary(), *(s.result.summary() for s in self.smoothed), *failed])


def preprocess_and_plan(raw: pd.DataFrame, vehicle: Vehicle, *, windows=None, preprocess_params: dict | None = None,
                        min_segment_s: float | None = None, source: str = "<memory>"):
    """Preprocessing with the vehicle file's [preprocess] table under the caller's
    settings, and the segment plan (min_segment_s None: the vehicle's, else 5 s, as the
    flow does).  Returns (PreprocessResult, segments); a plan with no segment is a
    ValueError naming the limit that refused the data."""
    params = merge_settings(vehicle.preprocess, preprocess_params or {})
    if min_segment_s is None:
        min_segment_s = vehicle.min_segment_s if vehicle.min_segment_s is not None else DEFAULT_MIN_SEGMENT_S
    raw = as_true_airspeed(raw, vehicle.airspeed_kind)[0]  # the vehicle file's [air_data] airspeed
    pre = preprocess(raw, PreprocessParams.from_dict(params), source=source)
    plan = plan_segments(pre.frame["t_s"].to_numpy(), list(pre.long_gaps), windows, min_segment_s,
                         pre.params.max_interp_gap_s)
    if not plan.segments:
        raise ValueError(plan.refusal())
    return pre, plan.segments


def estimate_flight_data(raw: pd.DataFrame, vehicle: Vehicle, *, flight: str = "flight", windows=None,
                         preprocess_params: dict | None = None, smoothing_options: dict | None = None,
                         min_segment_s: float | None = None, source: str = "<memory>",
                         skip_failed: bool = False, progress=None) -> EBMFlightData:
    """Raw telemetry -> flight data (preprocess, segments, EKF + MBF smoother, air data,
    coefficients, alpha/beta).  A segment that loses more than half its samples to
    findings is left out and recorded, as the flow does; with skip_failed, so is one whose
    smoothing fails; if none is left, ValueError.  progress: an optional callback
    progress(stage, fraction) (the CLI's display; the smoothing's fraction counts samples)."""
    report = progress or (lambda stage, fraction: None)
    report("preprocess", 0.0)
    pre, segments = preprocess_and_plan(raw, vehicle, windows=windows, preprocess_params=preprocess_params,
                                        min_segment_s=min_segment_s, source=source)
    db = load_database(vehicle)
    smoothed, failed = [], []
    total, done = max(sum(seg.stop - seg.start for seg in segments), 1), 0
    stage = f"smooth {len(segments)} segment(s)"
    for seg in segments:
        report(stage, done / total)
        done += seg.stop - seg.start
        rows = pre.frame.iloc[seg.start:seg.stop].reset_index(drop=True)
        try:
            sm = smooth_segment_frame(rows, vehicle, smoothing_options, seg.segment_id)
        except ValueError as exc:
            if not skip_failed:
                raise
            failed.append((seg.segment_id, str(exc)))
            continue
        if sm.lost:  # more than half the segment condemned by findings: failed, as the flow does (tasks.stages)
            failed.append((seg.segment_id, sm.lost_reason()))
            continue
        smoothed.append(sm)
    if not smoothed:
        why = "; ".join(f"{s}: {w}" for s, w in failed) or "no segment"
        raise ValueError(f"{source}: no segment could be smoothed ({why})")
    report("flight data", 0.0)
    fd = build_flight_data_segments(pre.frame, [s.frame for s in smoothed], vehicle, db, flight)
    return EBMFlightData(pre, tuple(smoothed), fd, tuple(failed))


def process_telemetry(raw: pd.DataFrame, vehicle: Vehicle, *, flight: str = "flight", windows=None,
                      models: dict[str, ChannelModel] | None = None, preprocess_params: dict | None = None,
                      smoothing_options: dict | None = None, mach_half_width: float | None = 0.5,
                      min_segment_s: float | None = None, source: str = "<memory>") -> EBMRun:
    """preprocess_params go on top of the vehicle file's [preprocess] table; min_segment_s
    None takes the vehicle's, else 5 s (as the flow does)."""
    est = estimate_flight_data(raw, vehicle, flight=flight, windows=windows, preprocess_params=preprocess_params,
                               smoothing_options=smoothing_options, min_segment_s=min_segment_s, source=source)
    fd = est.flight_data
    return EBMRun(est.preprocessed, est.smoothed, fd, identify(fd, vehicle, models, mach_half_width))


@dataclass(frozen=True)
class PooledEBMRun:
    """Several manoeuvres of one aircraft: each preprocessed and smoothed on its own
    (``flights``: flight id -> its preprocessing and smoothed segments), one regression
    on their pooled flight data."""

    flights: dict  # flight id -> (PreprocessResult, tuple[SmoothedSegmentResult, ...])
    flight_data: pd.DataFrame
    identification: Identification

    def summary(self) -> str:
        parts = [f"{len(self.flights)} manoeuvres pooled: {', '.join(self.flights)}"]
        for fid, (pre, smoothed) in self.flights.items():
            parts += [f"[{fid}]", pre.summary(), *(s.result.summary() for s in smoothed)]
        return "\n\n".join([*parts, self.identification.summary()])


def process_manoeuvres(raws: dict[str, pd.DataFrame], vehicle: Vehicle, *, windows=None,
                       models: dict[str, ChannelModel] | None = None, preprocess_params: dict | None = None,
                       smoothing_options: dict | None = None, mach_half_width: float | None = 0.5,
                       min_segment_s: float | None = None, sources: dict[str, str] | None = None) -> PooledEBMRun:
    """``raws``: flight id -> raw telemetry of one manoeuvre.  Each goes through
    preprocessing, segmentation and smoothing alone; the regression fits them together
    (the Prefect flow ``process_manoeuvres`` reproduces this)."""
    db = load_database(vehicle)
    per_flight, pooled = {}, []
    for fid, raw in raws.items():
        pre, segments = preprocess_and_plan(raw, vehicle, windows=windows, preprocess_params=preprocess_params,
                                            min_segment_s=min_segment_s, source=(sources or {}).get(fid, fid))
        smoothed = tuple(smooth_segment_frame(pre.frame.iloc[seg.start:seg.stop].reset_index(drop=True), vehicle,
                                              smoothing_options, seg.segment_id) for seg in segments)
        smoothed = tuple(s for s in smoothed if not getattr(s, "lost", False))  # as the flow fails them
        per_flight[fid] = (pre, smoothed)
        pooled.append((fid, pre.frame, [s.frame for s in smoothed]))
    fd = build_pooled_flight_data(pooled, vehicle, db)
    return PooledEBMRun(per_flight, fd, identify(fd, vehicle, models, mach_half_width))
