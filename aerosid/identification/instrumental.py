"""Instrumental-variable fit for flights in turbulent air (``identify(..., instrumental=True)``).

Why.  In turbulence the air itself rotates: the aerodynamic moments answer to the rates relative
to the air, p - p_g, q - q_g, r - r_g, while the gyros measure the rates relative to the ground.
The rotational gusts p_g, q_g, r_g are not measured, so they sit in the equation error, and the
gust moments they make drive the very rates the regression reads: the regressors correlate with
the equation error and least squares is biased, however long the flight.  Measured on JSBSim's
c172x with its MIL-F-8785C (Tustin) turbulence at light severity (vertical gust 0.55 m/s rms;
bench/results/turbulence.md): C_l,p -56 %, C_l,delta -48 %, C_n,beta +11 % from the pipeline,
and -49 %, -39 %, +14 % from the *noise-free* truth fitted with the gyros' rates instead of the
air's: the gusts' rates, not the sensors, make the bias.  The errors-in-variables correction
(SIMEX) cannot see it: the gust is not white sensor noise of a known sigma.

What.  Two-stage least squares with instruments that the turbulence does not move: the flight's
control-surface deflections (designed inputs, open loop) and the same deflections through a bank
of first-order lags (INSTRUMENT_LAGS_S, each segment from its own first sample), with a
constant.  Stage one projects every regressor on the instruments (the part of p, beta, r ... the
controls explain); stage two regresses the response on those projections.  The estimate is
consistent under rotational gusts and under the regressors' own sensor noise alike; its
covariance is the coloured-residual (Morelli-Klein) sandwich with the residual of the original
regressors.  It costs precision where the controls explain little of a regressor (C_m,alpha's
sigma grows 2-5 x in calm air: the short period's alpha and q follow the elevator together).

Not the default.  A check that would switch to it on its own was measured and rejected: the
difference between the least-squares and the instrumental estimates is as large on calm-air
flights (model structure, the controls' own noise) as on a turbulent one, so the data cannot
decide.  The engineer knows whether the air was turbulent (pilot's notes, the vane against the
kinematics): ``aerosid run --turbulent-air``.  With a feedback control system that moves a surface
with the rates it damps (a yaw damper) that surface is not a clean instrument: the warning says
so, and such a flight is better flown with the damper off.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import scipy.signal

from aerosid.identification.band import segment_keys
from aerosid.identification.linear_fit import LinearFit
from aerosid.identification.regression import with_posterior
from aerosid.identification.residual_covariance import _group_slices, _morelli_klein, auto_max_lag

#: Time constants [s] of the first-order lags the controls go through to make the instruments
#: (with the controls themselves): a roll mode, a short period and a Dutch roll of 0.1-3 s are
#: each followed by some combination of them.  Fixed from the modes' physics, not fitted.
INSTRUMENT_LAGS_S = (0.2, 0.6, 2.0)
#: The flight data's control columns used as instruments (those present).
CONTROL_COLUMNS = ("delta_p_rad", "delta_r_rad", "delta_y_rad")


def control_instruments(fd: pd.DataFrame, lags_s=INSTRUMENT_LAGS_S) -> np.ndarray:
    """(n, m) instruments of the flight data ``fd`` (sorted by segment and time): a constant, each
    control column, and each control minus its segment's first value through first-order lags of
    time constants ``lags_s`` [s] (per segment, on the segment's own median step)."""
    t = fd["t_s"].to_numpy(float)
    groups = segment_keys(fd)
    cols = [np.ones(len(fd))]
    for c in CONTROL_COLUMNS:
        if c not in fd.columns:
            continue
        u = fd[c].to_numpy(float)
        lagged = [np.zeros(len(fd)) for _ in lags_s]
        for g in pd.unique(groups):
            idx = np.flatnonzero(groups == g)
            if idx.size < 2:
                continue
            dt = float(np.median(np.diff(t[idx])))
            x = u[idx] - u[idx][0]
            for j, tau in enumerate(lags_s):
                a = float(np.exp(-dt / tau))
                lagged[j][idx] = scipy.signal.lfilter([1.0 - a], [1.0, -a], x)
        cols += [u, *lagged]
    return np.column_stack(cols)


def iv_estimate(y: np.ndarray, X: np.ndarray, Z: np.ndarray, groups=None):
    """(estimate (k,), covariance (k, k), first-stage R^2 per column (k,)) of the two-stage least
    squares of y (n,) on X (n, k) with instruments Z (n, m), m >= k; the covariance is the
    Morelli-Klein coloured-residual sandwich (within each group of ``groups`` when given)."""
    y, X, Z = np.asarray(y, float), np.asarray(X, float), np.asarray(Z, float)
    if Z.shape[1] < X.shape[1]:
        raise ValueError(f"{Z.shape[1]} instruments for {X.shape[1]} regressors: at least as many are needed")
    Q, _ = np.linalg.qr(Z)
    Xh = Q @ (Q.T @ X)
    A = Xh.T @ Xh
    A_inv = np.linalg.inv(A)
    theta = A_inv @ (Xh.T @ y)
    resid = y - X @ theta
    slices = _group_slices(None if groups is None else np.asarray(groups))
    cov, _ = _morelli_klein(Xh, resid, A_inv, auto_max_lag(resid, groups=groups), slices)
    spread = ((X - X.mean(axis=0)) ** 2).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        r2 = np.where(spread > 0, 1.0 - ((X - Xh) ** 2).sum(axis=0) / spread, 1.0)
    return theta, cov, r2


def instrumental_fit(fit: LinearFit, y: np.ndarray, X: np.ndarray, Z: np.ndarray, groups=None) -> LinearFit:
    """The fit with the instrumental estimate and covariance in place of its own (the residual
    statistics stay the least-squares fit's), and a warning that says so, with the least-squares
    estimates for comparison and the regressors the controls explain least (first-stage R^2).
    A fit that dropped rows or columns is returned with a warning only."""
    est = np.asarray(fit.estimate, float)
    if fit.n_dropped or not np.all(np.isfinite(est)):
        return with_posterior(fit, est, fit.cov, "instrumental-variable fit not applied: the least-squares fit "
                              "dropped rows or columns (aerosid.identification.instrumental)")
    theta, cov, r2 = iv_estimate(y, X, Z, groups)
    weak = [f"{n} {r:.2f}" for n, r in zip(fit.names, r2) if r < 0.5]
    ls = ", ".join(f"{n} {v:.4g}" for n, v in zip(fit.names, est))
    note = ("turbulent air: estimates and sigma from instrumental variables (the controls and their lags as "
            f"instruments, aerosid.identification.instrumental); least squares gave {ls}"
            + (f"; regressors the controls explain little (first-stage R^2): {', '.join(weak)}" if weak else "")
            + "; a surface a control system moves with the rates (a yaw damper) is not a clean instrument")
    return with_posterior(fit, theta, cov, note)
