"""The smoothing derivative of alpha_dot_hat and the fin rates (aerosid.identification.derivatives)."""
import numpy as np
import pytest
import scipy.signal

from aerosid.identification.derivatives import _savgol_slope, smooth_derivative


@pytest.mark.parametrize("n,win,dt", [(5, 5, 0.01), (31, 31, 0.01), (500, 11, 0.013), (2000, 21, 0.02),
                                      (302, 301, 0.01), (3000, 1001, 0.005)])
def test_cached_operators_equal_scipys_interp_mode(n, win, dt):
    y = np.cumsum(np.random.default_rng(n).standard_normal(n))
    ref = scipy.signal.savgol_filter(y, win, 2, deriv=1, delta=dt, mode="interp")
    # scipy fits its edges on the uncentred 0..win-1 (condition ~win^2): its own rounding reaches
    # ~2e-10 of the signal at win = 1001
    np.testing.assert_allclose(_savgol_slope(y, win, dt), ref, rtol=0, atol=1e-8 * np.max(np.abs(ref)))


def test_a_quadratic_is_differentiated_exactly_to_its_ends_per_group():
    t = np.arange(0.0, 4.0, 0.01)
    groups = (t >= 2.0).astype(int)  # two segments, each its own quadratic
    y = np.where(groups == 0, 3.0 * t**2 - t, -2.0 * t**2 + 5.0)
    dy = np.where(groups == 0, 6.0 * t - 1.0, -4.0 * t)
    np.testing.assert_allclose(smooth_derivative(t, y, groups, 0.25), dy, atol=1e-9)
