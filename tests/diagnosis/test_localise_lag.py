"""The lag test of the localisation (aerosid.diagnosis.localise): its p on a known lag, and
its calibration on no-lag flights (issue 18: the lag finding's p must mean what it says).

A synthetic channel Cm = Cm0 + Cm_alpha alpha + Cm_delta_p delta_p(t - tau)/2 + coloured
error: the fin is band-limited noise (0.2-2 Hz, the autopilot's band), alpha a slow random
signal and the error white noise low-passed at 1 Hz (the flight-derived coefficients' error
has its power at 0.5-1.5 Hz, aerosid.diagnosis.synthetic).  The fin rate is exact
(np.gradient of the noise-free fin): the test is about the statistic, not the derivative.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.signal
import scipy.stats

from aerosid.diagnosis.localise import _Channel
from aerosid.diagnosis.trends import _lag_findings
from aerosid.modelling.models import ChannelModel, Term

FS_HZ = 100.0
N = 4000  # 40 s
MODEL = ChannelModel("Cm", (Term("Cm0", "1"), Term("Cm_alpha", "alpha"), Term("Cm_delta_p", "delta_p/2")))
TRUTH = {"Cm0": 0.01, "Cm_alpha": -0.25, "Cm_delta_p": 0.08}


def _band(rng, lo_hz, hi_hz, std):
    x = rng.standard_normal(N + 800)
    sos = scipy.signal.butter(4, [lo_hz, hi_hz] if lo_hz else hi_hz, "bandpass" if lo_hz else "lowpass",
                              fs=FS_HZ, output="sos")
    x = scipy.signal.sosfiltfilt(sos, x)[400:-400]
    return std * x / np.std(x)


def _flight(seed: int, lag_s: float, error_std: float = 4e-4):
    rng = np.random.default_rng(seed)
    t = np.arange(N) / FS_HZ
    # the fin over a longer record, so the lagged fin is defined at the start
    fin = _band(rng, 0.2, 2.0, 0.03)
    alpha = 0.05 + _band(rng, 0.0, 0.1, 0.02)
    lagged = np.interp(t - lag_s, t, fin)
    y = (TRUTH["Cm0"] + TRUTH["Cm_alpha"] * alpha + TRUTH["Cm_delta_p"] * lagged / 2.0
         + _band(rng, 0.0, 1.0, error_std))
    signals = {"alpha": alpha, "delta_p": fin, "delta_p_dot": np.gradient(fin, t), "t": t}
    return signals, y, t


def _lag(seed: int, lag_s: float):
    signals, y, t = _flight(seed, lag_s)
    win = np.minimum((np.arange(N) * 8) // N, 7)
    c = _Channel("Cm", MODEL, y, signals, win)
    (f,) = _lag_findings(c, t, np.zeros(N, dtype=int))
    return f


def test_a_known_40_ms_lag_is_significant_with_its_size():
    f = _lag(seed=3, lag_s=0.040)
    assert f.kind == "lag" and f.variable == "delta_p" and f.suggested_expression == "delta_p_dot/2"
    assert f.significant, f.reasons
    assert f.p_value < 1e-6
    # first order u(t - tau) = u - tau u_dot: the estimate is the lag (to within its sigma)
    assert f.evidence["lag_s"] == pytest.approx(0.040, abs=max(0.006, 3 * f.evidence["lag_std_s"]))
    assert f.evidence["lag_scan_s"] == pytest.approx(0.040, abs=0.010)
    # coefficient of delta_p_dot/2 is -lag x Cm_delta_p
    assert f.estimate == pytest.approx(-0.040 * TRUTH["Cm_delta_p"], rel=0.25)


def test_lag_test_p_is_calibrated_on_flights_without_a_lag():
    """No lag: the lag statistic's p is about uniform (share below 0.05 about 5 %, not 0 % or
    30 %), t about N(0, 1), and the estimated sigma covers the estimate's scatter over seeds."""
    fs = [_lag(seed, 0.0) for seed in range(60)]
    p = np.array([f.p_value for f in fs])
    t = np.array([f.t_value for f in fs])
    est = np.array([f.estimate for f in fs])
    se = np.array([f.std_error for f in fs])
    assert not any(f.significant for f in fs)
    assert np.mean(p < 0.05) <= 0.15  # 3 of 60 expected; measured 0 (the sigma is ~10 % conservative)
    assert 0.08 <= np.mean(p < 0.2) <= 0.35  # measured 0.18
    assert np.mean(p < 0.5) == pytest.approx(0.5, abs=0.2)
    assert scipy.stats.kstest(p, "uniform").pvalue > 0.01
    assert 0.6 <= np.mean(t**2) <= 1.6
    # the coloured-residual sigma is the estimate's real scatter (neither 2x nor 0.5x)
    assert 0.7 <= np.std(est) / np.sqrt(np.mean(se**2)) <= 1.4


def test_lag_power_grows_with_the_lag():
    """Same noise draw, lag 0 -> 20 -> 40 ms: |t| grows with the lag (the statistic measures it)."""
    t = [abs(_lag(seed=5, lag_s=lag).t_value) for lag in (0.0, 0.020, 0.040)]
    assert t[0] < t[1] < t[2]
