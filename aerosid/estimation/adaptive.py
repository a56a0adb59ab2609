"""Process noise chosen per flight and per chain from the filter's own gate.

The chains' spectral process noise (method.md §3) comes from the measured spectra,
which cannot show a chain's bandwidth where the signal sinks under the sensor noise.
With a chain too stiff for the flight, the filter cannot follow a sharp manoeuvre:
the innovation gate starts rejecting that channel's samples, or the windowed NIS
leaves its band, and the smoother loses the vehicle there (JSBSim c172x seed 0: a_z gated for 3.3 s during the elevator
3-2-1-1, the smoothed a_z off by up to 69 m/s^2).  Instead of a per-vehicle factor
calibrated on simulated truth, the flight itself decides: while a channel's gating is
systematic -- several gated runs, or 5 % of the segment -- (or the windowed NIS has such
excursions: then the channels whose mean standardised innovation exceeds 1.5, or the
worst one), the chains that channel sees get ESCALATION times more process
noise and the segment is smoothed again (at most MAX_ESCALATIONS times).  Once a state has
run off, the gate keeps rejecting its channel for good (a lock-out), and whether a raise
frees it depends on which chains are raised, so each escalation tries two sets -- every
chain the channels see, and only the chain that the channel gated first (the cascade's
cause; for a NIS excursion without gating, the worst-fitting channel) measures directly --
and keeps the one that condemns fewer samples (gated on any channel, or in a NIS excursion;
the first set on a tie).  A raise can make things worse before a further one makes
them better (unseen pa28 seed 10: raising M for a NIS excursion 376 -> 479 samples, the next
raises removed them), so the whole path is walked and the run that condemns fewest is kept
(the later on a tie); the runs after it are undone and the summary says so.
Measured on the unseen JSBSim J3Cub: seed 9's third escalation, for a NIS excursion alone,
took M to x27000, the q state ran off after a 1.2 rad/s^2 elevator step and q was gated for
the last 25 s (209 -> 2601 samples condemned, the segment lost); on seed 5 raising X, L, M, N
left q locked out from 3.8 s (3098 condemned) where raising M alone freed it (233).  What is
still gated afterwards is a single event: if it is a manoeuvre the model cannot follow
(several channels out, controls moving), the process noise is raised over its span only
(aerosid.estimation.local_q); what is left is reported and cut (aerosid.estimation.findings).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from aerosid.estimation.findings import (GATED_RUN_MIN_S, MERGE_GAP_S, condemned_samples, dilate, sample_interval,
                                         true_runs)
from aerosid.estimation.local_q import CHAIN_NAMES, follow_locally, gate_lifted
from aerosid.estimation.local_q import CHAINS_OF_CHANNEL as MEASURED_CHAIN
from aerosid.estimation.pipeline import EBMOptions, EBMResult, smooth_flight

#: Factor on a chain's process-noise intensity per escalation.
ESCALATION = 30.0
#: At most this many re-runs of the smoother per segment.
MAX_ESCALATIONS = 3
#: Chains (X, Y, Z, L, M, N) each measurement channel (ax, ay, az, p, q, r) depends on:
#: the accelerometers see their force chain and, through the lever arm, the angular ones.
CHAINS_OF_CHANNEL = ((0, 4, 5), (1, 3, 5), (2, 3, 4), (3, 5), (4,), (5, 3))


@dataclass(frozen=True)
class AdaptiveSmoothing:
    """The final smoother result, the chain factors it used and what was escalated."""

    result: EBMResult
    q_chain_scale: tuple
    escalations: tuple  # (attempt, (why + channels ...)) per re-run; (0, (why,)): runs undone
    local_rounds: tuple = ()  # per local round: the aerosid.estimation.local_q.LocalEvent's it classified

    def summary(self) -> str:
        local = ""
        if self.local_rounds:
            local = "; raised locally: " + " | ".join(
                f"round {i + 1}: " + ", ".join(ev.summary() for ev in evs) for i, evs in enumerate(self.local_rounds))
        if not self.escalations:
            return "process noise: spectral, no escalation needed" + local
        steps = "; ".join(f"run {a}: {', '.join(ch)}" if a else ch[0] for a, ch in self.escalations)
        return f"process noise escalated ({steps}); chain factors {self.q_chain_scale}" + local


#: A channel's gating is the model's (escalate) rather than one local event (a sensor fault:
#: report and cut) when it has at least this many gated runs, or this share of gated samples.
SYSTEMATIC_RUNS = 2
SYSTEMATIC_FRACTION = 0.05


def _systematic(flags: np.ndarray, need: int, merge: int) -> bool:
    """Runs of at least `need` samples exist, and after merging runs closer than `merge`
    samples there are SYSTEMATIC_RUNS of them, or they cover SYSTEMATIC_FRACTION."""
    if not any(b - a >= need for a, b in true_runs(flags)):
        return False
    merged = true_runs(dilate(flags, merge // 2))
    return len(merged) >= SYSTEMATIC_RUNS or flags.mean() >= SYSTEMATIC_FRACTION


def gated_channels(result: EBMResult, min_run_s: float = GATED_RUN_MIN_S) -> list[int]:
    """Measurement channels whose gating is systematic: runs of gated samples of at least
    min_run_s, at least SYSTEMATIC_RUNS of them or SYSTEMATIC_FRACTION of the segment.  One
    short gated run is a local event -- a sensor step, a bias jump -- that more process
    noise would let into the smoothed signals (a 1.5 s, +25 m/s^2 a_z step on seed-rlv,
    absorbed that way, took C_m_alpha to -90 % without a word): it stays a finding."""
    t = result.t_s
    dt = sample_interval(t)
    need = max(1, int(np.ceil(min_run_s / dt)))
    merge = int(round(MERGE_GAP_S / dt))
    return [j for j in range(result.gate_flags.shape[1]) if _systematic(result.gate_flags[:, j], need, merge)]


def _chain_choices(bad: list[int], first: int) -> list[tuple[int, ...]]:
    """The chain sets one escalation tries for the channels `bad`: every chain those channels
    see (CHAINS_OF_CHANNEL), then only the chain that `first` -- the channel gated first, the
    cause of a lock-out cascade -- measures directly (its own force or moment: local_q's
    CHAINS_OF_CHANNEL), when that differs."""
    seen = tuple(sorted({c for j in bad for c in CHAINS_OF_CHANNEL[j]}))
    own = MEASURED_CHAIN[first]
    return [seen] if own == seen else [seen, own]


def smooth_flight_adaptive(t_s, z, valid, inertia_kg_m2, sensor_offset_m, z_filled=None,
                           options: EBMOptions | None = None, controls=None,
                           local_q: bool = True) -> AdaptiveSmoothing:
    """:func:`aerosid.estimation.pipeline.smooth_flight`, re-run with more process noise on
    the chains of any channel that has a run of gated samples (module doc); controls (N, m)
    control positions (or None) for the local decision; local_q=False: no local raise."""
    opt = options or EBMOptions()
    scale = np.asarray(opt.q_chain_scale, dtype=float).copy()
    escalations = []
    result = smooth_flight(t_s, z, valid, inertia_kg_m2, sensor_offset_m, z_filled, opt)
    path = [(condemned_samples(result), scale, result, 0)]  # (condemned, chain factors, result, escalations)
    for attempt in range(1, MAX_ESCALATIONS + 1):
        bad = gated_channels(result)
        flagged = np.zeros(result.t_s.size, bool)
        flagged[np.asarray(result.divergence_samples, dtype=int)] = True
        dt = sample_interval(result.t_s)
        excursion = _systematic(flagged, 1, int(round(MERGE_GAP_S / dt)))
        if not bad and not excursion:
            break
        misfit = np.asarray(result.chan_nis_filter, float)
        why = "gated"
        if not bad:  # a windowed-NIS excursion without a gated run: the channels that fit worst
            bad = [int(j) for j in np.nonzero(misfit > 1.5)[0]] or [int(np.nanargmax(misfit))]
            why = "NIS excursion, no channel gated; worst fit"
        best = None
        gated = result.gate_flags[:, bad]
        if gated.any():  # the channel gated first: the cause of a lock-out cascade
            first = bad[int(np.argmin(np.where(gated.any(axis=0), gated.argmax(axis=0), gated.shape[0])))]
        else:  # the worst-fitting one
            first = bad[int(np.nanargmax(misfit[bad]))]
        for chains in _chain_choices(bad, first):
            trial = scale.copy()
            trial[list(chains)] *= ESCALATION
            run = smooth_flight(t_s, z, valid, inertia_kg_m2, sensor_offset_m, z_filled,
                                dataclasses.replace(opt, q_chain_scale=tuple(float(v) for v in trial)))
            n = condemned_samples(run)
            if best is None or n < best[0]:
                best = (n, chains, trial, run)
        n, chains, scale, result = best
        raised = "".join(CHAIN_NAMES[c] for c in sorted(chains))
        label = [result.meas_names[j] for j in bad]
        label[-1] += f" (raised {raised})"
        label[0] = f"{why} {label[0]}"
        escalations.append((attempt, tuple(label)))
        path.append((n, scale, result, len(escalations)))
    # the run of the path that condemns fewest samples (the later one on a tie): a raise can make
    # things worse before a further one makes them better, so the path is walked, then chosen on
    n_best = min(h[0] for h in path)
    kept = [h for h in path if h[0] == n_best][-1]
    if kept is not path[-1]:
        _, scale, result, k = kept
        runs = f"run {k + 1}" if k + 1 == len(path) - 1 else f"runs {k + 1}-{len(path) - 1}"
        escalations.append((0, (f"{runs} undone: {path[-1][0]} samples condemned at the end, {n_best} before",)))
    rounds = ()
    if local_q:
        def local(res, sc):
            # the local rounds keep the stationary pass's Q scale: re-tuning it once the burst is absorbed
            # moves Q for the whole segment (F4N seed 1: q_scale to its lower bound, a pitch manoeuvre at
            # 6 s then gated); R is re-estimated (EM) from the stationary pass's values
            tuned = [h for h in res.tuning_history if np.isfinite(h.mean_nis_filter)][-1:]
            fix = dict(q_scale=tuned[0].q_scale, q_scale_bounds=(tuned[0].q_scale,) * 2,
                       r_scale=tuple(tuned[0].r_scale)) if tuned else {}
            final = dataclasses.replace(opt, q_chain_scale=tuple(float(v) for v in sc), **fix)
            return follow_locally(
                lambda ql: smooth_flight(t_s, z, valid, inertia_kg_m2, sensor_offset_m, z_filled, final, q_local=ql,
                                         gate_off=gate_lifted(ql)),
                res, controls)

        escalated, _, rounds = local(result, scale)
        if any(a > 0 for a, _ in escalations):
            # the whole-segment escalation and the local raise are alternatives: a lock-out in one
            # manoeuvre reads as systematic gating, and raising the whole segment can leave it locked
            # (unseen global5000 seed 0: L, N x27000, p then gated to the end; the local raise from the
            # unescalated run frees it): the local rounds from the first run too, fewer condemned kept
            first, _, first_rounds = local(path[0][2], path[0][1])
            n_first, n_escalated = condemned_samples(first), condemned_samples(escalated)
            if first_rounds and n_first < n_escalated:
                escalations.append((0, (f"escalation undone: the local raise on the first run condemns "
                                        f"{n_first} samples, {n_escalated} with it",)))
                escalated, rounds, scale = first, first_rounds, path[0][1]
        result = escalated
    return AdaptiveSmoothing(result, tuple(float(v) for v in scale), tuple(escalations), rounds)
