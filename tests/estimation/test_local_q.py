"""Time-varying (local) process noise: the kernel's stationary path is untouched, a local
multiplier is the process noise it says, a short sharp manoeuvre is followed instead of
gated, and a single-channel sensor step is still gated and cut (aerosid.estimation.local_q)."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from aerosid.estimation import discrete_process_noise, run_filter_smoother
from aerosid.estimation.adaptive import smooth_flight_adaptive
from aerosid.estimation.core_run import chain_shares
from aerosid.estimation.findings import smoother_findings
from aerosid.estimation.init import initial_state
from aerosid.estimation.local_q import channels_out, classify, controls_moving
from aerosid.estimation.model import IX_ACC, IX_ANG, N_STATE, PlantModel, measure_many, rate_rhs
from aerosid.estimation.pipeline import EBMOptions
from aerosid.estimation.synthetic import RLV_INERTIA, RLV_OFFSET, SEED_NOISE_SIGMA

Q_CHAIN = np.array([4e5, 4e5, 8e5, 2e4, 2e4, 2e4])
R_DIAG = np.asarray(SEED_NOISE_SIGMA) ** 2
BURST_T = 25.0


def _setup(flight, n=1500):
    z = flight.z[:n]
    valid = np.ones_like(z, bool)
    x0, P0, _ = initial_state(flight.t_s[:n], z, valid, flight.model, np.asarray(SEED_NOISE_SIGMA))
    return z, valid, x0, P0, discrete_process_noise(Q_CHAIN, flight.model)


def _fields(run):
    return ("x_filter", "sigma_filter", "x_smooth", "sigma_smooth", "nis_filter", "nis_smoother", "used", "gated",
            "angacc", "angacc_sigma", "chan_nis_filter", "chan_nis_smoother", "em_R", "innovation_sq")


def test_all_ones_multiplier_is_the_stationary_filter_bit_for_bit(flight):
    z, valid, x0, P0, Qd = _setup(flight)
    a = run_filter_smoother(z, valid, x0, P0, flight.model, Qd, R_DIAG, 23.93)
    b = run_filter_smoother(z, valid, x0, P0, flight.model, Qd, R_DIAG, 23.93,
                            q_local=np.ones((z.shape[0], 6)), q_shares=chain_shares(Q_CHAIN, flight.model))
    for f in _fields(a):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    # (all ones are passed to the kernel as no rows; the per-step path itself: _fast test below)
    c = run_filter_smoother(z, valid, x0, P0, flight.model, Qd, R_DIAG, 23.93,
                            q_local=np.where(np.arange(z.shape[0])[:, None] == 7, 2.0, 1.0) * np.ones((1, 6)),
                            q_shares=chain_shares(Q_CHAIN, flight.model))
    assert not np.array_equal(a.x_smooth, c.x_smooth)  # one step with 2 x Q does change the result


def test_kernel_with_ones_on_every_step_equals_no_rows(flight):
    """The kernel's per-step test (_fast._step_q) with ones everywhere returns Qd itself."""
    from aerosid.estimation import _fast
    z, valid, x0, P0, Qd = _setup(flight, n=600)
    NP, N = _fast.NP, z.shape[0]
    x0p, P0p, Qdp = np.zeros(NP), np.zeros((NP, NP)), np.zeros((NP, NP))
    x0p[:21], P0p[:21, :21], Qdp[:21, :21] = x0, P0, Qd
    Qc = np.zeros((6, NP, NP))
    Qc[:, :21, :21] = chain_shares(Q_CHAIN, flight.model)
    outs = []
    for qm in (np.ones((0, 6)), np.ones((N, 6))):
        seg = 64
        bufs = [np.empty((N, 21)), np.empty((N, 21)), np.empty(N), np.empty(N, np.int64), np.empty((N, 6), bool),
                np.empty((N, 6), bool), np.empty(((N + seg - 1) // seg, NP, NP)), np.empty((N, 21)),
                np.empty((N, 21)), np.empty(N), np.empty((N, 3)), np.empty((N, 3)), np.zeros((5, 6)),
                np.empty((seg, NP, NP)), np.zeros((seg, 6, NP)), np.zeros((seg, 6, NP)), np.zeros((seg, 6)),
                np.ones((seg, 6)), np.zeros((seg, 3, 12)), np.empty((N, 6))]
        _fast.run(np.ascontiguousarray(z), valid, x0p, P0p, flight.model.params, Qdp, Qc, qm, R_DIAG, 23.93, True,
                  np.ones(0, np.bool_), np.zeros(6, np.int64), seg, *bufs)
        outs.append(bufs)
    for i in (0, 1, 2, 3, 4, 5, 7, 8, 9, 10, 11, 12, 19):  # the outputs (not checkpoints, work buffers)
        np.testing.assert_array_equal(outs[0][i], outs[1][i], err_msg=str(i))


def test_a_constant_multiplier_is_the_scaled_stationary_process_noise(flight):
    z, valid, x0, P0, Qd = _setup(flight)
    m = np.array([1.0, 3.0, 1.0, 10.0, 1.0, 30.0])
    a = run_filter_smoother(z, valid, x0, P0, flight.model, discrete_process_noise(Q_CHAIN * m, flight.model),
                            R_DIAG, 23.93)
    b = run_filter_smoother(z, valid, x0, P0, flight.model, Qd, R_DIAG, 23.93,
                            q_local=np.tile(m, (z.shape[0], 1)), q_shares=chain_shares(Q_CHAIN, flight.model))
    for f in ("x_smooth", "sigma_smooth", "nis_filter"):
        np.testing.assert_allclose(getattr(b, f), getattr(a, f), rtol=1e-7, atol=1e-9, err_msg=f)


def test_compiled_local_process_noise_equals_the_reference(short_flight):
    z, valid, x0, P0, Qd = _setup(short_flight, n=300)
    qm = np.ones((300, 6))
    qm[120:180, 5] = 50.0
    qm[150:200, 1] = 7.0
    kw = dict(q_local=qm, q_shares=chain_shares(Q_CHAIN, short_flight.model))
    a = run_filter_smoother(z, valid, x0, P0, short_flight.model, Qd, R_DIAG, 23.93, segment_length=16, **kw)
    b = run_filter_smoother(z, valid, x0, P0, short_flight.model, Qd, R_DIAG, 23.93, use_numba=False, **kw)
    s = run_filter_smoother(z, valid, x0, P0, short_flight.model, Qd, R_DIAG, 23.93, segment_length=16)
    sc = np.max(np.abs(b.x_smooth), axis=0) + 1e-12
    assert np.max(np.abs(a.x_smooth - b.x_smooth) / sc) < 1e-8
    np.testing.assert_allclose(a.sigma_smooth, b.sigma_smooth, rtol=1e-7, atol=1e-10)
    assert np.max(np.abs(a.sigma_smooth[130:170, 18] / s.sigma_smooth[130:170, 18])) > 1.5  # N looser there


def test_bad_multipliers_are_refused(short_flight):
    z, valid, x0, P0, Qd = _setup(short_flight, n=50)
    with pytest.raises(ValueError, match="q_local"):
        run_filter_smoother(z, valid, x0, P0, short_flight.model, Qd, R_DIAG, q_local=np.ones((49, 6)))
    with pytest.raises(ValueError, match="q_shares"):
        run_filter_smoother(z, valid, x0, P0, short_flight.model, Qd, R_DIAG, q_local=np.full((50, 6), 2.0))


# --------------------------------------------------------------------------- a short sharp manoeuvre
def _burst_flight(a_n=8.0, a_y=8.0, az_step=0.0, seed=1):
    """40 s at 100 Hz: slow background motion plus, at BURST_T, a 3 Hz yaw-moment and side-force
    burst (Gaussian envelope, 0.3 s) -- a rudder doublet the segment's spectral Q averages away;
    az_step: a +az_step m/s^2 accelerometer step for 1.5 s from t = 10 s.  Returns t, z, truth, rudder."""
    rng = np.random.default_rng(seed)
    dt = 0.01
    t = np.arange(4000) * dt
    model = PlantModel(RLV_INERTIA, RLV_OFFSET, dt)

    def bg(amp):
        f, a, ph = rng.uniform(0.1, 1.0, 4), amp * rng.uniform(0.3, 1, 4) / 2, rng.uniform(0, 2 * np.pi, 4)
        return lambda tt: np.sin(np.outer(np.atleast_1d(tt), 2 * np.pi * f) + ph) @ a

    def burst(tt):
        tt = np.atleast_1d(tt) - BURST_T
        return np.exp(-(tt / 0.3) ** 2) * np.sin(2 * np.pi * 3.0 * tt)

    ang = [bg(0.3) for _ in range(3)]
    acc = [bg(2.0) for _ in range(3)]
    x = np.zeros((t.size, N_STATE))
    for i, s in enumerate(IX_ANG):
        x[:, s] = ang[i](t) + (a_n * burst(t) if i == 2 else 0.0)
    for i, s in enumerate(IX_ACC):
        x[:, s] = acc[i](t) + (-9.0 if i == 2 else 0.0) + (a_y * burst(t) if i == 1 else 0.0)

    def u_of(tt):
        return np.array([ang[0](tt)[0], ang[1](tt)[0], ang[2](tt)[0] + a_n * burst(tt)[0]])

    sol = solve_ivp(lambda tt, w: rate_rhs(w, u_of(tt), model.params), (0, t[-1]), np.zeros(3), method="DOP853",
                    t_eval=t, rtol=1e-10, atol=1e-12, max_step=dt)
    x[:, 0:3] = sol.y.T
    z = measure_many(x, model) + rng.standard_normal((t.size, 6)) * np.asarray(SEED_NOISE_SIGMA)
    z[(t >= 10.0) & (t < 11.5), 2] += az_step
    return t, z, x, 0.1 * burst(t)[:, None]


def _smooth(t, z, rudder, local_q, options=None):
    return smooth_flight_adaptive(t, z, np.ones_like(z, bool), RLV_INERTIA, RLV_OFFSET, controls=rudder,
                                  local_q=local_q, options=options)


@pytest.fixture(scope="module")
def burst():
    return _burst_flight()


def test_a_short_sharp_manoeuvre_is_gated_without_the_local_q_and_followed_with_it(burst):
    t, z, x, rudder = burst
    near = (t > BURST_T - 1.5) & (t < BURST_T + 1.5)
    # the stationary filter with a gate that may hold the r gyro out for as long as it rejects it
    # (with the default gyro_gate_hold_s, r is taken again after 0.1 s and the filter catches up:
    # the side force's error is then 0.34, the local raise's 0.37, but the burst is still condemned)
    stat = _smooth(t, z, rudder, local_q=False, options=EBMOptions(gyro_gate_hold_s=None))
    assert stat.result.gate_flags[near][:, [1, 5]].any()  # ay / r rejected at the burst ...
    assert not stat.result.gate_flags[~near].any()        # ... and only there
    assert len(stat.result.divergence_samples) > 0
    loc = _smooth(t, z, rudder, local_q=True)
    r = loc.result
    assert not r.gate_flags.any() and len(r.divergence_samples) == 0
    (ev,), = loc.local_rounds
    assert ev.manoeuvre and {"r", "ay"} <= set(ev.channels) and {"N", "Y"} <= set(ev.chains)
    assert ev.t0_s < BURST_T < ev.t1_s and "raised locally" in loc.summary()
    # the multiplier is raised over the burst only
    ql = r.q_local
    assert ql[near, 5].max() == 30.0 and np.all(ql[t < BURST_T - 3.0] == 1.0) and np.all(ql[t > BURST_T + 3.0] == 1.0)
    # nothing is condemned any more, and the smoothed side force follows the burst better
    _, cut = smoother_findings(t, {m: r.gate_flags[:, j] for j, m in enumerate(r.meas_names)},
                               np.isin(np.arange(t.size), r.divergence_samples), r.mean_nis_filter, r.nis_band, "s")
    assert not cut.any()
    err = lambda res: np.sqrt(np.mean((res.x_smooth[near, 6] - x[near, 6]) ** 2))  # noqa: E731
    assert err(r) < 0.8 * err(stat.result)


def test_a_single_channel_sensor_step_is_still_gated_and_not_followed():
    t, z, x, rudder = _burst_flight(az_step=25.0)
    loc = _smooth(t, z, rudder * 0 + 0.1 * ((t > 9.5) & (t < 12.0))[:, None], local_q=True)  # controls move too
    r = loc.result
    step = (t >= 10.0) & (t < 11.5)
    assert r.gate_flags[step, 2].sum() > 10  # the step's edges are still rejected on az ...
    for evs in loc.local_rounds:               # ... and no round raised Q over the step
        assert all(not (ev.t0_s < 11.5 and ev.t1_s > 10.0) for ev in evs if ev.manoeuvre)
    assert np.all(r.q_local is None or np.all(r.q_local[(t > 8.0) & (t < 13.5)] == 1.0))
    events = classify(r, rudder)
    step_events = [ev for ev in events if ev.t0_s < 11.5 and ev.t1_s > 10.0]
    assert step_events and all(not ev.manoeuvre and ev.channels[0] == "az" for ev in step_events)


def _events_of(innovation_sq, flagged):
    from types import SimpleNamespace

    n = innovation_sq.shape[0]
    res = SimpleNamespace(t_s=np.arange(n) * 0.01, innovation_sq=innovation_sq, gate_flags=np.zeros((n, 6), bool),
                          divergence_samples=np.asarray(flagged), meas_names=("ax", "ay", "az", "p", "q", "r"))
    return classify(res, None)


def test_the_companion_channels_are_tested_over_the_span_the_raise_covers():
    """An event of one flagged sample (a windowed-NIS excursion) inside a roll manoeuvre: p is out
    around it, a_y only moderately but for the whole second around it -- over the sample alone a_y
    is not significant, over the event +- MARGIN_S it is (unseen minisgs seed 0's doublet).
    And the reverse: a sensor step whose other channels are elevated only at its edge samples is not
    a manoeuvre once the test sees the quiet second around it (c182 seed 0's q step)."""
    rng = np.random.default_rng(3)
    v = rng.chisquare(1, (1000, 6))
    v[470:530, 3] = rng.chisquare(1, 60) * 6.0  # p six times its level over the roll
    v[500, 3] = 40.0                       # and far out at the flagged sample
    v[420:580, 1] = rng.chisquare(1, 160) * 3.0  # a_y three times its level around it
    v[500, 1] = 3.0
    (ev,) = _events_of(v, [500])
    assert ev.manoeuvre and set(ev.channels) == {"p", "ay"}
    w = rng.chisquare(1, (1000, 6))
    w[500:506, 4] = 60.0                   # a q step's edge: six samples far out
    w[500:506, 2] = 6.0                    # a_z elevated at those samples only
    (ev,) = _events_of(w, list(range(500, 506)))
    assert ev.channels == ("q",) and not ev.manoeuvre


def test_companion_and_control_tests():
    rng = np.random.default_rng(0)
    v = rng.chisquare(1, (400, 6))
    assert channels_out(v, 100, 300) == []
    v[150:250, 5] *= 8.0
    v[150:250, 1] *= 2.5
    assert channels_out(v, 100, 300) == [5, 1]  # worst first
    u = np.zeros((400, 2))
    u[:, 1] = 0.3  # a constant surface carries no evidence
    assert controls_moving(u, 100, 300, 50) is False
    u[200:230, 0] = 0.05
    assert controls_moving(u, 100, 300, 50) is True
    assert controls_moving(u, 300, 400, 20) is False
    assert controls_moving(None, 0, 10, 0) is None


def test_the_gate_lifted_over_a_span_compiled_equals_the_reference(short_flight):
    """gate_off lifts the innovation gate over its samples only: a 20-sigma r spike inside the
    span is used, the same spike outside it is gated; compiled and reference agree."""
    z, valid, x0, P0, Qd = _setup(short_flight, n=300)
    z = z.copy()
    z[[100, 200], 5] += 20 * np.sqrt(R_DIAG[5])
    off = np.zeros(300, bool)
    off[190:210] = True
    a = run_filter_smoother(z, valid, x0, P0, short_flight.model, Qd, R_DIAG, 23.93, segment_length=16, gate_off=off)
    b = run_filter_smoother(z, valid, x0, P0, short_flight.model, Qd, R_DIAG, 23.93, use_numba=False, gate_off=off)
    assert a.gated[100, 5] and not a.gated[200, 5] and a.used[200, 5]
    assert not a.gated[off].any()
    np.testing.assert_array_equal(a.gated, b.gated)
    sc = np.max(np.abs(b.x_smooth), axis=0) + 1e-12
    assert np.max(np.abs(a.x_smooth - b.x_smooth) / sc) < 1e-8
    with pytest.raises(ValueError, match="gate_off"):
        run_filter_smoother(z, valid, x0, P0, short_flight.model, Qd, R_DIAG, 23.93, gate_off=off[:10])


def test_the_local_raise_on_the_first_run_replaces_an_escalation_that_left_a_lock_out(monkeypatch):
    """The unseen global5000 seed 0 pattern: r locked out after a rudder doublet reads as
    systematic gating; escalating whole chains leaves the segment locked (1109 condemned); the
    local raise from the unescalated run frees it (123): that one is kept, the escalation undone."""
    from types import SimpleNamespace

    from aerosid.estimation import adaptive
    n = 4000

    def fake_smooth(t_s, z, valid, inertia, offset, z_filled, opt, **kw):
        g = np.zeros((n, 6), bool)
        g[2000:, 5] = True  # r gated to the end, whatever the chains' factors
        return SimpleNamespace(gate_flags=g, divergence_samples=np.zeros(0, int), t_s=np.arange(n) * 0.01,
                               x_smooth=np.zeros((n, 2)), chan_nis_filter=np.ones(6), tuning_history=(),
                               meas_names=("ax", "ay", "az", "p", "q", "r"), scale=opt.q_chain_scale)

    def fake_follow(smooth, res, controls):
        if res.scale[5] != 1.0:  # from the escalated run: nothing freed
            return res, None, ()
        freed = SimpleNamespace(**{**vars(res), "gate_flags": np.zeros((n, 6), bool)})
        freed.gate_flags[2000:2123, 5] = True
        return freed, np.ones((n, 6)), ((SimpleNamespace(summary=lambda: "a manoeuvre"),),)

    monkeypatch.setattr(adaptive, "smooth_flight", fake_smooth)
    monkeypatch.setattr(adaptive, "follow_locally", fake_follow)
    out = adaptive.smooth_flight_adaptive(np.arange(n) * 0.01, np.zeros((n, 6)), np.ones((n, 6), bool),
                                          (1, 1, 1, 0), (0, 0, 0), controls=np.zeros((n, 1)))
    assert adaptive.condemned_samples(out.result) == 123
    assert out.q_chain_scale == (1.0,) * 6
    assert "escalation undone: the local raise on the first run condemns 123 samples, 2000 with it" in out.summary()
