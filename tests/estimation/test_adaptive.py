"""The whole-segment escalation of aerosid.estimation.adaptive: it raises the chains of a
systematically gated channel, and keeps a raise only while it condemns fewer samples."""
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
    return SimpleNamespace(gate_flags=gated, divergence_samples=div, t_s=np.arange(N) * DT,
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


def test_an_escalation_that_condemns_more_is_undone_and_the_escalation_stops(monkeypatch):
    out, calls = _run(monkeypatch)
    # stiff -> x30 (gating gone) -> x900 (smaller excursion) -> x27000 tried, worse, undone
    assert [c[4] for c in calls] == [1.0, 30.0, 900.0, 27000.0]
    assert out.q_chain_scale[4] == 900.0
    assert out.result.scale[4] == 900.0
    assert adaptive.condemned_samples(out.result) == 250
    assert "undone" in out.escalations[-1][1][0] and "3100 samples instead of 250" in out.escalations[-1][1][0]
    assert "undone" in out.summary()


def test_escalations_that_help_are_all_kept(monkeypatch):
    monkeypatch.setattr(adaptive, "MAX_ESCALATIONS", 2)
    out, calls = _run(monkeypatch)
    assert [c[4] for c in calls] == [1.0, 30.0, 900.0]
    assert out.q_chain_scale[4] == 900.0
    assert all("undone" not in " ".join(ch) for _, ch in out.escalations)


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
