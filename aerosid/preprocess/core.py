"""preprocess(): raw telemetry -> uniform grid, raw kept, per-sample quality flags.

Pipeline (method.md §1), all vectorised:

1. **Structure.**  The 13 contract columns must be present and float64, ``t_s``
   finite and strictly increasing (otherwise ``TelemetryError`` naming file, column
   and rows); then the ``RawTelemetry`` schema is enforced.  Extra columns are not
   carried over; their names are recorded (``ignored_columns``).
2. **Grid.**  dt = 1 / ``nominal_rate_hz``, or the median interval when that is
   ``None``.  The grid origin is the circular mean phase of the timestamps, so
   jitter does not shift it.  A run of rows that left the grid together at a dropout
   (the sample phase moved: ``_phase_runs``) is re-timed onto it and reported
   (``PreprocessResult.retimed``, a ``phase_shift`` finding).  Each raw row goes to its
   nearest grid point; rows further than ``snap_tolerance`` steps away are flagged
   ``TIME_JITTER``; two rows on one grid point raise ``TelemetryError``.  A record stamped
   in absolute times (Unix time) is processed in seconds since its first whole second
   (``time_origin_s``; ``t_s`` and ``t_raw_s`` count from it).  Grid points without a raw row are
   inserted (``MISSING_ROW``; raw columns and ``t_raw_s`` NaN).
3. **Per channel detection** on the grid: ``NAN``, ``SENTINEL``, ``OUT_OF_RANGE``;
   then the sensor's profile (``sensors.profile``: resolution, update interval,
   whether it rests at its resolution), ``FROZEN`` (stuck runs, counted in updates),
   ``HELD`` (the repeats of a sample-and-hold channel between its updates), then
   ``OUTLIER`` (two-sided spike test on the update instants, threshold from the
   record length and ``false_alarm``; see ``detect.spike_mask``).
4. **Gap policy** per channel: each maximal run of samples with a detection bit is
   ``INTERPOLATED`` linearly between its good neighbours when it holds no fault
   (held samples between two updates) or is no longer than ``max_interp_gap_s``
   (for a held channel: two update intervals at least), and has good samples on
   both sides; otherwise it is left NaN in ``<channel>_clean`` (``LONG_GAP`` and/or
   ``EDGE_GAP``).
5. **Row-level gaps**: runs of grid rows where *every* channel has a fault bit.
   Those longer than ``max_interp_gap_s`` are ``long_gaps`` (the pipeline splits
   segments there; the sync gap is one); the longest is ``longest_gap_s``.
6. The output is enforced against ``PreprocessedTelemetry``.

Durations: a run of n grid samples lasts n * dt (the time not covered by data).
The result (frame, report, metadata) is :class:`~aerosid.preprocess.result.PreprocessResult`.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from schemas.telemetry import (
    AIR_DATA_CHANNELS,
    CHANNELS,
    PHYSICAL_BOUNDS,
    RAW_COLUMNS,
    PreprocessedTelemetry,
    RawTelemetry,
    sentinel_mask,
    validate,
)

from . import detect, sensors
from .errors import TelemetryError
from .flags import DETECTION, FAULT, FLAGS_DTYPE, UNUSABLE, QualityFlag
from .params import DEFAULT_MIN_NOISE_SCALE, PreprocessParams  # noqa: F401  (re-exported)
from .result import PreprocessResult

#: Hard cap on the grid size (a clock jump would otherwise allocate without bound).
MAX_GRID_ROWS = 50_000_000
#: A record is jittery when more than JITTERY_SHARE of its intervals lie more than JITTERY_STEP
#: [steps] off a whole number of steps; its rate is then the timestamps' coherent one (_coherent_rate).
JITTERY_STEP = 0.1
JITTERY_SHARE = 0.05
#: The coherent rate's first search: the first COHERENCE_SPAN_S seconds, f0 +- COHERENCE_BAND.
COHERENCE_SPAN_S = 20.0
COHERENCE_BAND = 0.05
#: A record whose first timestamp is at least this large [s] in magnitude (Unix time, 1.7e9 s) is
#: processed in seconds since time_origin_s(t0): at 1.7e9 s a float64 timestamp resolves only
#: 2.4e-7 s, so a 100 Hz grid's steps scatter by 2e-5 of a step and no stage downstream could
#: tell it from a broken clock (the smoother refused it); GPS time of week (< 6.1e5 s) stays as it is.
TIME_ORIGIN_ABOVE_S = 1e6
#: Rows a run must have to be re-timed as a phase shift (_phase_runs); shorter runs off the grid are jitter.
PHASE_RUN_MIN_ROWS = 10
#: A dropout interval further than this [steps] from a whole number moved the sample phase (_infer_rate).
PHASE_STEP_RESOLUTION = 1e-3


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


def time_origin_s(t0_s: float) -> float:
    """The origin [s] the pipeline's times count from for a record starting at t0_s: 0, or for a
    record stamped in large absolute times (|t0_s| >= TIME_ORIGIN_ABOVE_S) its first timestamp's
    whole second (so t - origin is exact in float64 and starts within a second of zero)."""
    return float(math.floor(t0_s)) if math.isfinite(t0_s) and abs(t0_s) >= TIME_ORIGIN_ABOVE_S else 0.0


def _infer_rate(t: np.ndarray) -> float:
    """Sample rate [Hz] from the timestamps: a first step dt0 = median interval, the
    sample count between consecutive rows = round(interval / dt0) (>= 1), then the
    least-squares slope of t against the cumulative sample index (the median alone
    drifts by samples over a long jittered record).  An interval across which the sample
    phase moved (_phase_moves) starts a new run with its own intercept, and the slope is the
    one within runs: counted as whole steps, each such jump would tilt it (0.13 % on 20 s of
    50 Hz with two half-step jumps; a 100 Hz record with dropouts thinned to 10 Hz has jumps
    of 1.2 and 1.5 steps, read as 9.965 Hz and refused by the schema)."""
    d = np.diff(t)
    dt0 = float(np.median(d))
    if not (dt0 > 0):
        return float("inf")
    for _ in range(2):
        x = d / dt0
        moved = _phase_moves(x)
        k = np.concatenate(([0.0], np.cumsum(np.maximum(1, np.round(x)))))
        if moved.any():
            run = np.concatenate(([0], np.cumsum(moved)))
            count = np.bincount(run)
            kc = k - (np.bincount(run, k) / count)[run]
            tc = t - (np.bincount(run, t) / count)[run]  # t counts from time_origin_s: group sums exact
        else:
            kc, tc = k - k.mean(), t - t.mean()
        denom = float(np.dot(kc, kc))
        if denom <= 0:
            break
        dt0 = float(np.dot(kc, tc) / denom)
    x = d * (1.0 / dt0)
    if np.mean(np.abs(x - np.round(x)) > JITTERY_STEP) > JITTERY_SHARE:
        return _coherent_rate(t, 1.0 / float(np.median(d)))
    return 1.0 / dt0


def _phase_moves(x: np.ndarray) -> np.ndarray:
    """Intervals x [steps] across which the sample phase moved: off a whole number of steps by
    more than the clock's own scatter (5 x the median offset, within PHASE_STEP_RESOLUTION ..
    JITTERY_STEP), or by more than PHASE_STEP_RESOLUTION in a dropout (>= 1.5 steps)."""
    off = np.abs(x - np.round(x))
    tol = min(JITTERY_STEP, max(PHASE_STEP_RESOLUTION, 5.0 * float(np.median(off)))) if off.size else 0.0
    return ((x >= 1.5) & (off > PHASE_STEP_RESOLUTION)) | (off > tol)


def _coherent_rate(t: np.ndarray, f0: float) -> float:
    """The rate [Hz] near f0 at which the timestamps are most coherent, |mean exp(2 pi i f t)|
    largest: a jittered clock's rows scatter about their grid points and dropouts leave none, so
    neither moves the peak, where counting whole steps between rows does (an interval that
    jitter stretches past 1.5 steps counts as a dropout: 0.2 step rms of jitter at 100 Hz gave
    103.2 Hz, and the grid then put 446 pairs of rows on one point).  The peak's width is 1 / span,
    so the search starts on the first COHERENCE_SPAN_S seconds over f0 +- COHERENCE_BAND and
    doubles the span, narrowing the band around the peak, until it holds the whole record."""
    t = t - t[0]
    T = float(t[-1])
    span = min(T, COHERENCE_SPAN_S)
    lo, hi = f0 * (1.0 - COHERENCE_BAND), f0 * (1.0 + COHERENCE_BAND)
    while True:
        tt = t[t <= span]
        f = np.linspace(lo, hi, max(16, int(math.ceil((hi - lo) * span * 4.0)) + 1))
        # |mean exp(2 pi i f t)| in blocks of frequencies (memory: len(tt) x block)
        power = np.concatenate([np.abs(np.exp(2j * np.pi * np.outer(tt, fb)).mean(axis=0))
                                for fb in np.array_split(f, max(1, f.size * tt.size // 2_000_000))])
        best = float(f[int(np.argmax(power))])
        if span >= T:
            return best
        step = (hi - lo) / (f.size - 1)
        span = min(T, 2.0 * span)
        lo, hi = best - 2.0 * step, best + 2.0 * step


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
        raise TelemetryError(f"time jumps by {t[big[0] + 1] - t[big[0]]:.6g} s, more than the longest gap taken "
                             f"for a dropout, max_time_gap_s = {params.max_time_gap_s:g} s (clock error?); if the "
                             "recording really paused, raise it: aerosid run --preprocess max_time_gap_s=SECONDS "
                             "or max_time_gap_s in the vehicle file's [preprocess] table", file=source,
                             column="t_s", rows=[int(big[0]), int(big[0]) + 1])
    if (t[-1] - t[0]) / dt + 1 > MAX_GRID_ROWS:
        raise TelemetryError(f"span {t[-1] - t[0]:.6g} s at {rate:.6g} Hz needs more than {MAX_GRID_ROWS} grid "
                             "rows", file=source, column="t_s")
    u = (t - t[0]) / dt
    pos = u - _circular_phase(u)
    k_global = np.round(pos)
    t0 = t[0] - (pos[0] - k_global[0]) * dt  # the global grid point of the first row
    retimed = _phase_runs(pos, params.snap_tolerance)
    for a, b, phi in retimed:
        pos[a:b] -= phi
    k = _resolve_collisions(pos, np.round(pos).astype(np.int64))
    resid = pos - k
    t0 += (k[0] - k_global[0]) * dt  # a re-timed first run may start one grid step off
    k -= k[0]
    coll = np.flatnonzero(np.diff(k) == 0)
    if coll.size:
        rows = sorted(set(coll.tolist()) | set((coll + 1).tolist()))
        raise TelemetryError(f"{coll.size} pair(s) of rows fall on the same grid point at {rate:.6g} Hz "
                             f"(first t_s={float(t[coll[0]])!r} and {float(t[coll[0] + 1])!r}); "
                             "is the nominal rate right?",
                             file=source, column="t_s", rows=rows)
    return rate, dt, inferred, t0, k, resid, tuple((a, b, -phi * dt) for a, b, phi in retimed)


def _resolve_collisions(pos: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Grid points k (int, non-decreasing) of rows at positions pos [steps] with two rows on one
    point resolved where the neighbouring point on the side of the row further from it is free:
    that row moves there.  It is then more than half a step off its point, so TIME_JITTER and
    treated as missing: no value is used at a time it was not taken.  A jittered clock (0.2 step
    rms) puts two rows within a quarter step of each other now and then (c182: 2.4 ms apart at
    100 Hz); where every neighbour is taken (a wrong nominal rate) the collision stays."""
    coll = np.flatnonzero(np.diff(k) == 0)
    if not coll.size:
        return k
    k = k.copy()
    n = k.size
    for j in coll:
        if k[j] != k[j + 1]:
            continue  # resolved by an earlier move
        far = j if abs(pos[j] - k[j]) >= abs(pos[j + 1] - k[j + 1]) else j + 1
        if far == j and (j == 0 or k[j - 1] < k[j] - 1) and pos[j] < k[j]:
            k[j] -= 1
        elif far == j + 1 and (j + 2 >= n or k[j + 2] > k[j + 1] + 1) and pos[j + 1] > k[j + 1]:
            k[j + 1] += 1
    return k


