"""Time-varying process noise: raise a chain's intensity only where the vehicle does what
the stationary (spectral, whole-segment) process noise cannot follow.

The chains' process noise (method.md §3) is one spectral intensity per segment, an average
over 40-90 s; a rudder doublet lasting 2-3 s near the end of the flight is a burst that
average does not see.  Locally the N / Y chains are too stiff, the filter falls behind, the
windowed NIS leaves its band and the gate rejects r or a_y -- and those spans, the only
yaw excitation of the flight, were cut (JSBSim F4N seed 2: C_n_beta -109 %, C_n_delta_y
-107 %, sigma 7.5 %).  Escalating the whole segment (aerosid.estimation.adaptive) is kept
for systematic gating; one event is decided here.

An EVENT is a span of gated samples or windowed-NIS excursion (runs closer than
MERGE_GAP_S merged).  It is a MANOEUVRE the model cannot follow -- and its span gets
ESCALATION times more process noise on the chains of the channels involved, MARGIN_S either
side, the segment smoothed again (at most MAX_ROUNDS times) -- when

* besides the worst channel, at least one OTHER channel's standardised innovations are
  significantly above their chi-square level over the span +- MARGIN_S -- the samples a raise
  would cover; over the event alone, a windowed-NIS excursion of one sample cannot show any
  channel out (unseen minisgs seed 0: a roll doublet at 14.35 s left to the findings, the
  departure of p cut, C_n_r -11 %) -- (sum of v^2/s over its n tested
  samples > chi2(n) upper COMPANION_PROBABILITY quantile): the vehicle moves in several
  axes at once.  A sensor step or bias jump persists in one channel only: measured on
  seed-rlv (a 1.5 s +25 m/s^2 a_z step) the other five channels stay at 0.5-1.6 over the
  edges, while on F4N seed 2 a_y and a_x run at 2-3 during the build-up of the gated r
  and on T37 seed 2 r at 2-5 beside the gated a_y (docs/estimation.md);
* and, when the control positions are known, a control surface moves within the span (or
  CONTROL_LEAD_S before it) by at least CONTROL_SHARE of its range over the segment.

A round is kept only if it condemns no more samples (gated, or in a NIS excursion) than the
result before it; the rounds stop at the first that condemns more (a raise that let a state
run off elsewhere).
Anything else (one channel, or no control activity) stays what it was: reported and cut
(aerosid.estimation.findings).  The stationary path is untouched: no manoeuvre, no
multiplier, and smooth_flight with q_local=None is the filter as before, bit for bit.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from aerosid.estimation.findings import MERGE_GAP_S, condemned_samples, dilate, merge_close, sample_interval, true_runs

#: Factor on the involved chains' intensity over a manoeuvre's span, per round.
ESCALATION = 30.0
#: At most this many local rounds (re-smoothings) per segment.
MAX_ROUNDS = 3
#: The raised span reaches this far beyond the event on either side [s] (the filter must be
#: loose before the build-up that the windowed NIS only sees late).
MARGIN_S = 1.0
#: False-alarm probability of the companion-channel test (chi-square on the span's v^2/s).
COMPANION_PROBABILITY = 1e-4
#: Control activity: a control moving this share of its segment range ...
CONTROL_SHARE = 0.25
#: ... within the span or this long before it [s].
CONTROL_LEAD_S = 2.0
#: The chain (X, Y, Z, L, M, N) each channel (ax, ay, az, p, q, r) measures directly: its own
#: force or moment.  Not the angular chains an accelerometer sees through the lever arm
#: (adaptive.CHAINS_OF_CHANNEL): raising M with a_x at a rudder doublet loosened the pitch
#: moment for nothing (T37 seed 3: C_m_alpha +6.4 -> +10.3 %).
CHAINS_OF_CHANNEL = ((0,), (1,), (2,), (3,), (4,), (5,))
CHAIN_NAMES = ("X", "Y", "Z", "L", "M", "N")


@dataclass(frozen=True)
class LocalEvent:
    """One event of one round: span [s], the channels whose innovations are out of their
    level (worst first), whether controls moved (None: unknown), and the decision."""

    t0_s: float
    t1_s: float
    channels: tuple
    controls_active: bool | None
    manoeuvre: bool
    chains: tuple = ()

    def summary(self) -> str:
        what = (f"manoeuvre: chains {', '.join(self.chains)} x{ESCALATION:g} locally" if self.manoeuvre
                else "one channel or no control activity: left to the findings")
        ctl = "" if self.controls_active is None else f", controls {'moving' if self.controls_active else 'still'}"
        return f"t = {self.t0_s:.2f}..{self.t1_s:.2f} s, channels {'+'.join(self.channels) or '-'}{ctl}: {what}"


def event_mask(result) -> np.ndarray:
    """Samples gated on any channel or flagged by the windowed NIS, runs closer than MERGE_GAP_S merged."""
    t = result.t_s
    dt = sample_interval(t)
    m = np.asarray(result.gate_flags, bool).any(axis=1)
    m[np.asarray(result.divergence_samples, dtype=int)] = True
    return merge_close(m, int(round(MERGE_GAP_S / dt)))


def channels_out(innovation_sq: np.ndarray, a: int, b: int, prob: float = COMPANION_PROBABILITY) -> list[int]:
    """Channels whose sum of v^2/s over samples a..b-1 exceeds the chi-square(n) upper `prob`
    quantile (n: the samples the channel was tested on), worst (largest ratio) first."""
    seg = innovation_sq[a:b]
    out = []
    for j in range(seg.shape[1]):
        v = seg[:, j][np.isfinite(seg[:, j])]
        if v.size and v.sum() > chi2.isf(prob, v.size):
            out.append((v.sum() / v.size, j))
    return [j for _, j in sorted(out, reverse=True)]


def moving_controls(controls: np.ndarray | None, a: int, b: int, lead: int) -> list[int] | None:
    """The columns of `controls` that move by CONTROL_SHARE of their segment range within
    a-lead..b (None: no controls)."""
    if controls is None or controls.size == 0:
        return None
    u = np.asarray(controls, float)
    span = u[max(0, a - lead):b]
    out = []
    for j in range(u.shape[1]):
        full = np.nanmax(u[:, j]) - np.nanmin(u[:, j]) if np.isfinite(u[:, j]).any() else 0.0
        if not full > 1e-9 or not np.isfinite(span[:, j]).any():
            continue
        if np.nanmax(span[:, j]) - np.nanmin(span[:, j]) >= CONTROL_SHARE * full:
            out.append(j)
    return out


def controls_moving(controls: np.ndarray | None, a: int, b: int, lead: int) -> bool | None:
    """Whether a control moves by CONTROL_SHARE of its segment range within a-lead..b (None: no controls)."""
    moving = moving_controls(controls, a, b, lead)
    return None if moving is None else bool(moving)


def classify(result, controls: np.ndarray | None = None) -> list[LocalEvent]:
    """The events of a smoothed segment and whether each is a manoeuvre (module doc)."""
    t = result.t_s
    dt = sample_interval(t)
    I = result.innovation_sq
    if I is None:
        return []
    lead = int(round(CONTROL_LEAD_S / dt))
    margin = int(round(MARGIN_S / dt))
    events = []
    for a, b in true_runs(event_mask(result)):
        chans = channels_out(I, max(0, a - margin), b + margin)
        ctl = controls_moving(controls, a, b, lead)
        man = len(chans) >= 2 and ctl is not False
        chains = sorted({c for j in chans for c in CHAINS_OF_CHANNEL[j]}) if man else []
        events.append(LocalEvent(float(t[a]), float(t[b - 1]), tuple(result.meas_names[j] for j in chans), ctl, man,
                                 tuple(CHAIN_NAMES[c] for c in chains)))
    return events


def raise_locally(q_local: np.ndarray, t_s: np.ndarray, events: list[LocalEvent]) -> np.ndarray:
    """q_local with the manoeuvres' chains multiplied by ESCALATION over their span +- MARGIN_S."""
    out = np.array(q_local, dtype=float, copy=True)
    dt = sample_interval(t_s)
    margin = int(round(MARGIN_S / dt))
    for ev in events:
        if not ev.manoeuvre:
            continue
        m = np.zeros(t_s.size, bool)
        m[(t_s >= ev.t0_s) & (t_s <= ev.t1_s)] = True
        m = dilate(m, margin)
        for c in ev.chains:
            out[m, CHAIN_NAMES.index(c)] *= ESCALATION
    return out


