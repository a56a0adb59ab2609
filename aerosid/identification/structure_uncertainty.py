"""Model-structure uncertainty from a term the flight does not determine.

When a term's 95 % interval holds 0, the flight cannot tell the model with the term from the
model without it, and the other coefficients may depend on which is right.  The reported
sigma of each estimate are conditional on the structure; they do not know this.  Measured on
JSBSim aircraft the project had never flown (bench/results/generalisation_unseen.md): on the
J3Cub, C_m,alpha_dot came out -2.3 +- 2.6 against a truth of -7.5 (the vane's noise in
alpha-dot attenuates it, and SIMEX's extrapolation cannot restore a regressor that is mostly
noise), and C_m,alpha -1.36 +- 0.11 against -1.58 (-14 %, 2.1 sigma).

So, after the errors-in-variables correction: for every non-constant term whose interval holds
0, the channel is refitted without it (plain least squares on the same samples), and the
coefficients' covariance takes the covariance of the two-point mixture of the two structures,
taken as equally likely: (1/4) d d^T, with d the change of every estimate when the term is
dropped (the dropped term's own change is minus its estimate).  Several such terms add (each
dropped alone).  The estimates are unchanged.  A combination the flight does determine (C_m,q
+ C_m,alpha_dot, whose parts trade when alpha-dot is dropped) keeps its sigma: the mixture
moves along the direction the data cannot see.  A term the flight determines changes nothing.
"""
from __future__ import annotations

import numpy as np

#: Weight of each structure in the two-point mixture (equally likely: 1/2 each, covariance d d^T / 4).
MIXTURE_WEIGHT = 0.5


def structure_covariance(X: np.ndarray, y: np.ndarray, estimate: np.ndarray,
                         undetermined: np.ndarray) -> tuple[np.ndarray, dict[int, np.ndarray]]:
    """(covariance to add (k, k), {dropped column: change d of every estimate when it is dropped}).

    X (n, k), y (n,): the fit's regressors and response (rows with a non-finite value are left
    out, as the fit did); estimate (k,): the reported estimates (the dropped term's change is
    minus its reported estimate; the others' is the difference of two plain least-squares fits,
    with and without the term, so an errors-in-variables correction of the reported estimates
    does not count as structure); undetermined (k,) bool: the terms whose 95 % interval holds 0
    (and that are not constants)."""
    X = np.asarray(X, float)
    y = np.asarray(y, float)
    est = np.asarray(estimate, float)
    k = est.size
    extra = np.zeros((k, k))
    changes: dict[int, np.ndarray] = {}
    drop = np.flatnonzero(np.asarray(undetermined, bool))
    ok = np.isfinite(y) & np.all(np.isfinite(X), axis=1)
    if drop.size == 0 or k < 2 or ok.sum() <= k:
        return extra, changes
    w = MIXTURE_WEIGHT * (1.0 - MIXTURE_WEIGHT)
    # like with like: the change between two plain least-squares fits; the reported estimates may
    # carry an errors-in-variables correction, which is not the structure's to count
    full = np.linalg.lstsq(X[ok], y[ok], rcond=None)[0]
    for j in drop:
        keep = np.array([i for i in range(k) if i != j])
        theta = np.linalg.lstsq(X[ok][:, keep], y[ok], rcond=None)[0]
        d = np.empty(k)
        d[keep] = theta - full[keep]
        d[j] = -est[j]
        d[~np.isfinite(d)] = 0.0
        changes[int(j)] = d
        extra += w * np.outer(d, d)
    return extra, changes
