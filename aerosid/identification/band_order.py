"""The band path's order of operations for a model's non-linear columns.

Why
---
The band path (aerosid.identification.band) puts every flight signal through one low-pass LP
and then forms the model's columns from the low-passed signals: a term f(x) enters the fit as
f(LP(x)).  The flight-derived coefficient, though, holds the low-pass of the aerodynamics,
LP(f(x)): the accelerations went through LP *after* the aircraft had formed f(x).  For a term
linear in the signals the two are the same; for a non-linear one they are not -- |beta|'s kink,
alpha^2's and alpha^3's harmonics, cos 4 phi_r near alpha_r = 0 -- and the difference is an
error in the regressor that no model term takes and no interval knows.

Measured (bench/results/band_order.md, JSBSim DHC-6, seeds 0-4): its C_l is even in beta, and
with the ``abs(beta + k)`` term the localisation suggests, C_l,p came out +14.8 % off on average
and outside 2 sigma on 5/5 seeds (a follow-up ``abs(r_hat)`` was this artefact); in the band's
order, -0.3 % (RMS 1.1 %), within 2 sigma on 5/5.  On seed-rlv the roll terms' non-linearity was
1.1-1.5 x the Cl floor of a complete model.

What this module does
---------------------
The band path writes the regressor signals *before* its low-pass into the flight data
(:data:`WIDEBAND_COLUMNS`, written by aerosid.identification.flight_data: the vanes' clean angles or the angles
inverted from the smoother's forces, the smoother's rates, the clean fins and V).  For every
term, :meth:`BandOrder.correction` is

    d = LP(f(x_wide)) - f(LP(x_wide)),

both sides formed from the same wide-band x, so LP's attenuation of in-band content cancels and
only the term's non-linearity is left; the model's column becomes f(x) + d (expressions.evaluate),
which is LP(f(x_wide)) up to the difference between the flight data's own low-passed signals and
LP(x_wide) (none for the vanes, the inversion's for inverted angles).  d is identically zero for
a term linear in the signals (alpha, delta_p/2, a rate) and tiny for one through V (q_hat).

Where the flight data's x and LP(x_wide) differ (inverted angles) and the term is ill-conditioned
(cos 4 phi_r near alpha_r = 0), f(x) - f(LP(x_wide)) is no longer small: a column that leaves the
range of the term's values takes LP(f(x_wide)) alone (:func:`guarded_column`).

x_wide is first put through the same low-pass at WIDE_BAND_FACTOR x the band edge: the signals'
own content is inside the band, and above it a wide-band column is sensor noise, which a
non-linear term would rectify into a bias (E|beta + n| > |beta| near the kink).

LP here is the band's low-pass over every run of consecutive flight-data rows
(:func:`flight_data_runs`: a segment's own rate and band, cut at holes and at rows without
their wide-band values); the first and last band period of a run (the filter's transients)
keep d = 0.  Flight data without the wide-band columns (the smoother path, older files) have no
band order: every column is f(x) as before.

How it reaches the fit: aerosid.modelling.models.vehicle_signals puts a lazy :class:`BandOrder`
and the row numbers into the signals it returns (aerosid.modelling.expressions.BAND_ORDER_KEY,
ROW_KEY), and expressions.evaluate adds d to every term it forms from such signals: any code that
designs a model or a candidate from them, or from a row subset of them, gets the corrected columns.
The wide-band signals are computed once per flight data and cached (SIMEX designs its models on
many copies of one frame with noise added to the low-passed angles: d is the same for all).
"""
from __future__ import annotations

import hashlib
import math
import threading
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from aerosid.identification.band import finite_runs, low_pass_runs, segment_rates_and_bands

#: The flight data's regressor signals before the band's low-pass: {flight-data column: its
#: wide-band column} (written by aerosid.identification.flight_data on the band path).
WIDEBAND_COLUMNS = {"alpha_rad": "alpha_wideband_rad", "beta_rad": "beta_wideband_rad",
                    "p_rad_s": "p_wideband_rad_s", "q_rad_s": "q_wideband_rad_s", "r_rad_s": "r_wideband_rad_s",
                    "delta_p_rad": "delta_p_wideband_rad", "delta_y_rad": "delta_y_wideband_rad",
                    "delta_r_rad": "delta_r_wideband_rad", "V_m_s": "V_wideband_m_s"}
