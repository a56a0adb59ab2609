"""EKF step vs filterpy, MBF vs RTS, compiled vs plain numpy, gate, flagged samples."""
import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter, KalmanFilter

from aerosid.estimation import (PlantModel, discrete_process_noise, ekf_predict, ekf_update, mbf_smooth, measure,
                                measurement_jacobian, propagate, run_filter_smoother)
from aerosid.estimation.synthetic import SEED_NOISE_SIGMA

from .conftest import col_rel_err

MODEL = PlantModel((150.0, 2500.0, 2550.0, 40.0), (1.1, -0.2, 0.3), 0.01)
Q_CHAIN = np.array([4e5, 4e5, 8e5, 2e4, 2e4, 2e4])
R_DIAG = np.asarray(SEED_NOISE_SIGMA) ** 2


def _prior(seed=0):
    rng = np.random.default_rng(seed)
    x = rng.normal(0, 0.5, 21)
    x[0:3] = rng.normal(0, 0.3, 3)
    A = rng.normal(0, 1, (21, 21))
    P = A @ A.T / 21 + np.diag(rng.uniform(0.1, 2.0, 21))
    return x, P


def _filterpy_ekf(x, P, Qd, R):
    ekf = ExtendedKalmanFilter(21, 6)
    ekf.x = x.reshape(21, 1).copy()
    ekf.P = P.copy()
    ekf.Q = Qd
    ekf.R = np.diag(R)

    def predict_x(u=0):
        ekf.x = propagate(ekf.x.ravel(), MODEL)[0].reshape(21, 1)

    ekf.predict_x = predict_x
    return ekf


def _filterpy_step(ekf, z):
    ekf.F = propagate(ekf.x.ravel(), MODEL)[1]
    ekf.predict()
    ekf.update(z.reshape(6, 1), lambda v: measurement_jacobian(v.ravel(), MODEL),
               lambda v: measure(v.ravel(), MODEL).reshape(6, 1))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ekf_step_equals_filterpy(seed):
    x, P = _prior(seed)
    Qd = discrete_process_noise(Q_CHAIN, MODEL)
    z = measure(propagate(x, MODEL)[0], MODEL) + np.random.default_rng(seed).normal(0, 1, 6) * np.sqrt(R_DIAG)
    ekf = _filterpy_ekf(x, P, Qd, R_DIAG)
    _filterpy_step(ekf, z)
    xp, Pp, _ = ekf_predict(x, P, MODEL, Qd)
    up = ekf_update(xp, Pp, z, np.ones(6, bool), MODEL, R_DIAG)
    scale_x = np.abs(ekf.x.ravel()) + 1.0
    assert np.max(np.abs(up.x - ekf.x.ravel()) / scale_x) < 1e-10
    assert np.max(np.abs(up.P - ekf.P)) / np.max(np.abs(ekf.P)) < 1e-10
    np.testing.assert_allclose(up.K, ekf.K, rtol=1e-9, atol=1e-12 * np.abs(ekf.K).max())
    assert up.nis == pytest.approx(float((ekf.y.T @ np.linalg.solve(ekf.S, ekf.y)).item()), rel=1e-10)


def test_compiled_two_steps_equal_filterpy():
    """The numba kernel (update at 0, then predict + update at 1) against filterpy."""
    x, P = _prior(3)
    Qd = discrete_process_noise(Q_CHAIN, MODEL)
    rng = np.random.default_rng(3)
    z = np.stack([measure(x, MODEL), measure(propagate(x, MODEL)[0], MODEL)]) + rng.normal(0, 1, (2, 6)) * np.sqrt(R_DIAG)
    ekf = _filterpy_ekf(x, P, Qd, R_DIAG)
    ekf.update(z[0].reshape(6, 1), lambda v: measurement_jacobian(v.ravel(), MODEL),
               lambda v: measure(v.ravel(), MODEL).reshape(6, 1))
    x0f, P0f = ekf.x.ravel().copy(), ekf.P.copy()
    _filterpy_step(ekf, z[1])
    run = run_filter_smoother(z, np.ones((2, 6), bool), x, P, MODEL, Qd, R_DIAG)
    for k, (xr, Pr) in enumerate([(x0f, P0f), (ekf.x.ravel(), ekf.P)]):
        assert np.max(np.abs(run.x_filter[k] - xr) / (np.abs(xr) + 1.0)) < 1e-10
        np.testing.assert_allclose(run.sigma_filter[k], np.sqrt(np.diag(Pr)), rtol=1e-10)


