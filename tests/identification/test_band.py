"""The common band of the regression (aerosid.identification.band): closed forms and a
seeded recovery that the smoother-attenuated path could not pass."""
import numpy as np
import pytest

from aerosid.estimation.model import PlantModel, measure, rate_rhs
from aerosid.identification.band import (accel_at_cg, aero_angular_acceleration, band_limited_signals,
                                         finite_runs, low_pass_runs, signal_band_edge_hz)

INERTIA = (2350.6, 2017.5, 3772.9, -4.3)
OFFSET = (0.3, -0.1, -0.2)


def test_euler_inversion_is_exact():
    rng = np.random.default_rng(1)
    prm = PlantModel(INERTIA, OFFSET, 0.01).params
    w = rng.normal(0, 0.5, (50, 3))
    u = rng.normal(0, 2.0, (50, 3))
    wd = np.array([rate_rhs(w[i], u[i], prm) for i in range(50)])
    assert aero_angular_acceleration(w, wd, INERTIA) == pytest.approx(u, abs=1e-12)


def test_lever_arm_inverts_the_measurement_equations():
    """The plant's accelerometer model (method.md §5) read backwards gives the CG force."""
    rng = np.random.default_rng(2)
    model = PlantModel(INERTIA, OFFSET, 0.01)
    prm = model.params
    for _ in range(20):
        x = rng.normal(0, 0.3, 21)
        z = measure(x, model)
        w, u = x[0:3], x[[12, 15, 18]]
        wd = rate_rhs(w, u, prm)
        a_cg = accel_at_cg(z[None, 0:3], w[None], wd[None], OFFSET)[0]
        assert a_cg == pytest.approx(x[[3, 6, 9]], abs=1e-10)


def test_finite_runs():
    ok = np.array([0, 1, 1, 0, 0, 1, 1, 1, 0, 1], bool)
    assert [(r.start, r.stop) for r in finite_runs(ok)] == [(1, 3), (5, 8), (9, 10)]


def test_band_edge_holds_the_signal_power():
    rng = np.random.default_rng(3)
    t = np.arange(6000) * 0.01
    x = 0.05 * np.sin(2 * np.pi * 0.4 * t) + 0.02 * np.sin(2 * np.pi * 1.3 * t) + 0.002 * rng.standard_normal(t.size)
    edge = signal_band_edge_hz(x[:, None], 0.01)
    assert 1.25 <= edge <= 1.45


def test_low_pass_keeps_a_linear_relation_and_does_not_bridge_gaps():
    t = np.arange(3000) * 0.01
    a, d = np.sin(2 * np.pi * 0.5 * t), np.sign(np.sin(2 * np.pi * 0.23 * t))
    y = 2.0 * a - 0.7 * d
    runs = [slice(0, 1400), slice(1600, 3000)]
    Y, A, D = (low_pass_runs(v, 100.0, 1.5, runs) for v in (y, a, d))
    assert np.all(np.isnan(Y[1400:1600]))
    ok = np.isfinite(Y)
    assert Y[ok] == pytest.approx(2.0 * A[ok] - 0.7 * D[ok], abs=1e-12)