def _circular_phase(u: np.ndarray) -> float:
    """The circular mean of the fractional parts of u [steps], in (-0.5, 0.5]: the grid's phase,
    which symmetric jitter does not shift."""
    frac = u - np.round(u)
    phase = math.atan2(float(np.mean(np.sin(2 * np.pi * frac))), float(np.mean(np.cos(2 * np.pi * frac))))
    return phase / (2 * np.pi)


def _phase_runs(pos: np.ndarray, tol: float) -> list[tuple[int, int, float]]:
    """Runs of rows that lie off the grid together because the record's sample phase moved at a
    dropout (a recorder that resumes on another phase; telemetry thinned after dropouts): (first
    row, end row, the run's phase [steps]) for every run of at least PHASE_RUN_MIN_ROWS rows,
    delimited by intervals across which the phase moved (_phase_moves: a phase can move at a
    dropout by any amount, and fractions add up), whose own phase is more than tol off the grid,
    with rows lost at one end at least (an interval longer than a step by more than the clock's
    scatter) and at neither end rows closer than a step.
    Such a run is re-timed onto the grid by its phase (at most half a step; the rows keep their
    spacing, every channel moves alike) instead of being lost as jitter.  A run that sits off the
    grid between unbroken intervals, or comes back early (a late clock: intervals of 1.4 and then
    0.6 steps), is a clock glitch and stays jitter."""
    if pos.size < PHASE_RUN_MIN_ROWS:
        return []
    d = np.diff(pos)
    moved = _phase_moves(d)
    edges = np.concatenate(([0], np.flatnonzero(moved) + 1, [pos.size]))
    lost = moved & (d > 1.0)  # time passed without rows
    early = moved & (d < 1.0)  # rows closer than a step
    out = []
    for a, b in zip(edges[:-1], edges[1:]):
        if b - a < PHASE_RUN_MIN_ROWS:
            continue
        ends = [j for j in (a - 1, b - 1) if 0 <= j < d.size]
        if not any(lost[j] for j in ends) or any(early[j] for j in ends):
            continue  # no rows lost at either end, or a clock that came back early: a glitch
        phi = _circular_phase(pos[a:b])
        if abs(phi) > tol:
            out.append((int(a), int(b), phi))
    return out