#: Form the band order (the default).  False: every column f(LP(x)) as before 2026-11-29 (for
#: the before/after comparison of bench/bench_band_order.py).
ENABLED = True
#: The wide-band signals are first low-passed at this multiple of the band edge (the same filter):
#: the signals' own content is inside the band (99 % of the gyros' signal power, band.py), and
#: |H| = 0.994 at the band edge keeps it; above, a wide-band column is sensor noise, which a
#: non-linear term rectifies (E|beta + n| > |beta| near the kink: the DHC-6's vane noise, 0.15 deg,
#: is 5 x beta's spread in quiet flight) into a bias that the final low-pass keeps.  DHC-6 seed 0
#: with the |beta| term: R^2 0.969 -> 0.989, C_l,p sigma 0.016 -> 0.012, and the |beta| x t trend
#: (t = 4.9) the noise made is gone; factors 2 and 3 agree, 4 and 6 leave a trend of beta x t.
WIDE_BAND_FACTOR = 3.0
#: Flight data whose wide-band signals are kept (a small LRU: SIMEX's frames share one).
_CACHE_SIZE = 4
#: The guard's range (guarded_column) is widened by this many robust sigmas of the bracket.
RANGE_MARGIN = 5.0
#: Fewest rows with a band-order correction for the guard to act.
MIN_GUARD_ROWS = 32
#: |d| below this share of the column is rounding: the term is linear in the signals.
LINEAR_TOLERANCE = 1e-9
#: Corrections kept per flight data (an LRU: the model's terms are asked for again and again, the
#: localisation's ~400 trial terms once or twice each; a kept correction is one float per row, so
#: keeping them all cost ~200 MB on a 60 000-row campaign).
_CORRECTIONS_KEPT = 64
_WIDE_CACHE: OrderedDict = OrderedDict()
_CACHE_LOCK = threading.Lock()  # Prefect's default task runner runs tasks in threads


def flight_data_runs(fd, valid: np.ndarray | None = None) -> list[tuple[slice, float, float, int]]:
    """(rows, sample rate [Hz], band edge [Hz], edge samples = one band period) of every run of
    consecutive flight-data rows: one flight segment (its own rate and band), adjacent rows, time
    increasing by at most 1.5 of the segment's steps, ``valid`` (default all), and longer than two
    band periods and 16 samples.  Rows are expected in flight and time order (as diagnose sorts
    them); a segment whose rows are not adjacent is cut where they are not."""
    t = fd["t_s"].to_numpy(float)
    valid = np.ones(len(fd), bool) if valid is None else np.asarray(valid, bool)
    out = []
    for idx, fs, band in segment_rates_and_bands(fd):
        if not (math.isfinite(fs) and math.isfinite(band)) or idx.size < 2:
            continue
        edge = int(math.ceil(fs / band - 1e-6))
        dt = np.diff(t[idx])
        joined = np.r_[False, (np.diff(idx) == 1) & (dt > 0) & (dt <= 1.5 / fs)]
        for r in finite_runs(valid[idx]):
            cuts = [r.start, *(r.start + 1 + np.flatnonzero(~joined[r.start + 1:r.stop])), r.stop]
            for a, b in zip(cuts[:-1], cuts[1:]):
                if b - a > 2 * edge + 16:
                    out.append((slice(int(idx[a]), int(idx[a]) + int(b - a)), fs, band, edge))
    return out


def has_wideband(fd) -> bool:
    """The flight data carry the band path's wide-band columns and a band on every row."""
    need = {*WIDEBAND_COLUMNS, *WIDEBAND_COLUMNS.values(), "band_hz", "t_s", "mach", "qbar_pa"}
    return (need <= set(fd.columns) and len(fd) > 2
            and bool(np.all(np.isfinite(fd["band_hz"].to_numpy(float)))))


@dataclass(frozen=True)
class _Wide:
    """One flight data's model signals formed from the wide-band columns (wide) and from their
    low-pass (low), the runs, the rows where d may be non-zero (inner), and the corrections
    computed so far (shared by every frame with the same wide-band content)."""

    wide: dict
    low: dict
    runs: list
    inner: np.ndarray
    corrections: OrderedDict = field(default_factory=OrderedDict)

    def low_pass(self, x: np.ndarray) -> np.ndarray:
        out = np.array(x, float)
        for r, fs, band, _ in self.runs:
            out[r] = low_pass_runs(x[r], fs, band, [slice(0, r.stop - r.start)])
        return out

    def correction(self, expression: str, keep: bool = True) -> np.ndarray | None:
        return self.parts(expression, keep)[0]

    def parts(self, expression: str, keep: bool = True) -> tuple[np.ndarray | None, np.ndarray | None, bool]:
        """(d, f(LP(x_wide)), linear) of the term on every row; (None, None, True) for a constant
        term.  linear: d is rounding (a term linear in the signals), so the guard has nothing to do."""
        from aerosid.modelling.expressions import ExpressionError, evaluate, signal_names

        with _CACHE_LOCK:
            if expression in self.corrections:
                self.corrections.move_to_end(expression)
                return self.corrections[expression]
        d = f_low = None
        linear = True
        try:  # a signal the flight data do not have (one a caller added: no wide-band form) -> none
            names = signal_names(expression, self.wide)
        except ExpressionError:
            names = frozenset()
        if names:
            n = len(self.inner)
            f_wide = evaluate(expression, self.wide, n)
            f_low = evaluate(expression, self.low, n)
            f_wide = np.where(np.isfinite(f_wide), f_wide, f_low)  # one bad value would spread over its run
            d = self.low_pass(f_wide) - f_low
            d = np.where(self.inner & np.isfinite(d), d, 0.0)
            d.setflags(write=False)
            f_low.setflags(write=False)
            linear = _is_rounding(d, f_low)
        if not keep:
            return d, f_low, linear
        with _CACHE_LOCK:
            self.corrections[expression] = (d, f_low, linear)
            while len(self.corrections) > _CORRECTIONS_KEPT:
                self.corrections.popitem(last=False)
        return d, f_low, linear


