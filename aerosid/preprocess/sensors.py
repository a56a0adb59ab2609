"""What a real sensor channel looks like: its resolution, its update interval, and
whether it rests at its resolution (pure numpy on one channel's values on the grid).

Real telemetry repeats values for two ordinary reasons, neither of them a fault:

* **Resolution** (quantisation).  A channel recorded in steps of ``Δ`` (0.01 deg for
  a surface, 0.17 ft/s for an airspeed) shows the same value for as long as the
  signal stays within one step: a surface that holds still repeats its value for
  seconds.  :func:`resolution` finds ``Δ`` as the step of the lattice the sample
  differences lie on (0 for continuous values).
* **Update interval** (sample-and-hold).  A channel updated at a lower rate than the
  telemetry's is held between its updates: runs of identical values whose lengths
  are multiples of the update interval ``u`` samples (4 or 5 for a 12 Hz sensor in a
  50 Hz record).  :func:`update_interval` finds ``u`` (1 when every sample is an
  update).

A **stuck** sensor repeats its value far longer than either explains.  For a
channel whose updates change by more than its resolution (noise-dominated, the
usual IMU and simulated channels) a run of identical *updates* is improbable and
``frozen_min_run`` updates of it are a stuck sensor; with a repeat probability
``p`` per update the run length is also raised to the one whose chance
``p**(U-1)`` over the record's updates is below the false-alarm probability.  A
channel whose updates repeat the previous value more often than ``still_share``
(median over noise windows) *rests at its resolution*: its still runs are how it
looks when nothing moves, so the frozen test is off for it unless a longest still
time ``frozen_max_still_s`` is given for that sensor.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from . import detect

#: Share of the sample differences that must lie on the lattice of a resolution.
LATTICE_SHARE = 0.9
#: A difference lies on the lattice when it is within this fraction of a step of a multiple.
LATTICE_TOLERANCE = 0.02
#: Largest median difference in steps for a lattice (beyond it the values are continuous).
LATTICE_MAX_STEPS = 10_000
#: Fewest interior runs (and differences) needed to infer an update interval (a resolution).
MIN_RUNS = 20
#: Share of the interior runs whose length must be a multiple of the update interval.
HOLD_SHARE = 0.9
#: The repeat share is a median over at least this many windows of at least MIN_BLOCK samples.
MIN_BLOCKS = 10
MIN_BLOCK = 50


@dataclass(frozen=True)
class SensorProfile:
    """What preprocessing found (or was told) about one channel.

    resolution:
        Quantisation step in the channel's unit (0: continuous values).
    update_interval:
        Samples between updates (1.0: every sample is an update; > 1: sample-and-hold).
    repeat_share:
        Share of updates that repeat the previous update's value exactly (median over
        noise windows).
    at_rest:
        The channel rests at its resolution (quantised, or one value throughout, and
        ``repeat_share > still_share``): still runs are not taken for a stuck sensor.
    constant:
        One value over the whole record.
    frozen_min_updates:
        Identical consecutive updates that make a frozen run (0: the test is off).
    frozen_max_still_s:
        For a channel at rest: a still run longer than this [s] is frozen (None: never).
    given:
        Names of the fields that came from the settings rather than from the data.
    """

    channel: str
    resolution: float
    update_interval: float
    repeat_share: float
    at_rest: bool
    constant: bool
    frozen_min_updates: int
    frozen_max_still_s: float | None = None
    given: tuple[str, ...] = ()

    @property
    def held(self) -> bool:
        return self.update_interval > 1.0

    def to_dict(self) -> dict:
        d = asdict(self)
        d["given"] = list(self.given)
        return d

    def describe(self, rate_hz: float, unit: str = "") -> str:
        """One line for summaries: only what differs from a plain noisy channel."""
        parts = []
        if self.constant:
            parts.append("one value throughout")
        elif self.resolution > 0:
            parts.append(f"resolution {self.resolution:.4g}{' ' + unit if unit else ''}")
        if self.held:
            parts.append(f"held: updated every {self.update_interval:.3g} samples "
                         f"({rate_hz / self.update_interval:.3g} Hz), interpolated between updates")
        if self.at_rest:
            still = (f"still runs > {self.frozen_max_still_s:g} s are frozen" if self.frozen_max_still_s
                     else "not tested for frozen runs (no frozen_max_still_s for it)")
            parts.append(f"rests at its resolution ({100 * self.repeat_share:.0f} % of updates repeat): {still}")
        elif self.frozen_min_updates == 0:
            parts.append("frozen test off")
        if self.given:
            parts.append(f"given: {', '.join(self.given)}")
        return "; ".join(parts)


def value_runs(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Maximal runs of bit-identical finite values: ``(starts, ends)``, ends exclusive.
    A NaN sample is in no run and breaks runs; a lone value is a run of one."""
    x = np.asarray(x, dtype=np.float64)
    n = x.size
    finite = np.isfinite(x)
    if n == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty
    new = np.ones(n, dtype=bool)  # new[k]: a run starts at k
    new[1:] = ~((x[1:] == x[:-1]) & finite[1:])
    starts = np.flatnonzero(new & finite)
    # a run ends at the next start or at the next non-finite sample
    nxt = np.flatnonzero(new | ~finite)
    idx = np.searchsorted(nxt, starts, side="right")
    ends = np.where(idx < nxt.size, nxt[np.minimum(idx, nxt.size - 1)], n)
    return starts, ends


