"""preprocess(): raw telemetry -> uniform grid, raw kept, per-sample quality flags.

Pipeline (method.md §1), all vectorised:

1. **Structure.**  The 13 contract columns must be present and float64, ``t_s``
   finite and strictly increasing (otherwise ``TelemetryError`` naming file, column
   and rows); then the ``RawTelemetry`` schema is enforced.  Extra columns are not
   carried over; their names are recorded (``ignored_columns``).
2. **Grid.**  dt = 1 / ``nominal_rate_hz``, or the median interval when that is
   ``None``.  The grid origin is the circular mean phase of the timestamps, so
   jitter does not shift it.  Each raw row goes to its nearest grid point; rows
   further than ``snap_tolerance`` steps away are flagged ``TIME_JITTER``; two rows
   on one grid point raise ``TelemetryError``.  Grid points without a raw row are
   inserted (``MISSING_ROW``; raw columns and ``t_raw_s`` NaN).
3. **Per channel detection** on the grid: ``NAN``, ``SENTINEL``, ``OUT_OF_RANGE``,
   ``FROZEN`` (stuck runs), then ``OUTLIER`` (two-sided spike test on what is left,
   see ``detect.spike_mask``).
4. **Gap policy** per channel: each maximal run of samples with a detection bit is
   ``INTERPOLATED`` linearly between its good neighbours when it is no longer than
   ``max_interp_gap_s`` and has good samples on both sides; otherwise it is left NaN
   in ``<channel>_clean`` (``LONG_GAP`` and/or ``EDGE_GAP``).
5. **Row-level gaps**: runs of grid rows where *every* channel has a detection bit.
   Those longer than ``max_interp_gap_s`` are ``long_gaps`` (the pipeline splits
   segments there; the sync gap is one); the longest is ``longest_gap_s``.
6. The output is enforced against ``PreprocessedTelemetry``.

Durations: a run of n grid samples lasts n * dt (the time not covered by data).
"""
from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from schemas.telemetry import (
    AIR_DATA_CHANNELS,
    CHANNELS,
    DEFAULT_SENTINELS,
    PHYSICAL_BOUNDS,
    RAW_COLUMNS,
    PreprocessedTelemetry,
    RawTelemetry,
    sentinel_mask,
    validate,
)

from . import detect
from .errors import TelemetryError
from .flags import DETECTION, FLAGS_DTYPE, UNUSABLE, QualityFlag

#: Version of the output layout / algorithm, recorded in the metadata.
PREPROCESS_VERSION = "1"

#: Default floor of the noise scale per channel, in the channel's unit (sigma of the
#: outlier test never goes below it: protects noise-free or constant channels).
DEFAULT_MIN_NOISE_SCALE: tuple[tuple[str, float], ...] = (
    ("ax_m_s2", 1e-3), ("ay_m_s2", 1e-3), ("az_m_s2", 1e-3),
    ("p_rad_s", 1e-4), ("q_rad_s", 1e-4), ("r_rad_s", 1e-4),
    ("d1_rad", 1e-5), ("d2_rad", 1e-5), ("d3_rad", 1e-5), ("d4_rad", 1e-5),
    ("V_m_s", 1e-3), ("h_m", 1e-2), ("alpha_vane_rad", 1e-5), ("beta_vane_rad", 1e-5),
    # measured air data: without a floor a constant column (SIDPAC logs one density per
    # manoeuvre) has noise scale 0 and every sample would be an "outlier"
    ("rho_kg_m3", 1e-6), ("qbar_pa", 1e-2), ("p_static_pa", 1e-2), ("T_total_K", 1e-4),
)

#: Hard cap on the grid size (a clock jump would otherwise allocate without bound).
MAX_GRID_ROWS = 50_000_000


