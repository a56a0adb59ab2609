"""The instrumental-variable fit (aerosid.identification.instrumental): it equals least squares
when the regressors lie in the instruments' span (closed form), recovers a slope least squares
gets wrong when the regressor shares a disturbance with the equation error (a gust that drives
the rate it also biases), with intervals that cover; the instruments restart in every segment;
the vehicle file's [estimation] turbulent_air switches identify to it."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.signal

from aerosid.identification.instrumental import control_instruments, instrumental_fit, iv_estimate
from aerosid.identification.regression import fit_linear

THETA = np.array([0.01, -0.5, 0.2])  # C_l = C_0 + C_p p + C_delta delta


def _gusty_flight(seed: int, n: int = 6000, dt: float = 0.02, gust: float = 1.0) -> pd.DataFrame:
    """A roll axis in turbulence: p follows the aileron and a coloured gust g; the moment reads
    the rate relative to the air, p - g, so the equation error -C_p g correlates with p."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    delta = 0.05 * np.sign(np.sin(2 * np.pi * t / 4.0))  # a square wave of 4 s period on the aileron
    b, a = scipy.signal.butter(1, 0.5, fs=1 / dt)
    g = scipy.signal.lfilter(b, a, rng.standard_normal(n))
    g *= gust * 0.08 / g.std()  # the rolling gust [rad/s]: a third of p's spread
    p = np.zeros(n)
    for k in range(1, n):  # a first-order roll mode driven by the aileron and by the gust's moment
        p[k] = p[k - 1] + dt * (-2.0 * (p[k - 1] - g[k - 1]) + 10.0 * delta[k - 1])
    cl = THETA[0] + THETA[1] * (p - g) + THETA[2] * delta + 1e-4 * rng.standard_normal(n)
    return pd.DataFrame({"t_s": t, "flight": "f", "segment": 0, "delta_r_rad": delta, "p": p, "Cl": cl})


def _design(fd: pd.DataFrame) -> np.ndarray:
    return np.column_stack([np.ones(len(fd)), fd["p"].to_numpy(), fd["delta_r_rad"].to_numpy()])


def test_equals_least_squares_when_the_regressors_are_instruments():
    rng = np.random.default_rng(0)
    Z = np.column_stack([np.ones(500), rng.standard_normal((500, 4))])
    X = Z[:, :3] @ np.array([[1.0, 0.0, 0.0], [0.5, 1.0, 0.0], [0.0, 0.3, 1.0]])
    y = X @ np.array([1.0, 2.0, -1.0]) + 0.1 * rng.standard_normal(500)
    theta, cov, r2 = iv_estimate(y, X, Z)
    np.testing.assert_allclose(theta, np.linalg.lstsq(X, y, rcond=None)[0], rtol=1e-10)
    np.testing.assert_allclose(r2, 1.0, atol=1e-12)
    assert np.all(np.diag(cov) > 0)


def test_recovers_the_slope_least_squares_gets_wrong_in_a_gust():
    ls_err, iv_err, iv_se, covered, ls_off = [], [], [], 0, 0
    for seed in range(8):
        fd = _gusty_flight(seed)
        X, y = _design(fd), fd["Cl"].to_numpy()
        ls = fit_linear(y, X, names=["C_0", "C_p", "C_delta"])
        iv = instrumental_fit(ls, y, X, control_instruments(fd))
        assert "instrumental variables" in iv.warnings[-1]
        ls_err.append(ls.estimate[1] - THETA[1])
        iv_err.append(iv.estimate[1] - THETA[1])
        iv_se.append(iv.std_error[1])
        # the gust's moment drives p the way the damping resists it: least squares sees less damping
        ls_off += ls.estimate[1] - THETA[1] > 3 * ls.std_error[1]
        covered += abs(iv.estimate[1] - THETA[1]) <= 1.96 * iv.std_error[1]
    assert ls_off >= 6 and np.mean(ls_err) > 0.1 * abs(THETA[1])
    assert covered >= 7
    assert abs(np.mean(iv_err)) < 2 * np.mean(iv_se) / np.sqrt(8)  # no bias left at the runs' precision
    assert 0.6 < np.std(iv_err, ddof=1) / np.mean(iv_se) < 1.6  # the sigma is the scatter's, not a multiple
    assert "2SLS" in iv.summary()  # the report names the method


def test_the_bias_check_finds_no_bias_in_an_instrumental_fit_without_sensor_noise():
    """The check's world for an instrumental fit is the flight's own response: with no sensor noise
    to draw, every refit returns the reported estimate (a world built on the least-squares residual
    would count the instrumental-minus-least-squares difference as bias)."""
    from aerosid.identification.bias_check import estimator_bias

    fd = _gusty_flight(0)
    Z = control_instruments(fd)

    def regressors(frame):
        return {"Cl": _design(frame)}

    def refit(frame):
        X, y = _design(frame), frame["Cl"].to_numpy()
        return {"Cl": instrumental_fit(fit_linear(y, X, names=["C_0", "C_p", "C_delta"]), y, X, Z)}

    fits = refit(fd)
    check = estimator_bias(fd, regressors, fits, refit, None, None, pairs=2)["Cl"]
    np.testing.assert_allclose(check.bias, 0.0, atol=1e-12)