def resolution(x: np.ndarray) -> float:
    """Quantisation step of the values, or 0 when they are continuous.

    The step is the smallest candidate ``q`` (the smallest non-zero difference between
    consecutive samples, or its 1st or 5th percentile, which skips float-rounding
    crumbs) such that at least ``LATTICE_SHARE`` of the non-zero differences are
    integer multiples of ``q`` (within ``LATTICE_TOLERANCE`` of a step; all of them
    when there are fewer than ``MIN_RUNS``, at least 3) and the median difference is
    at most ``LATTICE_MAX_STEPS`` steps.
    """
    d = np.abs(np.diff(np.asarray(x, dtype=np.float64)))
    d = d[np.isfinite(d) & (d > 0)]
    if d.size < 3:
        return 0.0
    # with few changes (a surface that moves a few times) every one must be on the lattice
    share = LATTICE_SHARE if d.size >= MIN_RUNS else 1.0
    for q in sorted({float(d.min()), float(np.percentile(d, 1)), float(np.percentile(d, 5))}):
        if q <= 0 or np.median(d) / q > LATTICE_MAX_STEPS:
            continue
        r = d / q
        if np.mean(np.abs(r - np.round(r)) <= LATTICE_TOLERANCE) >= share:
            return q
    return 0.0


def update_interval(x: np.ndarray) -> float:
    """Samples between a sample-and-hold channel's updates (1.0 when not held).

    Over the interior runs of identical values (runs touching a NaN or the record's
    edge may be cut, and are left out), with ``m`` the most common run length: when
    ``m >= 2``, ``u`` is the mean length of the runs within one sample of ``m`` (a
    fractional ``u`` when the update rate is not a divisor of the grid rate), and the
    channel is held when at least ``HOLD_SHARE`` of the runs last a whole number of
    updates (``|L - k u| < 1`` for ``k = round(L / u) >= 1``: an update that repeated
    the previous value makes a run of two updates) and fewer than 5 % last one sample.
    """
    x = np.asarray(x, dtype=np.float64)
    starts, ends = value_runs(x)
    if starts.size < MIN_RUNS + 2:
        return 1.0
    n = x.size
    finite = np.isfinite(x)
    prev_ok = np.concatenate(([False], finite))[starts]  # the sample before the run is finite
    next_ok = np.concatenate((finite, [False]))[ends]
    interior = (starts > 0) & (ends < n) & prev_ok & next_ok
    lengths = (ends - starts)[interior]
    if lengths.size < MIN_RUNS:
        return 1.0
    m = int(np.argmax(np.bincount(lengths)))
    if m < 2 or np.mean(lengths == 1) >= 0.05:
        return 1.0
    u = float(lengths[np.abs(lengths - m) <= 1].mean())
    k = np.maximum(1.0, np.round(lengths / u))
    if np.mean(np.abs(lengths - k * u) < 1.0) < HOLD_SHARE:
        return 1.0
    return u


def run_updates(lengths: np.ndarray, u: float) -> np.ndarray:
    """Number of updates a run of identical values spans (at least 1)."""
    return np.maximum(1, np.round(np.asarray(lengths, dtype=np.float64) / u)).astype(np.int64)


