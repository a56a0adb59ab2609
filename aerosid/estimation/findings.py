"""Findings: what went wrong in a segment, where, and what was cut because of it.

A run must not say "ok" over a failure that only shows in a number nobody reads.
Each check below names its time span; the samples it condemns are cut from the
regression (with a margin) and the rest of the segment is kept:

* ``gated``: a run of samples the filter's innovation gate rejected on one channel, left
  after the process noise was raised for systematic gating (aerosid.estimation.adaptive) and
  over the manoeuvres the model could not follow (aerosid.estimation.local_q):
  one local event where the measurement and the other sensors disagree, a sensor step or
  bias jump -- cut (the measurement is what the regression reads);
* ``nis_excursion``: the windowed NIS far outside its band (the divergence test of
  aerosid.estimation.pipeline) -- cut when it lasts SUSTAINED_EXCURSION_S (the measurements
  and the model disagree for seconds: a pitch gyro reading 10x, a lost filter); a shorter
  one is reported only: the smoother could not follow the vehicle for a moment, but the
  regression reads the measurements (aerosid.identification.band), and cutting where the
  smoother lags is cutting where the vehicle moves hardest -- a selection on the
  dependent variable that took C_m_alpha to -39 % on one c172x seed;
* ``nis_mean``: the segment's mean NIS outside its chi-square band, either way (R or Q
  mis-set for this flight: the smoother's sigma are off by about the factor the message
  gives, sqrt(mean NIS / its expected value)) -- reported;
* ``departure``: the smoothed signal departs from its band-limited measurement by more
  than DEPARTURE_SIGMA of their combined uncertainty, for DEPARTURE_MIN_S -- cut: short
  and local, they mark where either side is wrong (a fault the gate let pass, the band
  filter's transient at a gap); on seed-rlv, keeping them took C_m_alpha to -12 % on one
  seed (RMS 5.0 % over 10 against 2.8 % when cut);
* ``database_edge``: alpha/beta inverted at an edge of the force database (the table is
  clamped there: the angle would be made up), or Mach outside it -- cut.

The flight data add ``airdata_delay`` (reported): the vane alpha lags the IMU's kinematics
by a sample or more (aerosid.identification.vanes); ``airspeed_scale`` (reported): the pitch
kinematics put V_m_s beyond what a true airspeed gives (aerosid.identification.airdata_findings);
``kinematic_mismatch`` (cut from every channel): the vane's rate and the flight-path kinematics'
alpha-dot disagree for a moment -- a pitch-gyro or a_z step the filter followed as a manoeuvre.

The preprocessing adds ``time_jitter``, ``frozen``, ``sentinel`` and ``out_of_range`` (segment
"preprocess"): timestamps off the grid and sensor faults, whose samples it treats as missing
(aerosid.preprocess.result.PreprocessResult.findings); and ``phase_shift`` (reported): rows whose
sample phase moved at a dropout, re-timed onto the grid and kept.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

#: A run of gated samples on one channel at least this long is a finding [s].
GATED_RUN_MIN_S = 0.1
#: Gated runs of one channel closer than this are one event [s]: a sensor step is gated at
#: its two edges while the filter adapts in between, and the whole step is the fault.
MERGE_GAP_S = 2.0
#: A windowed-NIS excursion this long is sustained: cut (shorter ones are reported) [s];
#: the divergence test's own minimum run (EBMOptions.divergence_min_s).
SUSTAINED_EXCURSION_S = 3.0
#: The force coefficient each accelerometer makes.
ACCEL_CHANNEL = {"ax": "CA", "ay": "CY", "az": "CN"}
#: The accelerometers that feed that one channel alone, by the vehicle's air-data source.  With
#: vanes all three; with alpha and beta inverted from the force database a_y and a_z feed the
#: angles, hence every channel, and a_x still only C_A.  The gyros feed every channel (the
#: moments, and the accelerometers' transfer to the CG).
SENSOR_CHANNEL = {"vanes": dict(ACCEL_CHANNEL), "database": {"ax": "CA"}}
#: The smoothed frame's column of the samples condemned on such a sensor and kept for the others.
KEPT_SUSPECT_COLUMN = {"ax": "suspect_ax", "ay": "suspect_ay", "az": "suspect_az"}
#: The flight data's column of the rows whose coefficient reads such a condemned sample.
CUT_COLUMN = {"CA": "cut_CA", "CY": "cut_CY", "CN": "cut_CN"}
#: Departure threshold in sigma of (measured - smoothed) after the common band.
DEPARTURE_SIGMA = 6.0
#: A departure must last this long to count [s].
DEPARTURE_MIN_S = 0.1


@dataclass(frozen=True)
class Finding:
    """One finding of one segment: kind (see the module), segment id, channel (or ''),
    time span t0_s..t1_s [s], samples involved, whether those samples were cut from the
    regression, and a sentence for the engineer."""

    kind: str
    segment: str
    channel: str
    t0_s: float
    t1_s: float
    n_samples: int
    cut: bool
    detail: str

    def summary(self) -> str:
        where = f" {self.channel}" if self.channel else ""
        action = "cut from the regression" if self.cut else "reported"
        return (f"{self.segment}{where}: {self.kind} at t = {self.t0_s:.2f}..{self.t1_s:.2f} s "
                f"({self.n_samples} samples, {action}): {self.detail}")

    def as_dict(self) -> dict:
        return asdict(self)


def kept_sensors(air_data_source: str) -> dict[str, str]:
    """{sensor: channel} of the sensors whose condemned samples cost only the one channel they
    feed (SENSOR_CHANNEL): the flight data keep those samples for the other channels and mark
    that channel's rows (CUT_COLUMN), which its fit leaves out.  A finding on any other sensor
    cuts its samples from every channel's regression."""
    return dict(SENSOR_CHANNEL["vanes" if air_data_source == "vanes" else "database"])


