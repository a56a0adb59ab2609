"""The result of :func:`aerosid.preprocess.preprocess`: the preprocessed frame with its
report (counts per flag, gaps, sensor profiles) and the Parquet metadata it is written with.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from schemas.telemetry import PHYSICAL_BOUNDS, UNITS

from . import sensors
from .flags import QualityFlag
from .params import PreprocessParams

#: Rows whose timestamps lie off the grid are a finding from this many rows on (a stray timestamp
#: or two is interpolated over and left unsaid).
JITTER_MIN_ROWS = 5
#: A stuck sensor, sentinel or out-of-range values are a finding from this duration on [s] (a
#: single bad value is an outlier's business: interpolated over).
SENSOR_FAULT_MIN_S = 0.1
#: Version of the output layout / algorithm (of core.py), recorded in the metadata.
PREPROCESS_VERSION = "2"


@dataclass(frozen=True, eq=False)
class PreprocessResult:
    """Output of :func:`preprocess` (treat every field as read-only).

    frame:
        The preprocessed frame (``schemas.telemetry.PreprocessedTelemetry``): ``t_s``
        (uniform grid), ``t_raw_s``, the 12 raw channels as received (NaN on inserted
        rows), ``<channel>_clean``, ``flags_<channel>`` and ``flags`` (uint16).
    params, source:
        What was asked, and the file the raw frame came from.
    nominal_rate_hz, dt_s, rate_inferred:
        The grid rate [Hz] and step [s]; whether the rate was inferred.
    n_raw_rows, n_grid_rows, n_inserted_rows:
        Row bookkeeping: ``n_grid_rows == n_raw_rows + n_inserted_rows``.
    flag_counts:
        Bit name -> number of grid rows where at least one channel has that bit.
    flag_counts_by_channel:
        Channel -> (bit name -> number of samples with that bit).
    n_usable_rows:
        Grid rows where every channel is usable (flags == 0: a new measurement, used
        by the Kalman filter as it is).
    n_usable_by_channel:
        Channel -> number of usable samples.
    n_used_rows:
        Recorded rows where every contract channel holds no fault: a measurement, or a
        held value between its sensor's updates (``HELD``).  The usable share of the
        record is ``n_used_rows / n_raw_rows``.
    n_used_by_channel:
        Channel -> recorded samples without a fault.
    sensors:
        Channel -> :class:`~aerosid.preprocess.sensors.SensorProfile` as a dict
        (resolution, update interval, at rest, frozen run length) plus the outlier
        ``threshold_sigma`` used.
    longest_gap_s:
        Longest run of rows where every channel is bad [s] (0 if none).
    longest_gap_s_by_channel:
        Channel -> longest run of bad samples of that channel [s].
    long_gaps:
        ``(t_start_s, t_end_s)`` grid times of the first and last sample of each
        all-channel gap longer than ``max_interp_gap_s`` (edges included).
    noise_sigma:
        Channel -> whole-record robust noise standard deviation (channel unit) used by
        the outlier test (a diagnostic, not the R estimate of method.md §4).
    ignored_columns:
        Input columns outside the contract, not carried over.
    retimed:
        ``(t_start_s, t_end_s, n_rows, shift_s)`` of every run of rows re-timed onto the grid
        because the record's sample phase moved at a dropout (grid times of its first and last
        row; shift_s = grid time - raw time, at most half a step; ``t_raw_s`` keeps the raw time).
    time_origin_s:
        What ``t_s`` and ``t_raw_s`` count from [s]: 0, or for a record stamped in absolute
        times (Unix time) its first timestamp's whole second (recorded time = t_raw_s + origin).
    """

    frame: pd.DataFrame
    params: PreprocessParams
    source: str
    nominal_rate_hz: float
    dt_s: float
    rate_inferred: bool
    n_raw_rows: int
    n_grid_rows: int
    n_inserted_rows: int
    flag_counts: dict
    flag_counts_by_channel: dict
    n_usable_rows: int
    n_usable_by_channel: dict
    longest_gap_s: float
    longest_gap_s_by_channel: dict
    long_gaps: tuple = ()
    noise_sigma: dict = field(default_factory=dict)
    ignored_columns: tuple = ()
    n_used_rows: int = 0
    n_used_by_channel: dict = field(default_factory=dict)
    sensors: dict = field(default_factory=dict)
    retimed: tuple = ()
    time_origin_s: float = 0.0

    @property
    def usable_share(self) -> dict:
        """Rows used of rows recorded, overall (every contract channel) and per channel."""
        rec = max(self.n_raw_rows, 1)
        return {"recorded": self.n_raw_rows, "used": self.n_used_rows, "share": self.n_used_rows / rec,
                "by_channel": {c: {"used": u, "share": u / rec} for c, u in self.n_used_by_channel.items()}}

    @property
    def findings(self) -> list:
        """The preprocessing's findings (aerosid.estimation.findings.Finding, segment "preprocess"),
        the data a run lost to its clock or its sensors, each with its span:

        * ``time_jitter`` (channel t_s): rows whose timestamp lies off the grid (``TIME_JITTER``),
          reported from JITTER_MIN_ROWS rows on -- the clock or the sample phase of the record is
          the engineer's to check;
        * ``phase_shift`` (channel t_s): a run of rows whose sample phase moved at a dropout,
          re-timed onto the grid and kept (``retimed``; nothing cut);
        * ``frozen``, ``sentinel``, ``out_of_range`` (per channel): a stuck sensor, sentinel values,
          values outside the physical bounds, reported from SENSOR_FAULT_MIN_S on.

        Runs closer than aerosid.estimation.findings.MERGE_GAP_S (as gated runs) are one finding.
        The samples are missing to the preprocessing (interpolated across when short); ``cut`` when
        part of the span is left empty (a gap longer than ``max_interp_gap_s``: no measurement there
        for the regression)."""
        from aerosid.estimation.findings import MERGE_GAP_S, Finding, merge_close, true_runs

        if self.frame.empty or "flags" not in self.frame:
            return []
        t = self.frame["t_s"].to_numpy(float)
        rate = self.nominal_rate_hz
        empty_bits = int(QualityFlag.LONG_GAP | QualityFlag.EDGE_GAP)
        out = []

        def spans(kind: str, channel: str, flags: np.ndarray, bit: int, min_n: int, detail) -> None:
            hit = (flags & bit) != 0
            for a, b in true_runs(merge_close(hit, max(1, int(round(MERGE_GAP_S * rate))))):
                n = int(hit[a:b].sum())
                if n >= min_n:
                    cut = bool(np.any(flags[a:b][hit[a:b]] & empty_bits))
                    out.append(Finding(kind, "preprocess", channel, float(t[a]), float(t[b - 1]), n, cut, detail(n)))

        spans("time_jitter", "t_s", self.frame["flags"].to_numpy().astype(np.int64), int(QualityFlag.TIME_JITTER),
              JITTER_MIN_ROWS,
              lambda n: f"{n} timestamp(s) lie more than snap_tolerance = {self.params.snap_tolerance:g} of a step "
                        f"from the {rate:.6g} Hz grid (clock jitter, or the sample phase moved after a dropout); "
                        "those rows are treated as missing: check the record's clock or nominal_rate_hz (if the "
                        "samples are uniform and only their stamps jitter, a larger snap_tolerance, up to 0.49, "
                        "keeps them: aerosid run --preprocess snap_tolerance=0.45)")
        for t0, t1, n, shift in self.retimed:
            out.append(Finding("phase_shift", "preprocess", "t_s", t0, t1, n, False,
                               f"the sample phase moved at a dropout: {n} row(s) lie {-shift / self.dt_s:+.2f} of a "
                               f"step off the {rate:.6g} Hz grid together; re-timed onto it by {1e3 * shift:+.3g} ms "
                               "and kept (every channel alike; t_raw_s keeps the recorded time): a recorder that "
                               "resumed on another phase, or telemetry thinned after dropouts"))
        min_n = max(2, int(round(SENSOR_FAULT_MIN_S * rate)))
        for col in [c for c in self.frame.columns if c.startswith("flags_")]:
            ch = col[len("flags_"):]
            flags = self.frame[col].to_numpy().astype(np.int64)
            lo, hi = PHYSICAL_BOUNDS.get(ch, (-np.inf, np.inf))
            unit = UNITS.get(ch, "")
            for kind, bit, what in (
                    ("frozen", QualityFlag.FROZEN, "repeats one value far beyond its update interval (a stuck "
                                                   "or dead sensor)"),
                    ("sentinel", QualityFlag.SENTINEL, "holds sentinel values (e.g. -9999: no measurement)"),
                    ("out_of_range", QualityFlag.OUT_OF_RANGE, f"lies outside its physical bounds {lo:g}..{hi:g} "
                                                               f"{unit} (a unit or scaling error?)")):
                spans(kind, ch, flags, int(bit), min_n,
                      lambda n, what=what, ch=ch: f"{ch} {what} on {n} sample(s); those samples are treated as "
                                                  "missing")
        return out

    @property
    def summary_counts(self) -> dict:
        """Rows of each kind: ``raw``, ``grid``, ``inserted``, ``usable`` and one entry
        per flag bit (rows with that bit in any channel)."""
        out = {"raw": self.n_raw_rows, "grid": self.n_grid_rows, "inserted": self.n_inserted_rows,
               "usable": self.n_usable_rows}
        out.update(self.flag_counts)
        return out

    def metadata(self) -> dict[str, str]:
        """Key/value strings for the Parquet file's metadata (``aerosid.preprocess.*``)."""
        p = "aerosid.preprocess."
        return {
            "aerosid.stage": "preprocess",
            p + "version": PREPROCESS_VERSION,
            p + "source": self.source,
            p + "params": json.dumps(self.params.to_dict(), sort_keys=True),
            p + "nominal_rate_hz": repr(self.nominal_rate_hz),
            p + "dt_s": repr(self.dt_s),
            p + "rate_inferred": json.dumps(self.rate_inferred),
            p + "summary_counts": json.dumps(self.summary_counts, sort_keys=True),
            p + "flag_counts_by_channel": json.dumps(self.flag_counts_by_channel, sort_keys=True),
            p + "longest_gap_s": repr(self.longest_gap_s),
            p + "longest_gap_s_by_channel": json.dumps(self.longest_gap_s_by_channel, sort_keys=True),
            p + "long_gaps": json.dumps([list(g) for g in self.long_gaps]),
            p + "noise_sigma": json.dumps(self.noise_sigma, sort_keys=True),
            p + "ignored_columns": json.dumps(list(self.ignored_columns)),
            p + "flag_bits": json.dumps({f.name: int(f) for f in QualityFlag}),
            p + "physical_bounds": json.dumps(PHYSICAL_BOUNDS, sort_keys=True),
            p + "usable_share": json.dumps(self.usable_share, sort_keys=True),
            p + "sensors": json.dumps(self.sensors, sort_keys=True),
            p + "retimed": json.dumps([list(r) for r in self.retimed]),
            p + "time_origin_s": repr(self.time_origin_s),
            "aerosid.findings": json.dumps([f.as_dict() for f in self.findings]),
        }

    def summary(self) -> str:
        """Human-readable per-flight summary."""
        share = self.usable_share
        lines = [
            f"preprocess {self.source}: {self.n_raw_rows} raw rows -> {self.n_grid_rows} grid rows "
            f"({self.n_inserted_rows} inserted) at {self.nominal_rate_hz:.6g} Hz "
            f"({'inferred' if self.rate_inferred else 'given'})"
            + (f"; times in s since {self.time_origin_s:.0f} (the record's first whole second)"
               if self.time_origin_s else ""),
            f"  rows used (every channel a measurement or a held value): {self.n_used_rows} of "
            f"{self.n_raw_rows} recorded ({100.0 * share['share']:.2f} %)",
            f"  usable rows (all channels): {self.n_usable_rows} "
            f"({100.0 * self.n_usable_rows / max(self.n_grid_rows, 1):.2f} %)",
            "  rows with flag: " + (", ".join(f"{k}={v}" for k, v in self.flag_counts.items() if v) or "none"),
            f"  longest all-channel gap: {self.longest_gap_s:.3f} s; "
            f"long gaps (> max_interp_gap_s = {self.params.max_interp_gap_s:g} s): {len(self.long_gaps)}"
            + "".join(f"\n    {a:.3f} .. {b:.3f} s" for a, b in self.long_gaps),
        ]
        for c in self.flag_counts_by_channel:
            counts = {k: v for k, v in self.flag_counts_by_channel[c].items() if v}
            if counts:
                lines.append(f"  {c}: used {100.0 * share['by_channel'][c]['share']:.1f} %, "
                             f"usable {self.n_usable_by_channel[c]}, "
                             f"longest bad run {self.longest_gap_s_by_channel[c]:.3f} s, "
                             + ", ".join(f"{k}={v}" for k, v in counts.items()))
        for c, prof in self.sensors.items():
            text = sensors.SensorProfile(**{k: (tuple(v) if k == "given" else v) for k, v in prof.items()
                                            if k != "threshold_sigma"}).describe(self.nominal_rate_hz,
                                                                                UNITS.get(c, ""))
            if text:
                lines.append(f"  sensor {c}: {text}")
        if self.ignored_columns:
            lines.append(f"  ignored columns: {list(self.ignored_columns)}")
        return "\n".join(lines)