@dataclass(frozen=True)
class PreprocessParams:
    """Thresholds of the preprocessing stage (all recorded in the output metadata).

    nominal_rate_hz:
        Sample rate of the grid [Hz]; ``None`` infers it as 1 / median interval.
    snap_tolerance:
        A raw timestamp further than this many grid steps (fraction of dt) from its
        nearest grid point is flagged ``TIME_JITTER`` (still placed there).
    max_interp_gap_s:
        Longest run of bad samples [s] (n samples last n*dt) that is linearly
        interpolated in ``<channel>_clean``; longer runs are left NaN (``LONG_GAP``)
        and all-channel ones are reported in ``long_gaps``.
    outlier_window_s:
        Length [s] of each one-sided median window of the spike test (h samples, at
        least ``outlier_min_window``).  A genuine pulse must last longer than about
        half of it not to be taken for a burst of spikes.
    outlier_min_window:
        Minimum h [samples] at low sample rates.
    outlier_threshold_sigma:
        A spike must lie beyond both neighbourhoods by more than this many local
        noise standard deviations.
    noise_window_s:
        Window [s] of the rolling robust noise-scale estimate.
    min_noise_scale:
        ``(channel, floor)`` pairs: floor of the noise scale in the channel's unit.
        The floor is also at least the channel's quantisation step.
    frozen_min_run:
        A run of at least this many bit-identical consecutive samples [samples] is a
        stuck sensor (``FROZEN``; the first sample of the run is kept).
    frozen_channels:
        Channels checked for frozen values (default all; drop genuinely constant or
        coarsely quantised channels).
    sentinel_values:
        Values meaning "no data" (matched exactly or after a float32 round trip).
    max_time_gap_s:
        A time gap longer than this [s] is taken for a clock error (TelemetryError)
        rather than a dropout.
    rate_bounds_hz:
        Plausible grid rates [Hz]; an inferred or given rate outside raises
        TelemetryError (e.g. t in milliseconds).
    """

    nominal_rate_hz: float | None = None
    snap_tolerance: float = 0.25
    max_interp_gap_s: float = 0.5
    outlier_window_s: float = 0.05
    outlier_min_window: int = 5
    outlier_threshold_sigma: float = 3.3
    noise_window_s: float = 5.0
    min_noise_scale: tuple[tuple[str, float], ...] = DEFAULT_MIN_NOISE_SCALE
    frozen_min_run: int = 10
    frozen_channels: tuple[str, ...] = CHANNELS
    sentinel_values: tuple[float, ...] = DEFAULT_SENTINELS
    max_time_gap_s: float = 600.0
    rate_bounds_hz: tuple[float, float] = (1.0, 100_000.0)

    def __post_init__(self) -> None:
        def positive(name: str) -> None:
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"PreprocessParams.{name} must be a finite number > 0, got {v!r}")

        if self.nominal_rate_hz is not None:
            positive("nominal_rate_hz")
        for name in ("max_interp_gap_s", "outlier_window_s", "outlier_threshold_sigma", "noise_window_s",
                     "max_time_gap_s"):
            positive(name)
        if not (0 < self.snap_tolerance < 0.5):
            raise ValueError(f"PreprocessParams.snap_tolerance must be in (0, 0.5) grid steps, "
                             f"got {self.snap_tolerance!r}")
        if int(self.outlier_min_window) < 1 or int(self.frozen_min_run) < 2:
            raise ValueError("PreprocessParams.outlier_min_window must be >= 1 and frozen_min_run >= 2")
        known = (*CHANNELS, *AIR_DATA_CHANNELS)
        unknown = [c for c in self.frozen_channels if c not in known]
        unknown += [c for c, _ in self.min_noise_scale if c not in known]
        if unknown:
            raise ValueError(f"PreprocessParams: unknown channel(s) {unknown}; channels are {list(known)}")
        lo, hi = self.rate_bounds_hz
        if not (0 < lo < hi):
            raise ValueError(f"PreprocessParams.rate_bounds_hz must be 0 < low < high, got {self.rate_bounds_hz}")

    def min_noise_scale_of(self, channel: str) -> float:
        return float(dict(self.min_noise_scale).get(channel, 0.0))

    def to_dict(self) -> dict:
        """JSON-friendly dict of the parameters."""
        d = dataclasses.asdict(self)
        d["min_noise_scale"] = dict(self.min_noise_scale)
        d["frozen_channels"] = list(self.frozen_channels)
        d["sentinel_values"] = list(self.sentinel_values)
        d["rate_bounds_hz"] = list(self.rate_bounds_hz)
        return d


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
        Grid rows where every channel is usable (flags == 0).
    n_usable_by_channel:
        Channel -> number of usable samples.
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
        }

    def summary(self) -> str:
        """Human-readable per-flight summary."""
        lines = [
            f"preprocess {self.source}: {self.n_raw_rows} raw rows -> {self.n_grid_rows} grid rows "
            f"({self.n_inserted_rows} inserted) at {self.nominal_rate_hz:.6g} Hz "
            f"({'inferred' if self.rate_inferred else 'given'})",
            f"  usable rows (all channels): {self.n_usable_rows} "
            f"({100.0 * self.n_usable_rows / max(self.n_grid_rows, 1):.2f} %)",
            "  rows with flag: " + (", ".join(f"{k}={v}" for k, v in self.flag_counts.items() if v) or "none"),
            f"  longest all-channel gap: {self.longest_gap_s:.3f} s; "
            f"long gaps (> {self.params.max_interp_gap_s:g} s): {len(self.long_gaps)}"
            + "".join(f"\n    {a:.3f} .. {b:.3f} s" for a, b in self.long_gaps),
        ]
        for c in self.flag_counts_by_channel:
            counts = {k: v for k, v in self.flag_counts_by_channel[c].items() if v}
            if counts:
                lines.append(f"  {c}: usable {self.n_usable_by_channel[c]}, "
                             f"longest bad run {self.longest_gap_s_by_channel[c]:.3f} s, "
                             + ", ".join(f"{k}={v}" for k, v in counts.items()))
        if self.ignored_columns:
            lines.append(f"  ignored columns: {list(self.ignored_columns)}")
        return "\n".join(lines)


