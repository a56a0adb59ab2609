"""Input waveforms of unit peak amplitude: 3-2-1-1, doublets, Schroeder-phased multisines.

The field's standard inputs (Klein & Morelli, "Aircraft System Identification", ch. 9;
SIDPAC's ``mksqw`` for the multisine):

* **3-2-1-1**: steps of 3, 2, 1, 1 time units with alternating sign; its power spreads
  over about 0.1/T ... 1.5/T Hz (T the time unit).
* **doublet**: +1 for T, -1 for T; its power peaks near 0.74/T Hz.
* **multisine**: a sum of harmonics of the base frequency 1/period inside a band,
  equal power, phases by Schroeder's rule phi_k = -pi k^2 / n (the low peak factor that
  lets the largest total excitation fit a deflection limit), a whole number of periods.

Every step is smoothed by a raised-cosine ramp of ``ramp_s`` (a realistic input box or
pilot, and a finite surface rate); repeated sequences alternate in sign so that the
mean input stays near zero.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Waveform:
    """One candidate input shape: kind ("3211", "doublet", "multisine"), its parameters
    and the unit-peak time history on the sample grid."""

    kind: str
    time_unit_s: float  # 3211/doublet: time unit; multisine: period
    band_hz: tuple[float, float]
    start_s: float
    end_s: float
    values: np.ndarray  # unit peak

    def label(self) -> str:
        if self.kind == "multisine":
            return (f"Schroeder multisine {self.band_hz[0]:.2g}-{self.band_hz[1]:.2g} Hz, period "
                    f"{self.time_unit_s:.3g} s")
        return f"{'3-2-1-1' if self.kind == '3211' else 'doublet'}s, time unit {self.time_unit_s:.3g} s"


def _ramp_filter(x: np.ndarray, dt: float, ramp_s: float) -> np.ndarray:
    """Smooth steps into raised-cosine ramps of ramp_s (convolution with a Hann window of unit area)."""
    k = int(round(ramp_s / dt))
    if k < 2:
        return x
    w = np.hanning(k + 2)[1:-1]
    w /= w.sum()
    y = np.convolve(x, w, mode="full")[: x.size]
    return y


def _steps(t: np.ndarray, start: float, end: float, pattern, unit: float, gap_units: float) -> np.ndarray:
    x = np.zeros_like(t)
    length = sum(abs(u) for u, _ in pattern) * unit
    s, sign = start, 1.0
    while s + length <= end + 1e-9:
        c = s
        for units, level in pattern:
            x[(t >= c - 1e-9) & (t < c + units * unit - 1e-9)] = sign * level
            c += units * unit
        s = c + gap_units * unit
        sign = -sign
    return x


def three_two_one_one(t: np.ndarray, start: float, end: float, unit: float, ramp_s: float,
                      gap_units: float = 3.0) -> Waveform:
    x = _steps(t, start, end, ((3, 1.0), (2, -1.0), (1, 1.0), (1, -1.0)), unit, gap_units)
    return Waveform("3211", unit, (0.1 / unit, 1.5 / unit), start, end, _unit_peak(_ramp_filter(x, t[1] - t[0], ramp_s)))


def doublets(t: np.ndarray, start: float, end: float, unit: float, ramp_s: float, gap_units: float = 1.0) -> Waveform:
    x = _steps(t, start, end, ((1, 1.0), (1, -1.0)), unit, gap_units)
    return Waveform("doublet", unit, (0.3 / unit, 1.2 / unit), start, end, _unit_peak(_ramp_filter(x, t[1] - t[0], ramp_s)))


def schroeder_multisine(t: np.ndarray, start: float, end: float, f_lo: float, f_hi: float, period: float,
                        ramp_s: float) -> Waveform:
    """Equal-power harmonics of 1/period in [f_lo, f_hi] with Schroeder phases, repeated over
    whole periods inside [start, end] (raised-cosine fade-in/out of ramp_s at the ends)."""
    f0 = 1.0 / period
    ks = np.arange(max(1, int(np.ceil(f_lo / f0 - 1e-9))), int(np.floor(f_hi / f0 + 1e-9)) + 1)
    if ks.size == 0:
        raise ValueError(f"no harmonic of 1/{period:g} s inside {f_lo:g}-{f_hi:g} Hz")
    n = ks.size
    phases = -np.pi * np.arange(1, n + 1) ** 2 / n
    n_periods = int(np.floor((end - start) / period + 1e-9))
    stop = start + n_periods * period
    inside = (t >= start) & (t < stop)
    tau = t - start
    x = np.zeros_like(t)
    for k, ph in zip(ks, phases):
        x[inside] += np.cos(2 * np.pi * k * f0 * tau[inside] + ph)
    # fade in / out so the command starts and ends at zero without a jump
    fade = np.ones_like(t)
    if ramp_s > 0:
        a = np.clip(tau / ramp_s, 0, 1)
        b = np.clip((stop - t) / ramp_s, 0, 1)
        fade = 0.5 * (1 - np.cos(np.pi * np.minimum(a, b)))
    return Waveform("multisine", period, (float(ks[0] * f0), float(ks[-1] * f0)), start, stop,
                    _unit_peak(x * fade * inside))


def _unit_peak(x: np.ndarray) -> np.ndarray:
    m = float(np.max(np.abs(x)))
    return x / m if m > 0 else x


def candidate_waveforms(t: np.ndarray, start: float, end: float, ramp_s: float,
                        units=(0.25, 0.4, 0.6, 1.0, 1.5, 2.5, 4.0),
                        bands=((0.05, 0.4), (0.1, 0.8), (0.2, 1.2), (0.3, 2.0), (0.05, 1.5), (0.5, 3.0))
                        ) -> list[Waveform]:
    """The search grid: 3-2-1-1s and doublets at several time units, multisines in several bands."""
    out: list[Waveform] = []
    span = end - start
    for u in units:
        if 7 * u <= span:
            out.append(three_two_one_one(t, start, end, u, ramp_s))
        if 2 * u <= span:
            out.append(doublets(t, start, end, u, ramp_s))
    for lo, hi in bands:
        period = min(span, max(2.0 / lo, 10.0)) if lo > 0 else span
        period = min(period, span)
        try:
            out.append(schroeder_multisine(t, start, end, lo, hi, period, ramp_s))
        except ValueError:
            continue
    return out
