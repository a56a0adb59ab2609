"""The whole-segment escalation of aerosid.estimation.adaptive (it raises the chains of a
systematically gated channel and keeps the run of its path that condemns fewest samples)
and the local rounds of aerosid.estimation.local_q (a round that condemns more is not kept)."""
from types import SimpleNamespace

import numpy as np

from aerosid.estimation import adaptive

N, DT, Q = 4000, 0.01, 4  # samples, step [s], the q channel (ax, ay, az, p, q, r)


def _fake_result(scale):
    """What smooth_flight gives for the pitch chain's factor scale[4] (the J3Cub seed 9
    pattern): too stiff -> q gated in two runs; x30 and x900 -> no gating, a shrinking
    windowed-NIS excursion; x27000 -> the q state runs off and q is gated for good."""
    m = scale[4]
    gated = np.zeros((N, 6), bool)
    div = np.zeros(0, int)
    if m < 30:
        gated[500:700, Q] = gated[1500:1700, Q] = True
    elif m < 27000:
        div = np.arange(1000, 1000 + (300 if m < 900 else 250))  # > 5 %: systematic
    else:
        gated[900:, Q] = True
    return SimpleNamespace(gate_flags=gated, divergence_samples=div, t_s=np.arange(N) * DT, x_smooth=np.zeros((N, 2)),
                           chan_nis_filter=np.array([1.0, 1.0, 1.0, 1.0, 1.6, 1.0]),
                           meas_names=("ax", "ay", "az", "p", "q", "r"), scale=tuple(scale))


def _run(monkeypatch):
    calls = []

    def fake(t_s, z, valid, inertia, offset, z_filled, opt, **kw):
        calls.append(tuple(opt.q_chain_scale))
        return _fake_result(opt.q_chain_scale)

    monkeypatch.setattr(adaptive, "smooth_flight", fake)
    t = np.arange(N) * DT
    out = adaptive.smooth_flight_adaptive(t, np.zeros((N, 6)), np.ones((N, 6), bool), (1, 1, 1, 0), (0, 0, 0),
                                          local_q=False)
    return out, calls


def test_condemned_samples_counts_gated_or_excursion_once():
    r = _fake_result((1,) * 6)
    assert adaptive.condemned_samples(r) == 400
    r.divergence_samples = np.arange(600, 800)  # overlaps one gated run by 100 samples
    assert adaptive.condemned_samples(r) == 500


def test_a_run_whose_states_are_not_finite_condemns_those_samples(monkeypatch):
    """The unseen minisgs seed 0 pattern: the second raise of M (x900) ran the filter off
    numerically -- NaN states everywhere, hence NaN NIS: no gated sample, no excursion.  Counted
    as condemning nothing, it was kept and the segment failed at the schema; it condemns all."""
    r = _fake_result((1,) * 6)
    r.x_smooth = np.zeros((N, 2))
    r.x_smooth[3000:, 1] = np.nan
    assert adaptive.condemned_samples(r) == 400 + 1000

    def fake(t_s, z, valid, inertia, offset, z_filled, opt, **kw):
        r = _fake_result(opt.q_chain_scale)
        if opt.q_chain_scale[4] >= 900:
            r.gate_flags[:] = False
            r.divergence_samples = np.zeros(0, int)
            r.x_smooth = np.full((N, 2), np.nan)
        return r

    monkeypatch.setattr(adaptive, "smooth_flight", fake)
    monkeypatch.setattr(adaptive, "MAX_ESCALATIONS", 2)
    out = adaptive.smooth_flight_adaptive(np.arange(N) * DT, np.zeros((N, 6)), np.ones((N, 6), bool), (1, 1, 1, 0),
                                          (0, 0, 0), local_q=False)
    assert np.isfinite(out.result.x_smooth).all()
    assert out.q_chain_scale[4] == 30.0
    assert "run 2 undone" in out.summary()


def test_the_run_of_the_path_that_condemns_fewest_is_kept_and_the_later_runs_undone(monkeypatch):
    out, calls = _run(monkeypatch)
    # stiff -> x30 (gating gone) -> x900 (smaller excursion) -> x27000 tried, worse, undone
    assert [c[4] for c in calls] == [1.0, 30.0, 900.0, 27000.0]
    assert out.q_chain_scale[4] == 900.0
    assert out.result.scale[4] == 900.0
    assert adaptive.condemned_samples(out.result) == 250
    assert out.escalations[-1] == (0, ("run 3 undone: 3100 samples condemned at the end, 250 before",))
    assert "run 3 undone" in out.summary()


def test_escalations_that_help_are_all_kept(monkeypatch):
    monkeypatch.setattr(adaptive, "MAX_ESCALATIONS", 2)
    out, calls = _run(monkeypatch)
    assert [c[4] for c in calls] == [1.0, 30.0, 900.0]
    assert out.q_chain_scale[4] == 900.0
    assert all(a > 0 for a, _ in out.escalations)  # nothing undone