# ---------------------------------------------------------------------------
# Steps
# ---------------------------------------------------------------------------

def _check_structure(raw: pd.DataFrame, source: str) -> None:
    if not isinstance(raw, pd.DataFrame):
        raise TelemetryError(f"expected a pandas DataFrame, got {type(raw).__name__}", file=source)
    missing = [c for c in RAW_COLUMNS if c not in raw.columns]
    if missing:
        raise TelemetryError(f"missing column(s) {missing}; the raw contract is {list(RAW_COLUMNS)}",
                             file=source, column=missing[0])
    if raw.columns.duplicated().any():
        dup = [str(c) for c in raw.columns[raw.columns.duplicated()]]
        raise TelemetryError(f"duplicated column name(s) {dup}", file=source, column=dup[0])
    for c in RAW_COLUMNS:
        if raw[c].dtype != np.float64:
            raise TelemetryError(f"dtype is {raw[c].dtype}, the raw contract requires float64", file=source,
                                 column=c)
    if len(raw) == 0:
        raise TelemetryError("no rows: nothing to preprocess", file=source)
    t = raw["t_s"].to_numpy()
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise TelemetryError("timestamp is NaN or infinite (a row without a time cannot be placed on the grid)",
                             file=source, column="t_s", rows=bad)
    d = np.diff(t)
    bad = np.flatnonzero(d <= 0)
    if bad.size:
        rows = sorted(set(bad.tolist()) | set((bad + 1).tolist()))
        kind = "duplicated" if np.any(d[bad] == 0) else "decreasing"
        raise TelemetryError(f"timestamps must be strictly increasing; {kind} time at {bad.size} place(s), "
                             f"first t_s={float(t[bad[0]])!r} then {float(t[bad[0] + 1])!r}", file=source, column="t_s",
                             rows=rows)


def _infer_rate(t: np.ndarray) -> float:
    """Sample rate [Hz] from the timestamps: a first step dt0 = median interval, the
    sample count between consecutive rows = round(interval / dt0) (>= 1), then the
    least-squares slope of t against the cumulative sample index (the median alone
    drifts by samples over a long jittered record)."""
    d = np.diff(t)
    dt0 = float(np.median(d))
    if not (dt0 > 0):
        return float("inf")
    for _ in range(2):
        steps = np.maximum(1, np.round(d / dt0))
        k = np.concatenate(([0.0], np.cumsum(steps)))
        kc = k - k.mean()
        denom = float(np.dot(kc, kc))
        if denom <= 0:
            break
        dt0 = float(np.dot(kc, t - t.mean()) / denom)
    return 1.0 / dt0