@dataclass(frozen=True)
class BandOrder:
    """The band order of one flight-data frame's model columns (module doc).  Lazy: nothing is
    computed until a term asks for its correction."""

    fd: pd.DataFrame = field(repr=False)
    vehicle: object = field(repr=False)
    _state: dict = field(default_factory=dict, repr=False, compare=False)

    def correction(self, expression: str, keep: bool = True) -> np.ndarray | None:
        """d = LP(f(x_wide)) - f(LP(x_wide)) of the term f = ``expression`` on every row of the
        flight data (0 where it cannot be formed: the runs' edges, rows without wide-band values);
        None for a constant term.  keep=False: not kept among the flight data's corrections (a
        scan's trial terms, which would push the model's own terms out)."""
        return self._wide().correction(expression, keep)

    def column(self, expression: str, values: np.ndarray, rows: np.ndarray, keep: bool = True) -> np.ndarray:
        """The term's column on flight-data rows ``rows``, given its values f(x) there: f(x) + d,
        except where that leaves the range of the term's values (guarded_column)."""
        d, f_low, linear = self._wide().parts(expression, keep)
        if d is None:
            return values
        if linear:  # the guard's own test, made once per term (every SIMEX frame asks again)
            return values + d[rows]
        return guarded_column(values, d[rows], f_low[rows])

    def _wide(self) -> "_Wide":
        if "wide" not in self._state:
            self._state["wide"] = _wide_signals(self.fd, self.vehicle)
        return self._state["wide"]


def guarded_column(values: np.ndarray, d: np.ndarray, f_low: np.ndarray) -> np.ndarray:
    """f(x) + d, and LP(f(x_wide)) = f(LP(x_wide)) + d on the rows where f(x) + d leaves the range
    its two ingredients span over the rows ([min, max] of f(x) and of LP(f(x_wide)) together,
    widened by RANGE_MARGIN robust sigmas of b, the bracket's own noise).

    f(x) + d = LP(f(x_wide)) + b, b = f(x) - f(LP(x_wide)): the band order holds while the flight
    data's x and LP(x_wide) are close enough that b is the small difference of two nearby values
    of f.  Where f is ill-conditioned b is O(1) instead: cos 4 phi_r near alpha_r = 0, where phi_r
    is undefined and the inverted angles' x and LP(x_wide) (inverted from low-passed forces and
    from the smoother's) differ by their noise.  On seed-rlv (no hidden effect, seeds 0-3) the
    column of cos 4 phi_r left [-1, 1] on 635-918 of ~6800 rows, up to 2.6
    (bench/results/band_order_columns.md); a column no value of the term reaches is the
    bracket's, not the aircraft's.  A wider rule (every bracket beyond 5 robust sigma and the
    term's spread) took rows of beta*abs(beta) where beta's noise is large, and with them the
    power to find a real beta*abs(beta) (seed-rlv with one of 30 /rad: recommended 2/3 -> 0/3).
    Only terms the band order changes (d not ~0); rows with d = 0 (runs' edges) keep f(x)."""
    out = values + d
    inside = (d != 0.0) & np.isfinite(values) & np.isfinite(f_low)
    if inside.sum() < MIN_GUARD_ROWS:
        return out
    if _is_rounding(d[inside], f_low[inside]):
        return out  # a term linear in the signals
    band = f_low + d
    b = values[inside] - f_low[inside]
    margin = RANGE_MARGIN * 1.4826 * float(np.median(np.abs(b - np.median(b))))  # the bracket's own noise
    lo = min(float(np.min(values[inside])), float(np.min(band[inside]))) - margin
    hi = max(float(np.max(values[inside])), float(np.max(band[inside]))) + margin
    gross = inside & ((out < lo) | (out > hi))
    return np.where(gross, band, out)