def test_pitch_acceleration_slopes_are_unbiased_from_a_noisy_gyro():
    """q' = M_a alpha + M_d delta + M_q q, integrated exactly; the gyro adds white noise.
    Regressing the band-limited q' on the same band's regressors recovers the slopes
    (the point of the common band: a q' with its own, narrower bandwidth would not)."""
    rng = np.random.default_rng(4)
    dt, n = 0.01, 6000
    t = np.arange(n) * dt
    unit = 1.0  # a 3-2-1-1 of 1 s unit, repeated
    seq = np.concatenate([np.full(3, 1.0), np.full(2, -1.0), [1.0], [-1.0], np.zeros(8)])
    delta = 0.05 * seq[((t / unit).astype(int)) % seq.size]
    Ma, Md, Mq, Za = -8.0, -12.0, -2.5, -1.2
    alpha, q = np.zeros(n), np.zeros(n)
    for k in range(n - 1):  # short-period dynamics, RK2
        def f(a, qq, d):
            return qq + Za * a, Ma * a + Md * d + Mq * qq
        k1 = f(alpha[k], q[k], delta[k])
        k2 = f(alpha[k] + dt * k1[0], q[k] + dt * k1[1], delta[k + 1])
        alpha[k + 1] = alpha[k] + 0.5 * dt * (k1[0] + k2[0])
        q[k + 1] = q[k] + 0.5 * dt * (k1[1] + k2[1])
    q_meas = q + np.radians(0.2) * rng.standard_normal(n)
    w = np.column_stack([np.zeros(n), q_meas, np.zeros(n)])
    acc = np.zeros((n, 3)) + 0.01 * rng.standard_normal((n, 3))
    bl = band_limited_signals(t, w, acc, (1.0, 1.0, 1.0, 0.0), (0, 0, 0), band_hz=2.0)
    runs = finite_runs(bl.used)
    A, D = (low_pass_runs(v, 1 / dt, 2.0, runs) for v in (alpha, delta))
    ok = bl.used
    X = np.column_stack([A[ok], D[ok], bl.rates_rad_s[ok, 1]])
    est = np.linalg.lstsq(X, bl.ang_accel_rad_s2[ok, 1], rcond=None)[0]
    assert est == pytest.approx([Ma, Md, Mq], rel=0.02)
    # the same regression with a q' that only went through a narrower filter (what a
    # smoother tuned too tight gives) is biased beyond that: the test can fail
    narrow = low_pass_runs(bl.ang_accel_rad_s2[:, 1], 1 / dt, 0.7, runs)
    est_bad = np.linalg.lstsq(X, narrow[ok], rcond=None)[0]
    assert abs(est_bad[1] / Md - 1) > 0.05


def test_dilate_and_merge():
    from aerosid.estimation.findings import dilate, merge_close

    m = np.zeros(10, bool)
    m[4] = True
    assert dilate(m, 2).nonzero()[0].tolist() == [2, 3, 4, 5, 6]
    assert dilate(m, 50).all()  # a margin longer than the record
    m[8] = True
    assert merge_close(m, 4).nonzero()[0].tolist() == [4, 5, 6, 7, 8]
    assert merge_close(m, 3).nonzero()[0].tolist() == [4, 8]


def test_bridge_spikes_replaces_isolated_spikes_only():
    from aerosid.identification.band import bridge_spikes

    rng = np.random.default_rng(5)
    t = np.arange(4000) * 0.01
    truth = np.sin(2 * np.pi * 0.5 * t)
    x = truth + 0.01 * rng.standard_normal(t.size)
    x[[500, 1500, 1501]] += [0.2, -0.15, -0.15]  # a spike and a two-sample spike
    x[3000:3050] += 0.3  # a 0.5 s step: a fault for the findings, not a spike
    y = bridge_spikes(x[:, None], (x - truth)[:, None])[:, 0]
    assert abs(y[500] - truth[500]) < 0.03 and abs(y[1500] - truth[1500]) < 0.03
    assert np.array_equal(y[3000:3050], x[3000:3050])
    assert np.count_nonzero(y != x) == 3