def test_the_chain_of_the_channel_gated_first_is_tried_alone_and_kept_when_it_frees_more(monkeypatch):
    """The J3Cub seed 5 pattern: q locked out from 3.8 s, a_x gated later as a consequence;
    raising every chain a_x and q see (X, M, N) leaves q locked, raising M alone frees it."""
    def fake(t_s, z, valid, inertia, offset, z_filled, opt, **kw):
        sc = np.asarray(opt.q_chain_scale)
        r = _fake_result((1,) * 6)
        r.gate_flags[:] = False
        if sc[4] > 1 and sc[0] == 1:  # M alone raised: free
            return r
        r.gate_flags[380:, Q] = True
        r.gate_flags[2000:2300, 0] = True
        return r

    monkeypatch.setattr(adaptive, "smooth_flight", fake)
    assert adaptive._chain_choices([0, 4], 4) == [(0, 4, 5), (4,)]
    assert adaptive._chain_choices([4], 4) == [(4,)]
    out = adaptive.smooth_flight_adaptive(np.arange(N) * DT, np.zeros((N, 6)), np.ones((N, 6), bool), (1, 1, 1, 0),
                                          (0, 0, 0), local_q=False)
    assert out.q_chain_scale == (1.0, 1.0, 1.0, 1.0, 30.0, 1.0)
    assert adaptive.condemned_samples(out.result) == 0
    assert "raised M)" in out.summary()


def test_a_local_round_that_condemns_more_is_not_kept(monkeypatch):
    from aerosid.estimation import local_q

    def result(gated_from):
        r = _fake_result((1,) * 6)
        r.gate_flags[:] = False
        r.gate_flags[gated_from:gated_from + 100, 5] = True  # a gated r span, the manoeuvre
        if gated_from == 0:
            r.gate_flags[1000:, Q] = True  # ... freed, but q locked out from 10 s
        r.diverged, r.x_smooth, r.sigma_smooth = False, np.zeros((N, 2)), np.ones((N, 2))
        return r

    monkeypatch.setattr(local_q, "classify", lambda res, controls: [SimpleNamespace(manoeuvre=True)])
    monkeypatch.setattr(local_q, "raise_locally", lambda base, t, events: base * 30.0)
    first = result(2000)
    worse = result(0)
    out, q_local, rounds = local_q.follow_locally(lambda ql: worse, first)
    assert out is first and q_local is None and rounds == ()
    better = result(2000)
    better.gate_flags[:] = False
    out, q_local, rounds = local_q.follow_locally(lambda ql: better, first)
    assert out is better and len(rounds) == local_q.MAX_ROUNDS  # the fake classify always finds one


def test_a_raise_that_makes_things_worse_before_the_next_makes_them_better_is_walked_through(monkeypatch):
    """The pa28 seed 10 pattern: the second raise condemns more, the third removes everything."""
    def fake(t_s, z, valid, inertia, offset, z_filled, opt, **kw):
        m = opt.q_chain_scale[4]
        r = _fake_result((1,) * 6)
        r.gate_flags[:] = False
        if m < 30:
            r.gate_flags[500:700, Q] = r.gate_flags[1500:1700, Q] = True  # 400 condemned
        elif m < 900:
            r.divergence_samples = np.arange(1000, 1600)                   # 600: worse
        return r                                                           # x900: clean

    monkeypatch.setattr(adaptive, "smooth_flight", fake)
    out = adaptive.smooth_flight_adaptive(np.arange(N) * DT, np.zeros((N, 6)), np.ones((N, 6), bool), (1, 1, 1, 0),
                                          (0, 0, 0), local_q=False)
    assert out.q_chain_scale[4] == 900.0 and adaptive.condemned_samples(out.result) == 0
    assert all(a > 0 for a, _ in out.escalations) and len(out.escalations) == 2


def test_an_excursion_without_gating_tries_the_worst_fitting_channels_chain_alone(monkeypatch):
    calls = []

    def fake(t_s, z, valid, inertia, offset, z_filled, opt, **kw):
        calls.append(tuple(opt.q_chain_scale))
        r = _fake_result(opt.q_chain_scale)
        r.gate_flags[:] = False
        r.chan_nis_filter = np.array([1.6, 1.0, 1.0, 1.0, 2.5, 1.0])  # a_x and q fit badly, q worst
        r.divergence_samples = np.arange(1000, 1300) if len(calls) == 1 else np.arange(0)
        return r

    monkeypatch.setattr(adaptive, "smooth_flight", fake)
    out = adaptive.smooth_flight_adaptive(np.arange(N) * DT, np.zeros((N, 6)), np.ones((N, 6), bool), (1, 1, 1, 0),
                                          (0, 0, 0), local_q=False)
    assert calls[1] == (30.0, 1.0, 1.0, 1.0, 30.0, 30.0)  # every chain a_x and q see
    assert calls[2] == (1.0, 1.0, 1.0, 1.0, 30.0, 1.0)    # M alone: q fits worst, a_x is not first
    assert "run 1: NIS excursion, no channel gated; worst fit ax, q (raised XMN)" in out.summary()