def _linear_problem(n=6, m=3, N=200, seed=0):
    rng = np.random.default_rng(seed)
    F = np.eye(n) + 0.05 * rng.normal(size=(n, n))
    F /= max(1.0, np.max(np.abs(np.linalg.eigvals(F))) * 1.01)
    H = rng.normal(size=(m, n))
    Aq = rng.normal(size=(n, n)) * 0.1
    Q = Aq @ Aq.T + 1e-3 * np.eye(n)
    R = np.diag(rng.uniform(0.2, 1.0, m))
    x = rng.normal(size=n)
    zs = []
    for _ in range(N):
        x = F @ x + rng.multivariate_normal(np.zeros(n), Q)
        zs.append(H @ x + rng.multivariate_normal(np.zeros(m), R))
    return F, H, Q, R, np.array(zs)


@pytest.mark.parametrize("seed", [0, 1])
def test_mbf_equals_filterpy_rts_on_linear_gaussian_model(seed):
    F, H, Q, R, zs = _linear_problem(seed=seed)
    n, m = F.shape[0], H.shape[0]
    kf = KalmanFilter(n, m)
    kf.F, kf.H, kf.Q, kf.R = F, H, Q, R
    kf.x = np.zeros((n, 1))
    kf.P = np.eye(n) * 5.0
    xs, Ps, vs, Ss, Ks = [], [], [], [], []
    for k, z in enumerate(zs):
        if k > 0:
            kf.predict()
        kf.update(z.reshape(m, 1))
        xs.append(kf.x.ravel().copy())
        Ps.append(kf.P.copy())
        vs.append(kf.y.ravel().copy())
        Ss.append(kf.S.copy())
        Ks.append(kf.K.copy())
    xs, Ps = np.array(xs), np.array(Ps)
    N = len(zs)
    xr, Pr, _, _ = kf.rts_smoother(xs.reshape(N, n, 1), Ps, Fs=[F] * N, Qs=[Q] * N)
    sm = mbf_smooth(xs, Ps, np.array([F] * N), [H] * N, vs, Ss, Ks)
    assert np.max(np.abs(sm.x_smooth - xr.reshape(N, n))) / np.max(np.abs(xr)) < 1e-9
    assert np.max(np.abs(sm.P_smooth - Pr)) / np.max(np.abs(Pr)) < 1e-9
    assert "MBF smoother" in sm.summary()