def kept_note(sensor: str, channel: str) -> str:
    """The sentence a finding on a kept sensor ends with."""
    return (f"; kept for the other channels: {sensor} feeds only {channel}, whose fit leaves these samples "
            f"out{' (no default model fits it)' if channel == 'CA' else ''}")


def findings_mask(t_s: np.ndarray, findings) -> np.ndarray:
    """The samples inside the time spans of ``findings`` (each a run of samples t0_s..t1_s)."""
    t = np.asarray(t_s, float)
    out = np.zeros(t.size, bool)
    for f in findings:
        out |= (t >= f.t0_s) & (t <= f.t1_s)
    return out


def sample_interval(t_s: np.ndarray) -> float:
    """The segment's sample interval [s]: the median step of t_s (1 for fewer than two samples)."""
    t = np.asarray(t_s, float)
    return float(np.median(np.diff(t))) if t.size > 1 else 1.0


def true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index pairs of the runs of True."""
    m = np.asarray(mask, bool)
    d = np.diff(np.concatenate([[0], m.astype(np.int8), [0]]))
    return list(zip(np.nonzero(d == 1)[0].tolist(), np.nonzero(d == -1)[0].tolist()))


def merge_close(mask: np.ndarray, gap: int) -> np.ndarray:
    """mask with the gaps shorter than `gap` samples between two runs filled."""
    m = np.asarray(mask, bool).copy()
    runs = true_runs(m)
    for (a0, b0), (a1, b1) in zip(runs, runs[1:]):
        if a1 - b0 < gap:
            m[b0:a1] = True
    return m


def dilate(mask: np.ndarray, margin: int) -> np.ndarray:
    """mask grown by `margin` samples on each side."""
    m = np.asarray(mask, bool)
    if margin <= 0 or not m.any():
        return m.copy()
    c = np.concatenate([[0], np.cumsum(m, dtype=np.int64)])
    i = np.arange(m.size)
    return (c[np.minimum(i + margin + 1, m.size)] - c[np.maximum(i - margin, 0)]) > 0


def condemned_samples(result) -> int:
    """How much of a segment an EBMResult loses to its filter: the samples gated on any
    channel, in a windowed-NIS excursion, or whose smoothed state is not finite (a filter that
    ran off numerically: its NIS is NaN there, so neither test above sees it), counted once
    (the escalation's yardstick; the findings below cut less: they merge, and skip short runs
    and excursions)."""
    flags = np.asarray(result.gate_flags).any(axis=1)
    flags[np.asarray(result.divergence_samples, dtype=int)] = True
    flags |= ~np.isfinite(np.asarray(result.x_smooth)).all(axis=1)
    return int(flags.sum())


def span_findings(kind: str, segment: str, channel: str, t_s: np.ndarray, mask: np.ndarray, min_samples: int,
                  cut: bool, detail: str) -> tuple[list[Finding], np.ndarray]:
    """Findings for the runs of `mask` of at least `min_samples`, and the mask of those runs."""
    out, hit = [], np.zeros(len(t_s), bool)
    for a, b in true_runs(mask):
        if b - a >= max(1, min_samples):
            out.append(Finding(kind, segment, channel, float(t_s[a]), float(t_s[b - 1]), int(b - a), cut, detail))
            hit[a:b] = True
    return out, hit


def smoother_findings(t_s: np.ndarray, gated: dict[str, np.ndarray], excursion: np.ndarray,
                      mean_nis: float, nis_band: tuple[float, float], segment: str,
                      channel_nis: dict[str, float] | None = None, whiteness: dict[str, float] | None = None,
                      f_cut_hz: float | None = None) -> tuple[list[Finding], np.ndarray]:
    """Findings of a smoothed segment: gated runs per channel, windowed-NIS excursions,
    the mean NIS against its band.  Returns them and the mask of samples to cut.
    channel_nis: mean standardised innovation square per channel (1 expected);
    whiteness: dispersion sigma / white floor per channel
    (aerosid.estimation.init.NoiseDispersion.whiteness), f_cut_hz the dispersion's edge
    [Hz]: with them a mean-NIS finding names the channels and, below its band, the cause."""
    t = np.asarray(t_s, float)
    dt = sample_interval(t)
    found, cut = [], np.zeros(t.size, bool)
    for ch, g in gated.items():
        f, hit = span_findings("gated", segment, ch, t, merge_close(g, int(round(MERGE_GAP_S / dt))),
                               int(np.ceil(GATED_RUN_MIN_S / dt)), True,
                               "the filter's innovation gate rejected this channel's samples (runs less than "
                               f"{MERGE_GAP_S:g} s apart taken as one event)")
        found += f
        cut |= hit
    merged = merge_close(excursion, int(round(MERGE_GAP_S / dt)))
    need = int(np.ceil(SUSTAINED_EXCURSION_S / dt))
    for a, b in true_runs(merged):
        sustained = b - a >= need
        found.append(Finding(
            "nis_excursion", segment, "", float(t[a]), float(t[b - 1]), int(b - a), sustained,
            "windowed NIS far outside its chi-square band for "
            + (f"{SUSTAINED_EXCURSION_S:g} s or more: the measurements and the vehicle model disagree for "
               "seconds (a sensor fault, a lost filter)" if sustained else
               "a moment: the smoother could not follow the vehicle here (its states and sigma are "
               "suspect; the regression reads the measurements, which it keeps)")))
        if sustained:
            cut[a:b] = True
    lo, hi = nis_band
    if np.isfinite(mean_nis) and not (lo <= mean_nis <= hi):
        side = "above" if mean_nis > hi else "below"
        # innovations of covariance k S give a mean NIS of k m: their spread is sqrt(k) x the filter's
        spread = float(np.sqrt(mean_nis / (0.5 * (lo + hi)))) if mean_nis >= 0 and lo + hi > 0 else float("nan")
        found.append(Finding("nis_mean", segment, "", float(t[0]), float(t[-1]), int(t.size), False,
                             f"mean NIS {mean_nis:.2f} {side} its band {lo:.2f}..{hi:.2f}: the noise model does "
                             f"not fit this flight (the innovations spread {spread:.2f} x what the filter assumes), "
                             "the smoother's sigma are off by about that factor"
                             + nis_mean_cause(side, channel_nis or {}, whiteness or {}, f_cut_hz)))
    return found, cut


#: A channel's mean NIS this far from 1 (a factor) is named in a mean-NIS finding.
CHANNEL_NIS_OFF = 2.0
#: Dispersion sigma over the white floor near Nyquist from which a channel's noise is not
#: white (simulated white noise 0.9-1.06; the Twin Otter's low-passed IMU 13-34).
NOT_WHITE = 2.0


def nis_mean_cause(side: str, channel_nis: dict[str, float], whiteness: dict[str, float],
                   f_cut_hz: float | None) -> str:
    """The part of a mean-NIS finding that names the channels off their own NIS (1 each)
    and, below the band, those whose noise above the dispersion's edge is not white: a
    signal low-passed before it was recorded, whose R from the dispersion is too large."""
    off = {c: v for c, v in channel_nis.items()
           if np.isfinite(v) and (v * CHANNEL_NIS_OFF < 1.0 if side == "below" else v > CHANNEL_NIS_OFF)}
    if not off:
        return ""
    text = "; channels off their NIS of 1: " + ", ".join(f"{c} {v:.2f}" for c, v in off.items())
    coloured = {c: whiteness[c] for c in off if np.isfinite(whiteness.get(c, np.nan)) and whiteness[c] >= NOT_WHITE}
    if side == "below" and coloured:
        edge = f"{f_cut_hz:g} Hz" if f_cut_hz else "the band edge"
        text += (f". The noise of {', '.join(coloured)} above {edge} is not white (its sigma is "
                 + ", ".join(f"{w:.0f}x" for w in coloured.values())
                 + " the white-noise sigma the density near Nyquist implies): the recorded signals look low-pass "
                 "filtered (anti-aliasing or smoothing before recording), so R from their dispersion counts "
                 "signal or coloured noise as white noise and is too large")
    return text