def gate_lifted(q_local: np.ndarray) -> np.ndarray:
    """(N,) bool: the samples whose process noise is raised for a manoeuvre, where the innovation
    gate is lifted.  The gate guards against a sensor's fault; over a span the model could not
    follow (several channels out, controls moving: `classify`) it is the filter that is wrong,
    and a gate left on there locks the filter out for good once its state has run off (unseen
    global5000 seed 0: an 18-sample dropout at its rudder doublet's reversal, r 0.09 rad/s off
    after it, r gated from 52.3 s to the end even with Y, N x30 or x900 over the span; without
    the gate the smoothed r is within 0.017 rad/s of the truth)."""
    return np.any(np.asarray(q_local) != 1.0, axis=1)


def follow_locally(smooth, result, controls: np.ndarray | None = None):
    """Re-smooth with the process noise raised over the manoeuvres of `result` until none is
    left (at most MAX_ROUNDS).  smooth(q_local) -> EBMResult smooths the segment with the
    given multipliers.  Returns (final result, q_local or None, the events of every round)."""
    q_local = None
    rounds = []
    for _ in range(MAX_ROUNDS):
        if result.diverged:  # a lost filter is not one event: the segment fails as it is
            break
        events = classify(result, controls)
        if not any(ev.manoeuvre for ev in events):
            break
        base = np.ones((result.t_s.size, 6)) if q_local is None else q_local
        trial_q = raise_locally(base, result.t_s, events)
        trial = smooth(trial_q)
        if not (np.all(np.isfinite(trial.x_smooth)) and np.all(np.isfinite(trial.sigma_smooth))):
            break  # numerically lost with the raised noise: keep the last finite result
        if condemned_samples(trial) > condemned_samples(result):
            break  # the raise let a state run off elsewhere (a lock-out): keep the last result
        rounds.append(tuple(events))
        result, q_local = trial, trial_q
    return result, q_local, tuple(rounds)