def _run_bits(bad: np.ndarray, fault: np.ndarray, limit: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Classify runs of bad samples: interpolate / long / edge masks.  A run is long when
    it holds a fault and lasts more than ``limit`` samples (a run of held samples
    alone is the hold between two updates, always bridged)."""
    n = bad.size
    starts, ends = detect.runs(bad)
    lengths = ends - starts
    csum = np.concatenate(([0], np.cumsum(fault)))
    has_fault = (csum[ends] - csum[starts]) > 0
    edge = (starts == 0) | (ends == n)
    long_ = has_fault & (lengths > limit)
    interp = ~edge & ~long_
    return (detect.mark_runs(n, starts[interp], ends[interp]),
            detect.mark_runs(n, starts[long_], ends[long_]),
            detect.mark_runs(n, starts[edge], ends[edge]))


def _update_series(anchor: np.ndarray, u: float) -> tuple[np.ndarray, np.ndarray]:
    """Grid indices of the update instants and their positions on an update grid
    (a step of ``u`` samples; a gap of several updates keeps its length)."""
    idx = np.flatnonzero(anchor)
    if idx.size == 0:
        return idx, idx
    steps = np.maximum(1, np.round(np.diff(idx) / u)).astype(np.int64)
    return idx, np.concatenate(([0], np.cumsum(steps)))


def _outliers(cand: np.ndarray, anchor: np.ndarray, held: np.ndarray, prof: sensors.SensorProfile, channel: str,
              params: PreprocessParams, rate: float) -> tuple[np.ndarray, float, float]:
    """Outlier mask on the grid (an outlying update and the samples holding it), the
    whole-record noise sigma, and the threshold used [standard deviations]."""
    n = cand.size
    u = prof.update_interval
    idx, pos = _update_series(anchor, u)
    y = np.full(int(pos[-1]) + 1 if pos.size else 0, np.nan)
    y[pos] = cand[idx]
    floor = max(params.min_noise_scale_of(channel), prof.resolution if prof.resolution > 0 else detect.quantum(y))
    window = max(3, int(round(params.noise_window_s * rate / u)))
    sigma, sigma_global = detect.noise_scale(y, window, floor)
    fixed = params.sensor(channel, "outlier_threshold_sigma")
    threshold = float(fixed) if fixed is not None else detect.gaussian_threshold(
        idx.size, float(params.sensor(channel, "false_alarm")))
    out = np.zeros(n, dtype=bool)
    if params.sensor(channel, "detect_outliers", True) and y.size:
        h = max(int(params.outlier_min_window), int(round(params.outlier_window_s * rate / u)))
        bad = idx[detect.spike_mask(y, h, sigma, threshold, window)[pos]]
        out[bad] = True
        if prof.held and bad.size:  # the samples holding an outlying update hold its bad value too
            nxt = np.append(idx, n)[np.searchsorted(idx, bad, side="right")]
            out |= detect.mark_runs(n, bad, nxt) & held
    return out, sigma_global, threshold


def _channel(x: np.ndarray, present: np.ndarray, jitter: np.ndarray, channel: str, params: PreprocessParams,
             rate: float, max_interp: int):
    """Flags (uint16), clean values, noise sigma, longest fault run and the sensor's
    profile (a dict) of one channel on the grid."""
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
    prof = sensors.profile(
        cand, channel, rate_hz=rate, noise_window=int(round(params.noise_window_s * rate)),
        min_run=int(params.sensor(channel, "frozen_min_run")), still_share=params.still_share,
        false_alarm=float(params.sensor(channel, "false_alarm")),
        check_frozen=bool(params.sensor(channel, "detect_frozen")),
        given_resolution=params.sensor(channel, "resolution"),
        given_update_s=params.sensor(channel, "update_interval_s"),
        max_still_s=params.sensor(channel, "frozen_max_still_s"))
    frozen, held, anchor = sensors.frozen_and_held(cand, prof, 1.0 / rate)
    f[frozen] |= QualityFlag.FROZEN
    out, sigma_global, threshold = _outliers(cand, anchor, held, prof, channel, params, rate)
    f[out] |= QualityFlag.OUTLIER
    f[held & ~out] |= QualityFlag.HELD

    bad = (f & int(DETECTION)) != 0
    fault = (f & int(FAULT)) != 0
    limit = max(max_interp, int(math.ceil(2 * prof.update_interval)) - 1) if prof.held else max_interp
    interp, long_, edge = _run_bits(bad, fault, limit)
    f[interp] |= QualityFlag.INTERPOLATED
    f[long_] |= QualityFlag.LONG_GAP
    f[edge] |= QualityFlag.EDGE_GAP
    clean = np.where(bad, np.nan, x)
    if interp.any():
        good = np.flatnonzero(~bad)
        idx = np.flatnonzero(interp)
        clean[idx] = np.interp(idx, good, x[good])
    starts, ends = detect.runs(fault)
    longest = int((ends - starts).max()) if starts.size else 0
    info = {**prof.to_dict(), "threshold_sigma": threshold}
    return f.astype(FLAGS_DTYPE), clean, sigma_global, longest, info


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
    origin = time_origin_s(float(raw["t_s"].iloc[0]))
    t = raw["t_s"].to_numpy() - origin  # exact (Sterbenz) for an origin within a factor 2 of t
    rate, dt, inferred, t0, k, resid, retimed = _grid(t, params, source)
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
    sigmas, longest_by, profiles = {}, {}, {}
    all_bad = np.ones(n, dtype=bool)
    all_used = present.copy()
    air = tuple(c for c in AIR_DATA_CHANNELS if c in raw.columns)
    for c in air:
        if raw[c].dtype != np.float64:
            raise TelemetryError(f"dtype is {raw[c].dtype}, air-data channels must be float64", file=source,
                                 column=c)
    for c in (*CHANNELS, *air):
        x = np.full(n, np.nan)
        x[k] = raw[c].to_numpy()  # plain assignment: bit patterns are kept
        cols[c] = x
        f, clean, sig, longest, profiles[c] = _channel(x, present, jitter, c, params, rate, max_interp)
        clean_cols[f"{c}_clean"] = clean
        flag_cols[f"flags_{c}"] = f
        sigmas[c] = sig
        longest_by[c] = longest * dt
        if c in CHANNELS:
            all_bad &= (f & np.uint16(int(FAULT))) != 0
            all_used &= (f & np.uint16(int(FAULT))) == 0
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
    fault = np.uint16(int(FAULT))
    used_by = {c: int((present & ((flag_cols[f"flags_{c}"] & fault) == 0)).sum()) for c in (*CHANNELS, *air)}
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
        n_used_rows=int(all_used.sum()),
        n_used_by_channel=used_by,
        sensors=profiles,
        retimed=tuple((float(t_grid[k[a]]), float(t_grid[k[b - 1]]), int(b - a), float(shift))
                      for a, b, shift in retimed),
        time_origin_s=origin,
    )
    validate(frame, PreprocessedTelemetry, source)
    return result