def _grid(t: np.ndarray, params: PreprocessParams, source: str):
    """Grid step, origin and the grid index of every raw row."""
    if params.nominal_rate_hz is not None:
        rate, inferred = float(params.nominal_rate_hz), False
    else:
        if t.size < 2:
            raise TelemetryError("a single row: the sample rate cannot be inferred; give "
                                 "PreprocessParams(nominal_rate_hz=...)", file=source, column="t_s", rows=[0])
        rate, inferred = _infer_rate(t), True
    lo, hi = params.rate_bounds_hz
    if not (lo <= rate <= hi):
        raise TelemetryError(f"{'inferred' if inferred else 'given'} sample rate {rate:.6g} Hz is outside "
                             f"{params.rate_bounds_hz} Hz (is t_s in seconds?)", file=source, column="t_s")
    dt = 1.0 / rate
    big = np.flatnonzero(np.diff(t) > params.max_time_gap_s)
    if big.size:
        raise TelemetryError(f"time jumps by {t[big[0] + 1] - t[big[0]]:.6g} s > max_time_gap_s="
                             f"{params.max_time_gap_s:g} s (clock error?)", file=source, column="t_s",
                             rows=[int(big[0]), int(big[0]) + 1])
    if (t[-1] - t[0]) / dt + 1 > MAX_GRID_ROWS:
        raise TelemetryError(f"span {t[-1] - t[0]:.6g} s at {rate:.6g} Hz needs more than {MAX_GRID_ROWS} grid "
                             "rows", file=source, column="t_s")
    u = (t - t[0]) / dt
    frac = u - np.round(u)
    phase = math.atan2(float(np.mean(np.sin(2 * np.pi * frac))), float(np.mean(np.cos(2 * np.pi * frac))))
    phase /= 2 * np.pi  # in (-0.5, 0.5]
    pos = u - phase
    k = np.round(pos).astype(np.int64)
    k -= k[0]
    resid = pos - np.round(pos)
    t0 = t[0] - resid[0] * dt  # the grid point of the first row
    coll = np.flatnonzero(np.diff(k) == 0)
    if coll.size:
        rows = sorted(set(coll.tolist()) | set((coll + 1).tolist()))
        raise TelemetryError(f"{coll.size} pair(s) of rows fall on the same grid point at {rate:.6g} Hz "
                             f"(first t_s={float(t[coll[0]])!r} and {float(t[coll[0] + 1])!r}); "
                             "is the nominal rate right?",
                             file=source, column="t_s", rows=rows)
    return rate, dt, inferred, t0, k, resid


