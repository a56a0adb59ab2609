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
sigma in calm air: pa28 3.6 -> 4.1 %, c172x 3.7 -> 10.8 %, OV10 2.9 -> 27.7 %: the short period's
alpha and q follow the elevator together).  Measured in light turbulence on five aircraft, 4 seeds
each (bench/results/turbulence.md): it cuts the gusts' bias of the seed means to 0.2-0.5 of least
squares' (c172x C_l,p -60 -> -25 %, coverage 0 -> 50 %; single flights 0.2-0.8) but does not
remove it: with instruments that explain little of p, beta and r outside the doublets 2SLS leans
toward least squares.

Not the default.  A check that would switch to it on its own was measured and rejected: the
difference between the least-squares and the instrumental estimates is as large on calm-air
flights (model structure, the controls' own noise) as on a turbulent one, so the data cannot
decide.  The engineer knows whether the air was turbulent (pilot's notes, the vane against the
kinematics) and says so in the vehicle file: ``[estimation] turbulent_air = true``.  With a feedback
control system that moves a surface with the rates it damps (a yaw damper) that surface is not a
clean instrument: such a flight is better flown with the damper off.  The diagnosis, the
stepwise structure search and the experiment design still use least squares (the diagnosis's
message says so first on such a flight).
"""
from __future__ import annotations

import dataclasses

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
#: Singular values of the instruments below this share of the largest are not instruments.
RANK_TOL = 1e-10
#: LinearFit.method of an instrumental-variable fit (the estimator-bias check builds its world on it).
METHOD = "instrumental"


def _stretches(fd: pd.DataFrame) -> np.ndarray:
    """A label per row of the flight data's contiguous stretches: its segments (its flights when it
    has no segment column), split again where a step is more than 1.5 x the stretch's median step
    (rows a Mach window or a cut left out)."""
    if {"flight", "segment"} <= set(fd.columns):
        keys = segment_keys(fd)
    elif "segment" in fd.columns or "flight" in fd.columns:
        keys = fd["segment" if "segment" in fd.columns else "flight"].astype(str).to_numpy()
    else:
        keys = np.zeros(len(fd))
    t = fd["t_s"].to_numpy(float)
    out = np.empty(len(fd), dtype=object)
    for g in pd.unique(keys):
        idx = np.flatnonzero(keys == g)
        steps = np.diff(t[idx])
        dt = float(np.median(steps)) if steps.size else 0.0
        cut = (steps > 1.5 * dt) | (steps <= 0)  # a gap, or time not moving forward
        part = np.concatenate([[0], np.cumsum(cut)]) if steps.size else np.zeros(idx.size, int)
        out[idx] = [f"{g}#{k}" for k in part]
    return out


def control_instruments(fd: pd.DataFrame, lags_s=INSTRUMENT_LAGS_S) -> np.ndarray:
    """(n, m) instruments of the flight data ``fd`` (sorted by segment and time): a constant, each
    control column, and each control minus its stretch's first value through first-order lags of
    time constants ``lags_s`` [s] (per contiguous stretch, _stretches, on its own median step)."""
    t = fd["t_s"].to_numpy(float)
    groups = _stretches(fd)
    stretches = [idx for idx in (np.flatnonzero(groups == g) for g in pd.unique(groups)) if idx.size >= 2]
    steps = [float(np.median(np.diff(t[idx]))) for idx in stretches]
    cols = [np.ones(len(fd))]
    for c in CONTROL_COLUMNS:
        if c not in fd.columns:
            continue
        u = fd[c].to_numpy(float)
        lagged = [np.zeros(len(fd)) for _ in lags_s]
        for idx, dt in zip(stretches, steps):
            x = u[idx] - u[idx][0]
            for j, tau in enumerate(lags_s):
                a = float(np.exp(-dt / tau))
                lagged[j][idx] = scipy.signal.lfilter([1.0 - a], [1.0, -a], x)
        cols += [u, *lagged]
    return np.column_stack(cols)


def _unexplained(X: np.ndarray, Xh: np.ndarray) -> int | None:
    """Index of a regressor the instruments' projection leaves (nearly) collinear with the others,
    or None: the projected columns, each scaled to unit norm, must have full rank."""
    norms = np.linalg.norm(Xh, axis=0)
    if np.any(norms <= RANK_TOL * max(float(np.linalg.norm(X)), 1e-300)):
        return int(np.argmin(norms))
    sv = np.linalg.svd(Xh / norms, compute_uv=False)
    if sv.min() > RANK_TOL ** 0.5 * sv.max():
        return None
    r2 = norms ** 2 / np.maximum(np.linalg.norm(X - X.mean(axis=0), axis=0) ** 2, 1e-300)
    return int(np.argmin(r2))


def iv_estimate(y: np.ndarray, X: np.ndarray, Z: np.ndarray, groups=None, names=None):
    """(estimate (k,), covariance (k, k), first-stage R^2 per column (k,)) of the two-stage least
    squares of y (n,) on X (n, k) with instruments Z (n, m), m >= k; the covariance is the
    Morelli-Klein coloured-residual sandwich (within each group of ``groups`` when given).  A
    ValueError when the instruments are not finite, span fewer directions than X has columns, or
    leave a regressor (named from ``names`` when given) collinear with the others."""
    y, X, Z = np.asarray(y, float), np.asarray(X, float), np.asarray(Z, float)
    if not np.all(np.isfinite(Z)):
        bad = np.flatnonzero(~np.all(np.isfinite(Z), axis=0))
        raise ValueError(f"instrument column(s) {bad.tolist()} are not finite (a control with NaN)")
    # an orthonormal basis of the instruments' span, rank-revealing (a held control repeats the
    # constant and its lags are zero): directions below RANK_TOL of the largest are not instruments
    U, sv, _ = np.linalg.svd(Z, full_matrices=False)
    Q = U[:, sv > RANK_TOL * sv.max()] if sv.size and sv.max() > 0 else U[:, :0]
    if Q.shape[1] < X.shape[1]:
        raise ValueError(f"the instruments span {Q.shape[1]} directions for {X.shape[1]} regressors: at least as "
                         "many are needed (controls that move)")
    Xh = Q @ (Q.T @ X)
    j = _unexplained(X, Xh)
    if j is not None:
        name = names[j] if names is not None else f"column {j}"
        raise ValueError(f"the instruments do not explain the regressor of {name} apart from the others (its "
                         "projection on them is collinear with theirs)")
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
    """The fit with the instrumental estimate and covariance in place of its own and ``method``
    METHOD, and a warning that says so, with the least-squares estimates for comparison and the
    regressors the controls explain least (first-stage R^2).  Its residual statistics and its
    "sigma OLS" stay the least-squares fit's (the warning says so).  A fit that dropped rows or
    columns, or whose instruments do not span its regressors, is returned as least squares
    (without the errors-in-variables correction) with a warning saying why."""
    est = np.asarray(fit.estimate, float)
    why = ("the least-squares fit dropped rows or columns" if fit.n_dropped or not np.all(np.isfinite(est))
           else None)
    if why is None:
        try:
            theta, cov, r2 = iv_estimate(y, X, Z, groups, fit.names)
        except ValueError as exc:
            why = str(exc)
    if why is not None:
        return with_posterior(fit, est, fit.cov, f"turbulent air: instrumental-variable fit not possible ({why}); "
                              "plain least squares reported, without the errors-in-variables correction "
                              "(aerosid.identification.instrumental)")
    weak = [f"{n} {r:.2f}" for n, r in zip(fit.names, r2) if r < 0.5]
    ls = ", ".join(f"{n} {v:.4g}" for n, v in zip(fit.names, est))
    note = ("turbulent air: estimates and sigma from instrumental variables (the controls and their lags as "
            f"instruments, aerosid.identification.instrumental); least squares gave {ls}"
            + (f"; regressors the controls explain little (first-stage R^2): {', '.join(weak)}" if weak else "")
            + "; sigma OLS and the residual statistics are the least-squares fit's")
    return dataclasses.replace(with_posterior(fit, theta, cov, note), method=METHOD)
