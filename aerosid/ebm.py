"""The whole method in memory, without orchestration: raw telemetry -> coefficients.

The Prefect flow (flows/pipeline.py) runs exactly these stage functions, one task
each, with Parquet files in between; this function is the reference it must
reproduce (a test checks that it does, to the last bit).
"""
from __future__ import annotations

from dataclasses import dataclass

import pandas as pd

from aerosid.flight_data import build_flight_data_segments, load_database
from aerosid.identify import Identification, identify
from aerosid.models import ChannelModel
from aerosid.preprocess import (DEFAULT_MIN_SEGMENT_S, PreprocessParams, PreprocessResult, merge_settings,
                                preprocess)
from aerosid.segments import plan_segments
from aerosid.smoothing import SmoothedSegmentResult, smooth_segment_frame
from aerosid.vehicle import Vehicle


@dataclass(frozen=True)
class EBMRun:
    preprocessed: PreprocessResult
    smoothed: tuple[SmoothedSegmentResult, ...]
    flight_data: pd.DataFrame
    identification: Identification

    def summary(self) -> str:
        return "\n\n".join([self.preprocessed.summary(), *(s.result.summary() for s in self.smoothed),
                            self.identification.summary()])


def process_telemetry(raw: pd.DataFrame, vehicle: Vehicle, *, flight: str = "flight", windows=None,
                      models: dict[str, ChannelModel] | None = None, preprocess_params: dict | None = None,
                      smoothing_options: dict | None = None, mach_half_width: float | None = 0.5,
                      min_segment_s: float | None = None, source: str = "<memory>") -> EBMRun:
    """preprocess_params go on top of the vehicle file's [preprocess] table; min_segment_s
    None takes the vehicle's, else 5 s (as the flow does)."""
    params = merge_settings(vehicle.preprocess, preprocess_params or {})
    if min_segment_s is None:
        min_segment_s = vehicle.min_segment_s if vehicle.min_segment_s is not None else DEFAULT_MIN_SEGMENT_S
    pre = preprocess(raw, PreprocessParams.from_dict(params), source=source)
    plan = plan_segments(pre.frame["t_s"].to_numpy(), list(pre.long_gaps), windows, min_segment_s,
                         pre.params.max_interp_gap_s)
    if not plan.segments:
        raise ValueError(plan.refusal())
    segments = plan.segments
    db = load_database(vehicle)
    smoothed = [smooth_segment_frame(pre.frame.iloc[seg.start:seg.stop].reset_index(drop=True), vehicle,
                                     smoothing_options, seg.segment_id) for seg in segments]
    fd = build_flight_data_segments(pre.frame, [s.frame for s in smoothed], vehicle, db, flight)
    return EBMRun(pre, tuple(smoothed), fd, identify(fd, vehicle, models, mach_half_width))
