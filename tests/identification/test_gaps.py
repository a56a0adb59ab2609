"""Gaps the preprocessing bridged with a straight line are kept out of the regression
(aerosid.flight_data.bridged_gaps and the margin around them): a line across a 0.2 s
dropout cuts the manoeuvre's peaks, and the common low-pass spreads that to the
neighbours, biasing the slopes; without those rows they come back."""
import numpy as np
import pandas as pd
import pytest

from aerosid.estimation.findings import dilate
from aerosid.flight_data import GAP_MARGIN_CYCLES, bridged_gaps
from aerosid.identification.band import band_limited_signals, finite_runs, low_pass_runs
from aerosid.preprocess.flags import QualityFlag


def _short_period(n: int, dt: float):
    t = np.arange(n) * dt
    seq = np.concatenate([np.full(3, 1.0), np.full(2, -1.0), [1.0], [-1.0], np.zeros(3)])
    delta = 0.05 * seq[((t / 0.4).astype(int)) % seq.size]
    Ma, Md, Mq, Za = -40.0, -30.0, -4.0, -1.5
    alpha, q = np.zeros(n), np.zeros(n)
    for k in range(n - 1):  # short-period dynamics, RK2
        def f(a, qq, d):
            return qq + Za * a, Ma * a + Md * d + Mq * qq
        k1 = f(alpha[k], q[k], delta[k])
        k2 = f(alpha[k] + dt * k1[0], q[k] + dt * k1[1], delta[k + 1])
        alpha[k + 1] = alpha[k] + 0.5 * dt * (k1[0] + k2[0])
        q[k + 1] = q[k] + 0.5 * dt * (k1[1] + k2[1])
    return t, alpha, q, delta, (Ma, Md, Mq)


def test_bridged_gaps_are_runs_of_fault_flags_not_single_spikes():
    n = 200
    flags = np.zeros(n, np.uint16)
    flags[50:60] = QualityFlag.MISSING_ROW | QualityFlag.INTERPOLATED
    flags[120] = QualityFlag.OUTLIER | QualityFlag.INTERPOLATED     # a spike: not a gap
    flags[150:170] = QualityFlag.HELD | QualityFlag.INTERPOLATED    # a slow sensor: not a fault
    frame = pd.DataFrame({"flags_q_rad_s": flags, "flags": flags, "q_rad_s_clean": np.zeros(n)})
    gaps = bridged_gaps(frame, 100.0)
    assert np.flatnonzero(gaps).tolist() == list(range(50, 60))


def test_rows_near_bridged_gaps_bias_the_slopes_and_leaving_them_out_removes_it():
    dt, n = 0.01, 12000
    t, alpha, q, delta, truth = _short_period(n, dt)
    flags = np.zeros(n, np.uint16)
    rng = np.random.default_rng(7)
    for start in rng.integers(100, n - 100, 40):  # 40 dropouts of 0.2 s, bridged by a line
        flags[start:start + 20] = QualityFlag.MISSING_ROW | QualityFlag.INTERPOLATED
    gap = flags != 0
    idx = np.arange(n)
    bridged = [np.where(gap, np.interp(idx, idx[~gap], x[~gap]), x) for x in (alpha, q, delta)]
    band = 2.5
    w = np.column_stack([np.zeros(n), bridged[1], np.zeros(n)])
    bl = band_limited_signals(t, w, np.zeros((n, 3)), (1.0, 1.0, 1.0, 0.0), (0, 0, 0), band_hz=band)
    runs = finite_runs(bl.used)
    A, D = (low_pass_runs(v, 1 / dt, band, runs) for v in (bridged[0], bridged[2]))
    X = np.column_stack([A, D, bl.rates_rad_s[:, 1]])
    y = bl.ang_accel_rad_s2[:, 1]

    def fit(rows):
        return np.linalg.lstsq(X[rows], y[rows], rcond=None)[0]

    every = bl.used
    away = every & ~dilate(bridged_gaps(pd.DataFrame({"flags_q_rad_s": flags}), 1 / dt),
                           int(np.ceil(GAP_MARGIN_CYCLES / band / dt)))
    assert 0.6 < away.sum() / every.sum() < 0.95
    with_gaps, without = fit(every), fit(away)
    assert without == pytest.approx(truth, rel=0.01)
    assert max(abs(with_gaps / np.array(truth) - 1)) > 3 * max(abs(without / np.array(truth) - 1))
