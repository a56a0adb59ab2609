"""SIMEX correction for vane noise (aerosid.identification.eiv): a known slope attenuated by noise in its
regressor is recovered; without noise the correction changes nothing."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from aerosid.identification.eiv import filtered_noise, simex_estimates


def _frame(alpha: np.ndarray, t: np.ndarray) -> pd.DataFrame:
    return pd.DataFrame({"t_s": t, "flight": "f", "segment": "s0", "alpha_rad": alpha, "beta_rad": 0.0 * alpha,
                         "alpha_r_rad": np.abs(alpha), "phi_r_rad": 0.0 * alpha})


def _design(frame: pd.DataFrame) -> dict:
    a = frame["alpha_rad"].to_numpy()
    return {"Cm": np.column_stack([np.ones_like(a), a])}


@pytest.mark.parametrize("sigma", [0.02, 0.03])
def test_simex_recovers_a_slope_attenuated_by_filtered_vane_noise(sigma):
    rng = np.random.default_rng(0)
    t = np.arange(6000) * 0.01
    alpha = 0.01 * np.sin(2 * np.pi * 0.3 * t) + 0.006 * np.sin(2 * np.pi * 0.9 * t + 1.0)
    y = 0.1 - 1.8 * alpha + 1e-4 * rng.standard_normal(t.size)
    measured = alpha + filtered_noise(rng, np.zeros(t.size), t, sigma, 2.0)
    fd = _frame(measured, t)
    naive = np.linalg.lstsq(_design(fd)["Cm"], y, rcond=None)[0][1]
    res = simex_estimates(fd, {"Cm": y}, _design, sigma, 2.0)["Cm"]
    corrected = res.corrected[1]
    assert naive > -1.8 * 0.9  # attenuated by the noise (the test can fail)
    assert abs(corrected / -1.8 - 1) < 0.4 * abs(naive / -1.8 - 1)  # most of the attenuation removed
    # the corrected sigma grows with the correction and covers what is left of the bias
    se = res.std_error(np.array([0.0, 1e-6]))
    assert abs(corrected + 1.8) <= 2.5 * se[1]


def test_simex_without_noise_changes_nothing():
    t = np.arange(3000) * 0.01
    alpha = 0.01 * np.sin(2 * np.pi * 0.3 * t)
    y = 0.1 - 1.8 * alpha
    out = simex_estimates(_frame(alpha, t), {"Cm": y}, _design, 0.0, 2.0)["Cm"]
    assert out.corrected == pytest.approx([0.1, -1.8], rel=1e-9)
    assert out.std_error(np.array([1e-3, 2e-3])) == pytest.approx([1e-3, 2e-3], rel=1e-6)
