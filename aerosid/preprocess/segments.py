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


@dataclass(frozen=True)
class DroppedPiece:
    """A piece of the flight that is not smoothed, and why (times [s])."""

    t_start_s: float
    t_end_s: float
    source: str   # where the piece comes from: "the whole flight", "window 0..4.5 s"
    cut_at_gap: bool  # a long gap ends or starts it
    reason: str


#: How a user changes the limits that drop pieces (named in every message).
MIN_SEGMENT_HOW = ("aerosid run --min-segment-s SECONDS, or min_segment_s in the vehicle file's "
                   "[preprocess] table")
GAP_HOW = ("aerosid run --preprocess max_interp_gap_s=SECONDS, or max_interp_gap_s in the vehicle file's "
           "[preprocess] table")


@dataclass(frozen=True)
class SegmentPlan:
    """The segments to smooth and the pieces left out (with the limit that left them out)."""

    segments: tuple[Segment, ...]
    dropped: tuple[DroppedPiece, ...]
    min_duration_s: float
    long_gaps: tuple[tuple[float, float], ...] = ()
    max_interp_gap_s: float | None = None

    def _gaps_note(self) -> str:
        if not any(p.cut_at_gap for p in self.dropped):
            return ""
        limit = f" = {self.max_interp_gap_s:g} s" if self.max_interp_gap_s is not None else ""
        spans = ", ".join(f"{a:.2f}..{b:.2f} s" for a, b in self.long_gaps[:5])
        more = f" (+{len(self.long_gaps) - 5} more)" if len(self.long_gaps) > 5 else ""
        return (f" The flight is cut at {len(self.long_gaps)} gap(s) where every channel is bad for longer than "
                f"max_interp_gap_s{limit} ({spans}{more}); to bridge shorter ones raise it: {GAP_HOW}.")

    def dropped_note(self) -> str:
        """One paragraph naming every dropped piece and the limits (empty if none)."""
        if not self.dropped:
            return ""
        pieces = "; ".join(f"{p.t_start_s:.2f}..{p.t_end_s:.2f} s ({p.source}): {p.reason}" for p in self.dropped)
        return (f"{len(self.dropped)} piece(s) of the flight not smoothed: {pieces}. The minimum segment length is "
                f"min_segment_s = {self.min_duration_s:g} s; change it with {MIN_SEGMENT_HOW}." + self._gaps_note())

    def refusal(self) -> str:
        """The message when no segment is left."""
        if not self.dropped:
            return "no segment to smooth: the flight has no samples"
        return "no segment to smooth. " + self.dropped_note()


def plan_segments(t_s: np.ndarray, long_gaps: list[tuple[float, float]] = (),
                  windows: list[tuple[float, float]] | None = None, min_duration_s: float = 5.0,
                  max_interp_gap_s: float | None = None) -> SegmentPlan:
    """Segments of the uniform grid t_s [s]: the user's windows (or the whole flight),
    cut at every long gap (t_gap_start_s, t_gap_end_s); pieces shorter than
    min_duration_s are dropped (too short to initialise and smooth) and listed, with
    the limit, in the plan.  ``max_interp_gap_s`` (the limit that made the long gaps)
    is only quoted in messages."""
    t = np.asarray(t_s, dtype=float)
    if t.size == 0:
        return SegmentPlan((), (), float(min_duration_s), (), max_interp_gap_s)
    spans = [(float(t[0]), float(t[-1]))] if not windows else [(float(a), float(b)) for a, b in windows]
    for a, b in spans:
        if not b > a:
            raise ValueError(f"time window ({a}, {b}) s is empty: the end must be after the start")
    gaps = sorted((float(a), float(b)) for a, b in long_gaps)
    pieces = []
    for a, b in spans:
        source = "the whole flight" if not windows else f"window {a:g}..{b:g} s"
        cuts = [(a, b, False)]
        for g0, g1 in gaps:
            nxt = []
            for c0, c1, cut in cuts:
                if g1 <= c0 or g0 >= c1:
                    nxt.append((c0, c1, cut))
                    continue
                if g0 > c0:
                    nxt.append((c0, g0, True))
                if g1 < c1:
                    nxt.append((g1 + 1e-9, c1, True))  # the gap bounds are missing samples themselves
            cuts = nxt
        pieces.extend((c0, c1, cut, source) for c0, c1, cut in cuts)
    segments, dropped = [], []
    for c0, c1, cut, source in pieces:
        start = int(np.searchsorted(t, c0, side="left"))
        # half-open [c0, c1) so that adjacent windows share no sample; the flight's last sample is kept
        stop = len(t) if c1 >= t[-1] else int(np.searchsorted(t, c1, side="left"))
        if stop - start < 2:
            dropped.append(DroppedPiece(c0, c1, source, cut, f"no samples there (the record spans "
                                        f"{t[0]:.2f}..{t[-1]:.2f} s)"))
            continue
        length = float(t[stop - 1] - t[start])
        if length < min_duration_s:
            dropped.append(DroppedPiece(float(t[start]), float(t[stop - 1]), source, cut,
                                        f"{length:.2f} s long, shorter than min_segment_s = {min_duration_s:g} s"
                                        + (" (cut at a long gap)" if cut else "")))
            continue
        segments.append(Segment(f"seg{len(segments):02d}", start, stop, float(t[start]), float(t[stop - 1])))
    return SegmentPlan(tuple(segments), tuple(dropped), float(min_duration_s), tuple(gaps), max_interp_gap_s)


def split_segments(t_s: np.ndarray, long_gaps: list[tuple[float, float]] = (), windows: list[tuple[float, float]] | None = None,
                   min_duration_s: float = 5.0) -> list[Segment]:
    """The segments of :func:`plan_segments` (pieces shorter than min_duration_s are dropped)."""
    return list(plan_segments(t_s, long_gaps, windows, min_duration_s).segments)