def test_instruments_that_do_not_span_the_regressors_keep_least_squares_with_a_warning():
    fd = _gusty_flight(1, n=800)
    fd["delta_r_rad"] = 0.02  # a held aileron: the instruments are the constant alone
    X = np.column_stack([np.ones(len(fd)), fd["p"].to_numpy()])
    y = fd["Cl"].to_numpy()
    ls = fit_linear(y, X, names=["C_0", "C_p"])
    out = instrumental_fit(ls, y, X, control_instruments(fd))
    np.testing.assert_array_equal(out.estimate, ls.estimate)
    assert out.method == ls.method and "not possible" in out.warnings[-1] and "span 1 directions" in out.warnings[-1]


def test_instruments_restart_in_every_segment():
    t = np.arange(200) * 0.02
    fd = pd.DataFrame({"t_s": np.r_[t, t + 10], "flight": "f", "segment": np.repeat([0, 1], 200),
                       "delta_p_rad": np.r_[np.full(200, 0.1), np.full(200, 0.3)]})
    Z = control_instruments(fd)
    assert Z.shape == (400, 1 + 4)  # a constant, the control and its three lags
    np.testing.assert_allclose(Z[:, 2:], 0.0, atol=1e-15)  # a held control: no lagged step in either segment
    fd.loc[250:, "delta_p_rad"] += 0.05
    lagged = control_instruments(fd)[:, 2:]
    assert np.all(lagged[:250] == 0) and np.all(lagged[251:] > 0)


def test_too_few_instruments_is_refused():
    with pytest.raises(ValueError, match="instruments span 2 directions for 3"):
        iv_estimate(np.zeros(10), np.ones((10, 3)), np.random.default_rng(0).standard_normal((10, 2)))
    with pytest.raises(ValueError, match="instruments span 1 directions"):  # rank, not the column count
        iv_estimate(np.zeros(10), np.ones((10, 2)), np.ones((10, 4)))


def test_a_regressor_the_instruments_do_not_explain_is_named():
    rng = np.random.default_rng(3)
    Z = np.column_stack([np.ones(300), rng.standard_normal((300, 3))])
    X = np.column_stack([np.ones(300), Z[:, 1], rng.standard_normal(300)])  # the last: no instrument moves it
    X[:, 2] -= Z @ np.linalg.lstsq(Z, X[:, 2], rcond=None)[0]
    with pytest.raises(ValueError, match="regressor of C_beta"):
        iv_estimate(X @ np.ones(3), X, Z, names=("C_0", "C_a", "C_beta"))
    Zbad = Z.copy()
    Zbad[5, 2] = np.nan
    with pytest.raises(ValueError, match="not finite"):
        iv_estimate(X @ np.ones(3), X, Zbad)


def test_segments_without_a_flight_column_restart_too():
    t = np.arange(100) * 0.02
    fd = pd.DataFrame({"t_s": np.r_[t, t], "segment": np.repeat([0, 1], 100),
                       "delta_p_rad": np.r_[np.zeros(100), np.full(100, 0.1)]})
    np.testing.assert_allclose(control_instruments(fd)[:, 2:], 0.0, atol=1e-15)


def test_instruments_restart_after_a_gap_in_time():
    t = np.r_[np.arange(100), np.arange(150, 250)] * 0.02
    fd = pd.DataFrame({"t_s": t, "flight": "f", "segment": 0, "delta_y_rad": np.r_[np.zeros(100), np.full(100, 0.1)]})
    lagged = control_instruments(fd)[:, 2:]
    np.testing.assert_allclose(lagged, 0.0, atol=1e-15)  # the step is the second stretch's start, not a step


def test_the_vehicle_file_switches_identify_to_it(tmp_path, reference_run):
    import shutil

    from aerosid.identification.identify import identify
    from aerosid.vehicles.vehicle import load_vehicle

    data = Path(__file__).parents[2] / "aerosid" / "data" / "seed-rlv"
    shutil.copytree(data, tmp_path / "rlv")
    path = tmp_path / "rlv" / "vehicle.toml"
    path.write_text(path.read_text() + "\n[estimation]\nturbulent_air = true\n")
    calm, turbulent = load_vehicle("seed-rlv"), load_vehicle(path)
    assert calm.turbulent_air is False and turbulent.turbulent_air is True
    fd = reference_run.flight_data
    off = identify(fd, calm, bias_pairs=0)
    on = identify(fd, turbulent, bias_pairs=0)
    explicit = identify(fd, calm, bias_pairs=0, instrumental=True)
    for ch in on.fits:
        if ch in on.identities:  # alpha, beta are inverted from these: left as they are
            np.testing.assert_array_equal(on.fits[ch].estimate, off.fits[ch].estimate)
            continue
        assert any("instrumental variables" in w for w in on.fits[ch].warnings), ch
        np.testing.assert_array_equal(on.fits[ch].estimate, explicit.fits[ch].estimate)
        assert not np.array_equal(on.fits[ch].estimate, off.fits[ch].estimate), ch
