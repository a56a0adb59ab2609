"""Split a preprocessed flight into segments that are filtered on their own.

A flight splits at long telemetry gaps (the sync gap: the filter should not
predict across seconds of nothing) and at phase boundaries a user gives as time
windows.  Each segment is a contiguous row range of the preprocessed frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Segment:
    """Rows [start, stop) of the preprocessed frame; times [s]."""

    segment_id: str
    start: int
    stop: int
    t_start_s: float
    t_end_s: float

    @property
    def n_rows(self) -> int:
        return self.stop - self.start


def split_segments(t_s: np.ndarray, long_gaps: list[tuple[float, float]] = (), windows: list[tuple[float, float]] | None = None,
                   min_duration_s: float = 5.0) -> list[Segment]:
    """Segments of the uniform grid t_s [s]: the user's windows (or the whole flight),
    cut at every long gap (t_gap_start_s, t_gap_end_s); pieces shorter than
    min_duration_s are dropped (too short to initialise and smooth)."""
    t = np.asarray(t_s, dtype=float)
    if t.size == 0:
        return []
    spans = [(float(t[0]), float(t[-1]))] if not windows else [(float(a), float(b)) for a, b in windows]
    for a, b in spans:
        if not b > a:
            raise ValueError(f"time window ({a}, {b}) s is empty: the end must be after the start")
    pieces = []
    for a, b in spans:
        cuts = [(a, b)]
        for g0, g1 in sorted(long_gaps):
            nxt = []
            for c0, c1 in cuts:
                if g1 <= c0 or g0 >= c1:
                    nxt.append((c0, c1))
                    continue
                if g0 > c0:
                    nxt.append((c0, g0))
                if g1 < c1:
                    nxt.append((g1 + 1e-9, c1))  # the gap bounds are missing samples themselves
            cuts = nxt
        pieces.extend(cuts)
    segments = []
    for c0, c1 in pieces:
        start = int(np.searchsorted(t, c0, side="left"))
        # half-open [c0, c1) so that adjacent windows share no sample; the flight's last sample is kept
        stop = len(t) if c1 >= t[-1] else int(np.searchsorted(t, c1, side="left"))
        if stop - start < 2 or t[stop - 1] - t[start] < min_duration_s:
            continue
        segments.append(Segment(f"seg{len(segments):02d}", start, stop, float(t[start]), float(t[stop - 1])))
    return segments
