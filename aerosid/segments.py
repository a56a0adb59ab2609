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


def no_segment_reason(t_s: np.ndarray, long_gaps: list[tuple[float, float]] = (),
                      windows: list[tuple[float, float]] | None = None, min_duration_s: float = 5.0) -> str:
    """Why split_segments found nothing: what the flight spans, the windows, the long
    gaps and the longest piece left between them."""
    t = np.asarray(t_s, dtype=float)
    if t.size == 0:
        return "the flight has no samples"
    parts = [f"the flight spans t = {t[0] + 0.0:.2f}..{t[-1]:.2f} s ({t.size} samples)".replace("-0.00", "0.00")]
    if windows:
        parts.append("the windows " + ", ".join(f"{a:g}..{b:g} s" for a, b in windows))
        inside = [(a, b) for a, b in windows if b > t[0] and a < t[-1]]
        if not inside:
            parts.append("none of which overlaps the flight")
    if long_gaps:
        total = sum(b - a for a, b in long_gaps)
        parts.append(f"{len(long_gaps)} long gap(s) of unusable data cover {total:.2f} s")
    # the longest piece any cut left
    spans = [(float(t[0]), float(t[-1]))] if not windows else [(float(a), float(b)) for a, b in windows]
    edges = sorted(long_gaps)
    longest = 0.0
    for a, b in spans:
        start = max(a, float(t[0]))
        for g0, g1 in edges:
            if g1 <= start or g0 >= b:
                continue
            longest = max(longest, min(g0, b) - start)
            start = max(start, g1)
        longest = max(longest, min(b, float(t[-1])) - start)
    parts.append(f"the longest usable piece is {max(longest, 0.0):.2f} s, shorter than the {min_duration_s:g} s "
                 "a segment needs")
    return "; ".join(parts)


def flag_note(flag_counts_by_channel: dict, n_samples: int) -> str:
    """'; preprocessing flagged FROZEN at up to 8553 samples of ax_m_s2, ...' for the flags
    that make samples unusable (not the bookkeeping ones) on at least 10 % of the
    samples of some channel, most frequent first."""
    skip = {"MISSING_ROW", "INTERPOLATED", "LONG_GAP", "EDGE_GAP"}
    by_flag: dict[str, list[tuple[int, str]]] = {}
    for channel, counts in flag_counts_by_channel.items():
        for flag, n in counts.items():
            if flag not in skip and n >= 0.1 * n_samples:
                by_flag.setdefault(flag, []).append((int(n), channel))
    if not by_flag:
        return ""
    parts = []
    for flag, items in sorted(by_flag.items(), key=lambda kv: -max(n for n, _ in kv[1]))[:3]:
        items.sort(reverse=True)
        chans = ", ".join(c for _, c in items[:4]) + (f" and {len(items) - 4} more" if len(items) > 4 else "")
        parts.append(f"{flag} at up to {items[0][0]} samples of {chans}")
    return "; preprocessing flagged " + "; ".join(parts)