@pytest.mark.parametrize("p0_big, tol", [(1e2, 1e-9), (1e6, 1e-7)])
def test_compiled_filter_smoother_equals_filterpy_kf_rts_on_linear_plant(p0_big, tol):
    """Ixx = Iyy = Izz, Ixz = 0 and the accelerometer at the CG make the 21-state plant
    linear (no gyroscopic or lever-arm terms): the compiled EKF + MBF must then equal
    filterpy's KalmanFilter + rts_smoother."""
    model = PlantModel((100.0, 100.0, 100.0, 0.0), (0.0, 0.0, 0.0), 0.01)
    N = 3000
    rng = np.random.default_rng(7)
    Qd = discrete_process_noise(np.array([50.0, 60.0, 70.0, 5.0, 6.0, 7.0]), model)
    R = np.array([0.5, 0.6, 0.7, 0.01, 0.02, 0.03]) ** 2
    x_true = np.zeros(21)
    Phi = propagate(x_true, model)[1]
    H = measurement_jacobian(x_true, model)
    zs = []
    w, V = np.linalg.eigh(Qd)
    for _ in range(N):
        x_true = Phi @ x_true + V @ (np.sqrt(np.maximum(w, 0)) * rng.normal(size=21))
        zs.append(H @ x_true + rng.normal(size=6) * np.sqrt(R))
    zs = np.array(zs)
    x0 = np.zeros(21)
    # p0_big = 1e6 is badly scaled like a parabola-fit P0 (rounding then costs digits; a
    # long run with it exposed an asymmetry drift in Lambda once, an O(1) error)
    P0 = np.diag(np.r_[[0.1] * 3, [1.0, 10.0, p0_big] * 3, [0.5, 5.0, p0_big / 10] * 3])
    kf = KalmanFilter(21, 6)
    kf.F, kf.H, kf.Q, kf.R = Phi, H, Qd, np.diag(R)
    kf.x, kf.P = x0.reshape(21, 1).copy(), P0.copy()
    xs, Ps = [], []
    for k in range(N):
        if k > 0:
            kf.predict()
        kf.update(zs[k].reshape(6, 1))
        xs.append(kf.x.ravel().copy())
        Ps.append(kf.P.copy())
    xs, Ps = np.array(xs), np.array(Ps)
    xr, Pr, _, _ = kf.rts_smoother(xs.reshape(N, 21, 1), Ps, Fs=[Phi] * N, Qs=[Qd] * N)
    run = run_filter_smoother(zs, np.ones((N, 6), bool), x0, P0, model, Qd, R, segment_length=32)
    assert col_rel_err(run.x_filter, xs) < tol / 10
    assert col_rel_err(run.x_smooth, xr.reshape(N, 21)) < tol
    sig_r = np.sqrt(np.diagonal(Pr, axis1=1, axis2=2))
    assert col_rel_err(run.sigma_smooth, sig_r) < tol


@pytest.fixture(scope="module")
def problem(short_flight):
    """Short synthetic flight with dropouts, a partial dropout and two outliers."""
    sf = short_flight
    z = sf.z.copy()
    valid = np.ones_like(z, bool)
    valid[100:115] = False            # all channels out
    valid[200:210, 1] = False         # ay only
    z[250, 0] += 25.0                 # outlier on ax (~30 sigma)
    z[300, 4] += np.deg2rad(40.0)     # outlier on the q gyro (20 sigma)
    z[~valid] = np.nan
    Qd = discrete_process_noise(Q_CHAIN, sf.model)
    x0 = sf.x_true[0] + 0.01
    P0 = np.diag(np.r_[[1e-3] * 3, [1.0, 10.0, 100.0] * 3, [0.1, 1.0, 10.0] * 3])
    return sf, z, valid, Qd, x0, P0


def test_compiled_equals_numpy_reference_with_gaps_and_gate(problem):
    sf, z, valid, Qd, x0, P0 = problem
    a = run_filter_smoother(z, valid, x0, P0, sf.model, Qd, R_DIAG, 23.93, segment_length=16)
    b = run_filter_smoother(z, valid, x0, P0, sf.model, Qd, R_DIAG, 23.93, use_numba=False)
    np.testing.assert_array_equal(a.used, b.used)
    np.testing.assert_array_equal(a.gated, b.gated)
    np.testing.assert_array_equal(a.dof, b.dof)
    for f in ("x_filter", "sigma_filter", "x_smooth", "sigma_smooth", "angacc", "angacc_sigma"):
        assert col_rel_err(getattr(a, f), getattr(b, f)) < 1e-8, f
    for f in ("nis_filter", "nis_smoother"):
        A, B = getattr(a, f), getattr(b, f)
        np.testing.assert_array_equal(np.isnan(A), np.isnan(B))
        np.testing.assert_allclose(A, B, rtol=1e-8)
    for f in ("chan_nis_filter", "chan_nis_smoother", "em_R"):
        np.testing.assert_allclose(getattr(a, f), getattr(b, f), rtol=1e-8)