def repeat_share(x: np.ndarray, u: float, window: int) -> float:
    """Share of updates repeating the previous update's value, median over windows.

    Per window of ``window`` samples (shorter when the record holds fewer than
    ``MIN_BLOCKS`` windows, but at least ``MIN_BLOCK`` samples), ``s`` = share of consecutive finite pairs with
    identical values; a held channel repeats ``1 - 1/u`` of its samples by holding, so
    the update-level share is ``(s - (1 - 1/u)) u`` (clipped to [0, 1]).  The median
    over the windows (with at least half a window of pairs) is robust to a stuck
    sensor covering less than half of the windows."""
    x = np.asarray(x, dtype=np.float64)
    if x.size < 2:
        return 0.0
    pair = np.isfinite(x[1:]) & np.isfinite(x[:-1])
    same = (x[1:] == x[:-1]) & pair
    # blocks of the noise window, but at least MIN_BLOCKS of them (of >= MIN_BLOCK samples)
    block = max(MIN_BLOCK, min(int(window), pair.size // MIN_BLOCKS))
    nb = max(1, pair.size // block)
    shares = []
    for sl in np.array_split(np.arange(pair.size), nb):
        npair = int(pair[sl].sum())
        if npair >= max(2, len(sl) // 2):
            s = same[sl].sum() / npair
            shares.append(min(1.0, max(0.0, (s - (1.0 - 1.0 / u)) * u)))
    return float(np.median(shares)) if shares else 0.0


def frozen_run_length(min_run: int, p_repeat: float, n_updates: int, false_alarm: float) -> int:
    """Identical updates that make a frozen run: ``min_run``, raised to the length ``U``
    with ``n_updates * p_repeat**(U - 1) <= false_alarm`` when updates repeat by chance."""
    need = int(min_run)
    if 0.0 < p_repeat < 1.0 and n_updates > 0:
        need = max(need, 1 + int(np.ceil(np.log(false_alarm / n_updates) / np.log(p_repeat))))
    return need


def profile(x: np.ndarray, channel: str, *, rate_hz: float, noise_window: int, min_run: int, still_share: float,
            false_alarm: float, check_frozen: bool = True, given_resolution: float | None = None,
            given_update_s: float | None = None, max_still_s: float | None = None) -> SensorProfile:
    """Characterise one channel from its candidate values (NaN where already flagged)."""
    x = np.asarray(x, dtype=np.float64)
    given = []
    if given_resolution is not None:
        res, _ = float(given_resolution), given.append("resolution")
    else:
        res = resolution(x)
    if given_update_s is not None:
        u, _ = max(1.0, float(given_update_s) * rate_hz), given.append("update_interval_s")
    else:
        u = update_interval(x)
    finite = x[np.isfinite(x)]
    constant = finite.size > 1 and bool(np.all(finite == finite[0]))
    p = repeat_share(x, u, noise_window)
    at_rest = constant or (res > 0 and p > still_share)
    if max_still_s is not None:
        given.append("frozen_max_still_s")
    if not check_frozen or at_rest:
        need = 0
    else:
        need = frozen_run_length(min_run, p, int(round(finite.size / u)), false_alarm)
    return SensorProfile(channel, res, u, p, bool(at_rest), bool(constant), int(need),
                         float(max_still_s) if (max_still_s is not None and check_frozen) else None, tuple(given))


def frozen_and_held(x: np.ndarray, prof: SensorProfile, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Masks ``(frozen, held, anchor)`` of one channel.

    frozen: the repeats of a stuck run (its first sample, the last genuine update,
    stays unflagged).  held: the samples of a held channel that repeat the last update
    (not frozen).  anchor: the update instants (every finite sample of a channel that
    is not held; for a held one each run's first sample plus, inside a run of several
    identical updates, one instant per update interval)."""
    x = np.asarray(x, dtype=np.float64)
    n = x.size
    starts, ends = value_runs(x)
    lengths = ends - starts
    updates = run_updates(lengths, prof.update_interval)
    stuck = np.zeros(starts.size, dtype=bool)
    if prof.frozen_min_updates > 0:
        stuck |= updates >= prof.frozen_min_updates
    if prof.frozen_max_still_s is not None:
        stuck |= (lengths - 1) * dt > prof.frozen_max_still_s
    frozen = detect.mark_runs(n, starts[stuck] + 1, ends[stuck])
    anchor = np.isfinite(x) & ~frozen
    held = np.zeros(n, dtype=bool)
    if prof.held:
        keep = ~stuck & (lengths > 1)
        held = detect.mark_runs(n, starts[keep] + 1, ends[keep])
        anchor &= ~held
        # one anchor per update inside runs of several identical updates
        multi = keep & (updates > 1)
        k = updates[multi] - 1                       # inner anchors per run
        if k.size:
            first = np.repeat(np.cumsum(k) - k, k)   # index of each run's first inner anchor
            j = np.arange(int(k.sum())) - first + 1  # 1 .. k within each run
            step = np.repeat(lengths[multi] / updates[multi], k)
            inner = np.repeat(starts[multi], k) + np.round(j * step).astype(np.int64)
            anchor[inner] = True
            held[inner] = False
    return frozen, held, anchor