def _run_bits(bad: np.ndarray, max_interp: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Classify runs of bad samples: interpolate / long / edge masks, and run lengths."""
    n = bad.size
    starts, ends = detect.runs(bad)
    lengths = ends - starts
    edge = (starts == 0) | (ends == n)
    long_ = lengths > max_interp
    interp = ~edge & ~long_
    return (detect.mark_runs(n, starts[interp], ends[interp]),
            detect.mark_runs(n, starts[long_], ends[long_]),
            detect.mark_runs(n, starts[edge], ends[edge]),
            lengths)


def _channel(x: np.ndarray, present: np.ndarray, jitter: np.ndarray, channel: str, params: PreprocessParams,
             rate: float, max_interp: int):
    """Flags (uint16), clean values and noise sigma of one channel on the grid."""
    n = x.size
    f = np.zeros(n, dtype=np.int64)
    f[~present] |= QualityFlag.MISSING_ROW
    finite = np.isfinite(x)
    f[present & ~finite] |= QualityFlag.NAN
    sent = sentinel_mask(x, params.sentinel_values)
    f[sent] |= QualityFlag.SENTINEL
    lo, hi = PHYSICAL_BOUNDS[channel]
    oor = finite & ~sent & ((x < lo) | (x > hi))
    f[oor] |= QualityFlag.OUT_OF_RANGE
    f[jitter] |= QualityFlag.TIME_JITTER
    cand = np.where(f == 0, x, np.nan)
    if channel in params.frozen_channels:
        f[detect.frozen_mask(cand, int(params.frozen_min_run))] |= QualityFlag.FROZEN
        cand = np.where(f == 0, x, np.nan)
    floor = max(params.min_noise_scale_of(channel), detect.quantum(cand))
    sigma, sigma_global = detect.noise_scale(cand, int(round(params.noise_window_s * rate)), floor)
    h = max(int(params.outlier_min_window), int(round(params.outlier_window_s * rate)))
    f[detect.spike_mask(cand, h, sigma, params.outlier_threshold_sigma)] |= QualityFlag.OUTLIER

    bad = (f & int(DETECTION)) != 0
    interp, long_, edge, lengths = _run_bits(bad, max_interp)
    f[interp] |= QualityFlag.INTERPOLATED
    f[long_] |= QualityFlag.LONG_GAP
    f[edge] |= QualityFlag.EDGE_GAP
    clean = np.where(bad, np.nan, x)
    if interp.any():
        good = np.flatnonzero(~bad)
        idx = np.flatnonzero(interp)
        clean[idx] = np.interp(idx, good, x[good])
    longest = int(lengths.max()) if lengths.size else 0
    return f.astype(FLAGS_DTYPE), clean, sigma_global, longest


def preprocess(raw: pd.DataFrame, params: PreprocessParams = PreprocessParams(),
               source: str = "<memory>") -> PreprocessResult:
    """Put raw telemetry on a uniform time grid with per-sample quality flags.

    ``raw``: a frame following ``schemas.telemetry.RawTelemetry`` (SI units, radians,
    ``t_s`` in seconds).  ``source``: the file it came from, used in error messages
    and metadata.  Pure: ``raw`` is not modified.

    Returns a :class:`PreprocessResult`.  Raises :class:`TelemetryError` for input
    that cannot be placed on a grid (missing or non-float64 columns, no rows, NaN or
    non-increasing time, an implausible rate, grid collisions, a clock jump) or that
    fails the raw schema.  A record with no usable sample at all is not an error: it
    comes back fully flagged (clean values NaN).
    """
    _check_structure(raw, source)
    validate(raw, RawTelemetry, source)
    t = raw["t_s"].to_numpy()
    rate, dt, inferred, t0, k, resid = _grid(t, params, source)
    n = int(k[-1]) + 1
    t_grid = t0 + np.arange(n, dtype=np.float64) * dt
    present = np.zeros(n, dtype=bool)
    present[k] = True
    jitter = np.zeros(n, dtype=bool)
    jitter[k[np.abs(resid) > params.snap_tolerance]] = True
    max_interp = int(math.floor(params.max_interp_gap_s * rate + 1e-9))

    t_raw = np.full(n, np.nan)
    t_raw[k] = t
    cols: dict[str, np.ndarray] = {"t_s": t_grid}
    clean_cols, flag_cols = {}, {}
    sigmas, longest_by = {}, {}
    all_bad = np.ones(n, dtype=bool)
    air = tuple(c for c in AIR_DATA_CHANNELS if c in raw.columns)
    for c in air:
        if raw[c].dtype != np.float64:
            raise TelemetryError(f"dtype is {raw[c].dtype}, air-data channels must be float64", file=source,
                                 column=c)
    for c in (*CHANNELS, *air):
        x = np.full(n, np.nan)
        x[k] = raw[c].to_numpy()  # plain assignment: bit patterns are kept
        cols[c] = x
        f, clean, sig, longest = _channel(x, present, jitter, c, params, rate, max_interp)
        clean_cols[f"{c}_clean"] = clean
        flag_cols[f"flags_{c}"] = f
        sigmas[c] = sig
        longest_by[c] = longest * dt
        if c in CHANNELS:
            all_bad &= (f & np.uint16(int(DETECTION))) != 0
    flags_all = np.zeros(n, dtype=FLAGS_DTYPE)
    for c in CHANNELS:
        flags_all |= flag_cols[f"flags_{c}"]
    frame = pd.DataFrame({"t_s": t_grid, "t_raw_s": t_raw, **{c: cols[c] for c in (*CHANNELS, *air)}, **clean_cols,
                          **flag_cols, "flags": flags_all})

    starts, ends = detect.runs(all_bad)
    lengths = ends - starts
    long_sel = lengths > max_interp
    long_gaps = tuple((float(t_grid[s]), float(t_grid[e - 1])) for s, e in zip(starts[long_sel], ends[long_sel]))

    names = [fl.name for fl in QualityFlag]
    flag_counts = {nm: int(((flags_all & np.uint16(int(QualityFlag[nm]))) != 0).sum()) for nm in names}
    by_channel = {c: {nm: int(((flag_cols[f"flags_{c}"] & np.uint16(int(QualityFlag[nm]))) != 0).sum())
                      for nm in names} for c in (*CHANNELS, *air)}
    unusable = np.uint16(int(UNUSABLE))
    usable_by = {c: int(((flag_cols[f"flags_{c}"] & unusable) == 0).sum()) for c in (*CHANNELS, *air)}
    result = PreprocessResult(
        frame=frame,
        params=params,
        source=str(source),
        nominal_rate_hz=rate,
        dt_s=dt,
        rate_inferred=inferred,
        n_raw_rows=int(len(raw)),
        n_grid_rows=n,
        n_inserted_rows=int(n - present.sum()),
        flag_counts=flag_counts,
        flag_counts_by_channel=by_channel,
        n_usable_rows=int(((flags_all & unusable) == 0).sum()),
        n_usable_by_channel=usable_by,
        longest_gap_s=float(lengths.max() * dt) if lengths.size else 0.0,
        longest_gap_s_by_channel=longest_by,
        long_gaps=long_gaps,
        noise_sigma=sigmas,
        ignored_columns=tuple(str(c) for c in raw.columns if c not in RAW_COLUMNS and c not in air),
    )
    validate(frame, PreprocessedTelemetry, source)
    return result