def test_gate_flags_outliers_and_flagged_samples_are_not_used(problem):
    sf, z, valid, Qd, x0, P0 = problem
    run = run_filter_smoother(z, valid, x0, P0, sf.model, Qd, R_DIAG, 23.93)
    assert run.gated[250, 0] and run.gated[300, 4]
    assert run.gated.sum() == 2
    assert not (run.used & ~valid).any()
    assert (run.dof[100:115] == 0).all() and np.isnan(run.nis_filter[100:115]).all()
    assert (run.dof[200:210] == 5).all()
    # at a sample without update the filtered state is the one-step prediction
    xp, _ = propagate(run.x_filter[104], sf.model)
    np.testing.assert_allclose(run.x_filter[105], xp, rtol=1e-12, atol=1e-12)
    # without the gate the outlier is swallowed and drags the estimate
    nog = run_filter_smoother(z, valid, x0, P0, sf.model, Qd, R_DIAG, np.inf)
    assert not nog.gated.any()
    assert abs(nog.x_filter[250, 3] - sf.x_true[250, 3]) > 3 * abs(run.x_filter[250, 3] - sf.x_true[250, 3])


def _longest_run(flags):
    best = n = 0
    for f in flags:
        n = n + 1 if f else 0
        best = max(best, n)
    return best


@pytest.fixture(scope="module")
def gyro_step(short_flight):
    """The short flight with a +40 sigma (1.4 rad/s) step on the q gyro over samples 150..249."""
    sf = short_flight
    z = sf.z.copy()
    z[150:250, 4] += 40 * np.sqrt(R_DIAG[4])
    x0 = sf.x_true[0] + 0.01
    P0 = np.diag(np.r_[[1e-3] * 3, [1.0, 10.0, 100.0] * 3, [0.1, 1.0, 10.0] * 3])
    return sf, z, np.ones_like(z, bool), discrete_process_noise(Q_CHAIN, sf.model), x0, P0


def test_a_gyro_gated_without_a_limit_locks_the_filter_out_and_a_hold_lets_it_back(gyro_step):
    """Gated, the q gyro's state is the M chain's extrapolation: it runs off and the gate then
    rejects q for good, to the end of the record.  With gate_hold, q is gated for at most
    that many samples in a row, taken once, and the filter follows the measurement again."""
    sf, z, valid, Qd, x0, P0 = gyro_step
    q_true = sf.x_true[:, 1]
    free = run_filter_smoother(z, valid, x0, P0, sf.model, Qd, R_DIAG, 23.93)
    assert free.gated[-1, 4] and free.gated[150:, 4].mean() > 0.95        # locked out to the end
    assert np.max(np.abs(free.x_smooth[260:, 1] - q_true[260:])) > 10.0  # the state has run off
    held = run_filter_smoother(z, valid, x0, P0, sf.model, Qd, R_DIAG, 23.93, gate_hold=[0, 0, 0, 5, 5, 5])
    assert _longest_run(held.gated[:, 4]) == 5 and not held.gated[300:, 4].any()
    assert np.max(np.abs(held.x_smooth[260:, 1] - q_true[260:])) < 20 * np.sqrt(R_DIAG[4])
    # the hold is per channel: an a_z step is rejected for longer than a gyro hold allows
    za = z.copy()
    za[:, 4] = sf.z[:, 4]
    za[150:250, 2] += 30 * np.sqrt(R_DIAG[2])
    acc = run_filter_smoother(za, valid, x0, P0, sf.model, Qd, R_DIAG, 23.93, gate_hold=[0, 0, 0, 5, 5, 5])
    assert _longest_run(acc.gated[:, 2]) > 20
    acc = run_filter_smoother(za, valid, x0, P0, sf.model, Qd, R_DIAG, 23.93, gate_hold=[5] * 6)
    assert _longest_run(acc.gated[:, 2]) == 5


def test_the_gate_hold_compiled_equals_the_reference(gyro_step):
    sf, z, valid, Qd, x0, P0 = gyro_step
    hold = [0, 0, 0, 5, 5, 5]
    a = run_filter_smoother(z, valid, x0, P0, sf.model, Qd, R_DIAG, 23.93, segment_length=16, gate_hold=hold)
    b = run_filter_smoother(z, valid, x0, P0, sf.model, Qd, R_DIAG, 23.93, use_numba=False, gate_hold=hold)
    assert a.gated[:, 4].sum() > 5
    np.testing.assert_array_equal(a.gated, b.gated)
    np.testing.assert_array_equal(a.used, b.used)
    for f in ("x_filter", "sigma_filter", "x_smooth", "sigma_smooth"):
        assert col_rel_err(getattr(a, f), getattr(b, f)) < 1e-8, f
    with pytest.raises(ValueError, match="gate_hold"):
        run_filter_smoother(z, valid, x0, P0, sf.model, Qd, R_DIAG, 23.93, gate_hold=[5, 5])


