"""Model-structure uncertainty: the covariance of the two-point mixture of the model with and
without a term the flight does not determine (closed forms on synthetic data)."""
from __future__ import annotations

import numpy as np

from aerosid.identification.structure_uncertainty import structure_covariance


def _data(seed: int = 0, n: int = 2000):
    rng = np.random.default_rng(seed)
    x1 = rng.normal(size=n)
    x2 = x1 + 0.05 * rng.normal(size=n)          # nearly collinear with x1
    x3 = rng.normal(size=n)                        # independent of both
    X = np.column_stack([np.ones(n), x1, x2, x3])
    y = 0.1 + 1.0 * x1 - 0.3 * x2 + 0.5 * x3 + 0.2 * rng.normal(size=n)
    est = np.linalg.lstsq(X, y, rcond=None)[0]
    return X, y, est


def test_the_added_covariance_is_the_two_point_mixture_of_the_refit_without_the_term():
    X, y, est = _data()
    weak = np.array([False, False, True, False])
    extra, changes = structure_covariance(X, y, est, weak)
    reduced = np.linalg.lstsq(X[:, [0, 1, 3]], y, rcond=None)[0]
    d = np.array([reduced[0] - est[0], reduced[1] - est[1], -est[2], reduced[2] - est[3]])
    assert set(changes) == {2} and np.allclose(changes[2], d)
    assert np.allclose(extra, 0.25 * np.outer(d, d))
    # x1 takes x2's part when x2 is dropped (about -0.3): that is the structure part of its sigma
    assert abs(np.sqrt(extra[1, 1]) - 0.5 * abs(d[1])) < 1e-12 and 0.1 < abs(d[1]) < 0.5
    # the sum x1 + x2, which the data determine, hardly moves; the independent x3 does not
    w = np.array([0.0, 1.0, 1.0, 0.0])
    assert np.sqrt(w @ extra @ w) < 0.05 * np.sqrt(extra[1, 1])
    assert np.sqrt(extra[3, 3]) < 0.01 * np.sqrt(extra[1, 1])


def test_nothing_is_added_when_every_term_is_determined():
    X, y, est = _data(1)
    extra, changes = structure_covariance(X, y, est, np.zeros(4, bool))
    assert not changes and not extra.any()


def test_rows_the_fit_left_out_are_left_out():
    X, y, est = _data(2)
    Xn = X.copy()
    Xn[:10, 3] = np.nan
    ok = np.all(np.isfinite(Xn), axis=1)
    est_ok = np.linalg.lstsq(X[ok], y[ok], rcond=None)[0]
    extra, changes = structure_covariance(Xn, y, est_ok, np.array([False, False, True, False]))
    reduced = np.linalg.lstsq(X[ok][:, [0, 1, 3]], y[ok], rcond=None)[0]
    assert np.isclose(changes[2][1], reduced[1] - est_ok[1])


def test_a_correction_of_the_reported_estimates_is_not_counted_as_structure():
    """The reported estimates may be SIMEX-corrected; the structure part compares two plain fits
    (review of 2026-11-26: half the correction had leaked into the sigma)."""
    rng = np.random.default_rng(3)
    n = 2000
    x1, x2 = rng.normal(size=n), rng.normal(size=n)  # x2 independent of x1: dropping it moves x1 by ~0
    X = np.column_stack([x1, x2])
    y = 1.0 * x1 + 0.001 * x2 + 0.2 * rng.normal(size=n)
    est = np.linalg.lstsq(X, y, rcond=None)[0] * np.array([1.05, 1.0])  # a 5 % "correction" of x1
    extra, _ = structure_covariance(X, y, est, np.array([False, True]))
    assert np.sqrt(extra[0, 0]) < 1e-3