def _is_rounding(d: np.ndarray, f_low: np.ndarray) -> bool:
    """d is rounding against the column LP(f(x_wide)) = f_low + d where d is not 0: the term is
    linear in the signals."""
    nz = d != 0.0
    if not nz.any():
        return True
    band = np.abs(f_low[nz] + d[nz])
    return bool(np.max(np.abs(d[nz])) <= LINEAR_TOLERANCE * max(float(np.nanmax(band)) if band.size else 0.0, 1e-300))


def band_order(fd, vehicle) -> BandOrder | None:
    """The flight data's BandOrder, or None without the wide-band columns (the smoother path,
    older files)."""
    return BandOrder(fd, vehicle) if ENABLED and has_wideband(fd) else None


def _digest(fd, vehicle) -> bytes:
    """What the wide-band model signals depend on: the wide-band columns, time, band, Mach, qbar,
    flight and segment, and the vehicle's reference lengths (not the low-passed signals, which
    SIMEX perturbs).  Each numeric column by its sum and 256 evenly spaced values, the labels by
    those values: SIMEX designs its models on ~1000 copies of one frame, and a full hash of every
    row cost 1.5 s per identify."""
    n = len(fd)
    rows = np.unique(np.linspace(0, max(n - 1, 0), 256).astype(int)) if n else np.zeros(0, int)
    h = hashlib.blake2b(repr((n, vehicle.length_pitch_m, vehicle.length_lateral_m, vehicle.derivative_half_window_s,
                              getattr(vehicle, "name", ""), WIDE_BAND_FACTOR)).encode(), digest_size=16)
    x = fd[["t_s", "band_hz", "mach", "qbar_pa", *WIDEBAND_COLUMNS.values()]].to_numpy(float)
    h.update(np.nansum(x, axis=0).tobytes())
    h.update(np.isnan(x).sum(axis=0).tobytes())
    h.update(np.ascontiguousarray(x[rows]).tobytes())
    labels = [c for c in ("flight", "segment") if c in fd]
    if labels:
        h.update("\x1f".join(map(str, fd[labels].to_numpy()[rows].ravel())).encode())
    return h.digest()


def _wide_signals(fd, vehicle) -> _Wide:
    """The wide-band and the low-passed wide-band model signals of fd (cached by content)."""
    key = _digest(fd, vehicle)
    with _CACHE_LOCK:
        if key in _WIDE_CACHE:
            _WIDE_CACHE.move_to_end(key)
            return _WIDE_CACHE[key]
    from aerosid.diagnosis.candidates import derived_signals
    from aerosid.identification.inversion import total_angles
    from aerosid.modelling.models import vehicle_signals

    # rows without their wide-band values (pooled with older files, the inversion at the database's
    # edge) end a run; there the low-passed values stand in, only so that every signal is finite
    valid = np.all(np.column_stack([np.isfinite(fd[w].to_numpy(float)) for w in WIDEBAND_COLUMNS.values()]), axis=1)
    runs = flight_data_runs(fd, valid)
    inner = np.zeros(len(fd), bool)
    for r, _, _, edge in runs:
        inner[r.start + edge:r.stop - edge] = True
    wide_cols = {c: np.where(valid, fd[w].to_numpy(float), fd[c].to_numpy(float)) for c, w in WIDEBAND_COLUMNS.items()}
    w = _Wide({}, {}, runs, inner)
    if WIDE_BAND_FACTOR:  # the sensor noise far above the band out first (WIDE_BAND_FACTOR)
        pre = _Wide({}, {}, [(r, fs, band * WIDE_BAND_FACTOR, e) for r, fs, band, e in runs], inner)
        wide_cols = {c: np.where(valid, pre.low_pass(x), x) for c, x in wide_cols.items()}

    def signals(values: dict) -> dict:
        frame = fd.copy()
        for c, v in values.items():
            frame[c] = v
        v_ratio = frame["V_m_s"].to_numpy(float) / fd["V_m_s"].to_numpy(float)
        frame["mach"] = fd["mach"].to_numpy(float) * v_ratio  # the same speed of sound and density
        frame["qbar_pa"] = fd["qbar_pa"].to_numpy(float) * v_ratio ** 2
        frame["alpha_r_rad"], frame["phi_r_rad"] = total_angles(frame["alpha_rad"], frame["beta_rad"])
        return derived_signals(vehicle_signals(frame, vehicle, with_band_order=False), vehicle.length_pitch_m,
                               vehicle.length_lateral_m)

    w.wide.update(signals(wide_cols))
    w.low.update(signals({c: w.low_pass(x) for c, x in wide_cols.items()}))
    with _CACHE_LOCK:
        _WIDE_CACHE[key] = w
        while len(_WIDE_CACHE) > _CACHE_SIZE:
            _WIDE_CACHE.popitem(last=False)
    return w