def test_smoothed_sigma_not_above_filtered_and_segment_length_invariance(problem):
    sf, z, valid, Qd, x0, P0 = problem
    a = run_filter_smoother(z, valid, x0, P0, sf.model, Qd, R_DIAG, 23.93, segment_length=64)
    b = run_filter_smoother(z, valid, x0, P0, sf.model, Qd, R_DIAG, 23.93, segment_length=7)
    assert np.all(a.sigma_smooth <= a.sigma_filter * (1 + 1e-9))
    # last sample: smoother = filter
    np.testing.assert_allclose(a.x_smooth[-1], a.x_filter[-1], rtol=1e-12)
    np.testing.assert_allclose(a.sigma_smooth[-1], a.sigma_filter[-1], rtol=1e-12)
    # checkpoint recomputation is bit-identical whatever the segment length
    np.testing.assert_array_equal(a.x_smooth, b.x_smooth)
    np.testing.assert_array_equal(a.sigma_smooth, b.sigma_smooth)
    assert a.bad_variances == 0


def test_mbf_equals_rts_with_nonlinear_mean_on_the_ekf(short_flight):
    """On the nonlinear plant the MBF equals the RTS recursion written for an EKF
    (mean predicted with f(x), covariance with Phi), and the compiled kernel equals both."""
    from aerosid.estimation import initial_state, run_reference
    sf = short_flight
    valid = np.ones_like(sf.z, bool)
    Qd = discrete_process_noise(Q_CHAIN, sf.model)
    x0, P0, _ = initial_state(sf.t_s, sf.z, valid, sf.model, sf.noise_sigma)
    ref = run_reference(sf.z, valid, x0, P0, sf.model, Qd, R_DIAG)
    xs = ref.x_filter.copy()
    Ps = ref.P_filter.copy()
    for k in range(len(xs) - 2, -1, -1):
        xp, F = propagate(ref.x_filter[k], sf.model)
        Pp = F @ ref.P_filter[k] @ F.T + Qd
        G = np.linalg.solve(Pp, F @ ref.P_filter[k]).T
        xs[k] = ref.x_filter[k] + G @ (xs[k + 1] - xp)
        Ps[k] = ref.P_filter[k] + G @ (Ps[k + 1] - Pp) @ G.T
    assert col_rel_err(ref.x_smooth, xs) < 1e-9
    assert np.max(np.abs(ref.P_smooth - Ps)) / np.max(np.abs(Ps)) < 1e-9
    fast = run_filter_smoother(sf.z, valid, x0, P0, sf.model, Qd, R_DIAG)
    assert col_rel_err(fast.x_smooth, xs) < 1e-9


@pytest.mark.parametrize("use_numba", [True, False])
def test_a_covariance_that_is_not_positive_definite_is_a_named_breakdown(use_numba):
    """c182 thinned to 5 Hz failed its segment with the kernel's bare "division by zero"; a
    breakdown of the covariance is now FilterBreakdown naming the sample interval (here forced
    by a zero prior, process and measurement covariance: a singular innovation covariance), and
    below 20 Hz it names the coarse sampling."""
    from aerosid.estimation.core_run import FilterBreakdown

    x, _ = _prior(4)
    z = np.stack([measure(x, MODEL)] * 3)
    zero = np.zeros((21, 21))
    for model, coarse in ((MODEL, False), (PlantModel(MODEL.inertia_kg_m2, MODEL.sensor_offset_m, 0.2), True)):
        with pytest.raises(FilterBreakdown) as err:
            run_filter_smoother(z, np.ones((3, 6), bool), x, zero, model, zero, np.zeros(6), use_numba=use_numba)
        assert f"sample interval of {model.dt_s:g} s" in str(err.value)
        assert ("below 20 Hz" in str(err.value)) == coarse
