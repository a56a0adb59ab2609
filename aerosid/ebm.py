"""The whole method in memory, without orchestration: raw telemetry -> coefficients.

The Prefect flow (flows/pipeline.py) runs exactly these stage functions, one task
each, with Parquet files in between; this function is the reference it must
reproduce (a test checks that it does, to the last bit).
"""
from __future__ import annotations

from dataclasses import dataclass

import pandas as pd

from aerosid.estimation.findings import Finding
from aerosid.flight_data import build_flight_data_segments, load_database
from aerosid.identify import Identification, identify
from aerosid.models import ChannelModel
from aerosid.preprocess import PreprocessParams, PreprocessResult, preprocess
from aerosid.segments import split_segments
from aerosid.smoothing import SmoothedSegmentResult, smooth_segment_frame
from aerosid.vehicle import Vehicle


@dataclass(frozen=True)
class EBMRun:
    preprocessed: PreprocessResult
    smoothed: tuple[SmoothedSegmentResult, ...]
    flight_data: pd.DataFrame
    identification: Identification

    @property
    def findings(self) -> list[dict]:
        """Every finding of the run (aerosid.estimation.findings): the smoother's and the
        flight data's, in segment order."""
        return [f.as_dict() for s in self.smoothed for f in s.findings] + list(self.flight_data.attrs.get("findings", []))

    def summary(self) -> str:
        found = [Finding(**f).summary() for f in self.findings]
        return "\n\n".join([self.preprocessed.summary(), *(s.result.summary() for s in self.smoothed),
                            *(["findings:\n  " + "\n  ".join(found)] if found else []),
                            self.identification.summary()])


def process_telemetry(raw: pd.DataFrame, vehicle: Vehicle, *, flight: str = "flight", windows=None,
                      models: dict[str, ChannelModel] | None = None, preprocess_params: dict | None = None,
                      smoothing_options: dict | None = None, mach_half_width: float | None = 0.5,
                      min_segment_s: float = 5.0, source: str = "<memory>") -> EBMRun:
    pre = preprocess(raw, PreprocessParams(**(preprocess_params or {})), source=source)
    segments = split_segments(pre.frame["t_s"].to_numpy(), list(pre.long_gaps), windows, min_segment_s)
    db = load_database(vehicle)
    smoothed = [smooth_segment_frame(pre.frame.iloc[seg.start:seg.stop].reset_index(drop=True), vehicle,
                                     smoothing_options, seg.segment_id) for seg in segments]
    smoothed = [s for s in smoothed if not s.lost]  # as the flow fails them (tasks.stages)
    if not smoothed:
        raise ValueError("no segment could be processed: every segment lost more than half its samples to findings")
    fd = build_flight_data_segments(pre.frame, [s.frame for s in smoothed], vehicle, db, flight)
    return EBMRun(pre, tuple(smoothed), fd, identify(fd, vehicle, models, mach_half_width))