def test_a_cut_span_costs_its_samples_not_the_segments_band():
    """The band edge comes from the longest run; a condemned span (the smoother's `suspect`) in
    the fast manoeuvre used to split that run so that the longest one held only a slow doublet,
    and the whole segment was low-passed at the slow edge.  The edge is the uncut segment's."""
    import pandas as pd

    from aerosid.identification.flight_data import BAND_IMU, _band_signals
    from aerosid.vehicles.vehicle import load_vehicle

    rng = np.random.default_rng(21)
    dt = 0.01
    t = np.arange(4000) * dt
    fast = np.where((t > 8) & (t < 12), np.sin(2 * np.pi * 2.5 * t), 0.0) * 0.1       # a 2.5 Hz pitch manoeuvre
    slow = np.where((t > 15) & (t < 35), np.sin(2 * np.pi * 0.4 * t), 0.0) * 0.1      # a 0.4 Hz doublet
    q = fast + slow
    true = {"ax_m_s2": np.zeros_like(t), "ay_m_s2": np.zeros_like(t), "az_m_s2": -9.81 + 0 * t,
            "p_rad_s": slow, "q_rad_s": q, "r_rad_s": 0.5 * slow}
    measured = pd.DataFrame({f"{c}_clean": true[c] + rng.normal(0, 0.002, t.size) for c in BAND_IMU})
    smoothed = pd.DataFrame({c: true[c] for c in ("p_rad_s", "q_rad_s", "r_rad_s")})
    for c, k in (("X1_m_s2", "ax_m_s2"), ("Y1_m_s2", "ay_m_s2"), ("Z1_m_s2", "az_m_s2")):
        smoothed[c] = true[k]
    ok = np.ones(t.size, bool)
    vehicle = load_vehicle("c172x")
    smoothed["suspect"] = False
    whole, _, _, _ = _band_signals(t, measured, smoothed, vehicle, ok, "seg00")
    # two condemned spans at the manoeuvre's ends: the longest run left holds the doublet only
    smoothed["suspect"] = ((t > 8.5) & (t < 8.7)) | ((t > 11.5) & (t < 11.7))
    cut, keep, _, _ = _band_signals(t, measured, smoothed, vehicle, ok, "seg00")
    assert whole.band_hz > 2.0 and whole.band_source == "flight"
    assert cut.band_hz == whole.band_hz and cut.band_source == "flight"
    assert not keep[(t > 8.5) & (t < 8.7)].any() and keep[(t > 15) & (t < 30)].all()
    from aerosid.identification.band import signal_band_edge_hz
    longest = (t > 12.2) & (t < 39.9)  # what the edge used to be computed on
    assert signal_band_edge_hz(measured.loc[longest, ["p_rad_s_clean", "q_rad_s_clean", "r_rad_s_clean"]]
                               .to_numpy(), dt) < 1.0


def test_a_span_condemned_on_a_sensor_that_feeds_one_channel_is_kept_for_the_others():
    """With vanes a_z feeds only C_N (kept_sensors; a_x only C_A, a_y only C_Y; with angles
    inverted from the force database a_y and a_z feed every channel).  Its condemned span (the
    smoother's suspect_az) is marked for C_N with the band margin and splits no run; the same
    span condemned for every channel (suspect) is cut."""
    import pandas as pd

    from aerosid.estimation.findings import kept_sensors
    from aerosid.identification.flight_data import BAND_IMU, MAX_MARGIN_S, _band_signals
    from aerosid.vehicles.vehicle import load_vehicle

    vehicle = load_vehicle("c172x")
    assert kept_sensors(vehicle.air_data_source) == {"ax": "CA", "ay": "CY", "az": "CN"}
    assert kept_sensors("database") == {"ax": "CA"}
    rng = np.random.default_rng(3)
    t = np.arange(3000) * 0.01
    q = 0.1 * np.sin(2 * np.pi * 0.8 * t)
    true = {"ax_m_s2": 0 * t, "ay_m_s2": 0 * t, "az_m_s2": -9.81 + 0 * t, "p_rad_s": 0.5 * q, "q_rad_s": q,
            "r_rad_s": 0.2 * q}
    measured = pd.DataFrame({f"{c}_clean": true[c] + rng.normal(0, 0.002, t.size) for c in BAND_IMU})
    smoothed = pd.DataFrame({c: true[c] for c in ("p_rad_s", "q_rad_s", "r_rad_s")})
    for c, k in (("X1_m_s2", "ax_m_s2"), ("Y1_m_s2", "ay_m_s2"), ("Z1_m_s2", "az_m_s2")):
        smoothed[c] = true[k]
    span = (t > 12.0) & (t < 13.0)
    ok = np.ones(t.size, bool)
    smoothed["suspect"] = False
    _, whole, _, _ = _band_signals(t, measured, smoothed, vehicle, ok, "seg00")
    smoothed["suspect_az"] = span
    bl, keep, _, marked = _band_signals(t, measured, smoothed, vehicle, ok, "seg00")
    assert keep[span].all() and np.array_equal(keep, whole)
    pad = min(1.0 / bl.band_hz, MAX_MARGIN_S) + 0.01
    margin = (t > 12.0 - pad) & (t < 13.0 + pad)
    assert marked["CN"][span].all() and not marked["CN"][~margin].any()
    assert not marked["CY"].any() and not marked["CA"].any()
    smoothed["suspect"], smoothed["suspect_az"] = span, False
    _, keep, _, marked = _band_signals(t, measured, smoothed, vehicle, ok, "seg00")
    assert not keep[span].any() and not any(m.any() for m in marked.values())
