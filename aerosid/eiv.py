"""Errors in the regressors: SIMEX correction for air-data vane noise.

With alpha and beta read from vanes, the regressors carry the vanes' noise (after the
vane low-pass) and so do the signals derived from them (alpha-dot, beta-dot, alpha_r,
phi_r). Least squares then attenuates the angle terms. The alpha-dot term suffers
most, and what it loses shifts into the terms it correlates with (C_m_alpha). On the
JSBSim c172x flight this moved C_m_alpha by about -6 %.

SIMEX (Cook & Stefanski 1994) measures the attenuation on the data themselves. It
refits with extra noise of variance lambda sigma^2 added to the raw vane angles,
passed through the same low-pass as the vanes, with every derived signal
recomputed. It does so for lambda in LAMBDAS, averaging REPLICATES draws each, then
extrapolates each coefficient quadratically to lambda = -1: no noise at all.

The corrected estimates replace the naive ones. The sigma stays the coloured-residual
sigma of the naive fit, a slight underestimate. The draws are seeded, so the result
is reproducible.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from aerosid.derivatives import zero_phase_low_pass
from aerosid.inversion import total_angles

LAMBDAS = (0.5, 1.0, 1.5, 2.0)
REPLICATES = 10
SEED = 20261122


def filtered_noise(rng: np.random.Generator, groups: np.ndarray, t_s: np.ndarray, sigma: float,
                   cutoff_hz: float | None) -> np.ndarray:
    """White noise of 1-sigma `sigma` through the vane low-pass, per flight segment."""
    out = np.empty(len(t_s))
    for g in pd.unique(groups):
        idx = np.flatnonzero(groups == g)
        fs = 1.0 / float(np.median(np.diff(t_s[idx]))) if idx.size > 1 else 1.0
        out[idx] = zero_phase_low_pass(sigma * rng.standard_normal(idx.size), fs, cutoff_hz)
    return out


def with_angle_noise(fd: pd.DataFrame, rng: np.random.Generator, groups: np.ndarray, sigma: float,
                     cutoff_hz: float | None) -> pd.DataFrame:
    """A copy of the flight data with extra noise of 1-sigma `sigma` on alpha and beta
    (alpha_r, phi_r recomputed): white when cutoff_hz is None (angles inverted from the
    database), else through the vanes' low-pass (the vanes' own noise)."""
    f = fd.copy()
    t = f["t_s"].to_numpy(float)

    def draw() -> np.ndarray:
        if cutoff_hz is None:
            return sigma * rng.standard_normal(len(f))
        return filtered_noise(rng, groups, t, sigma, cutoff_hz)

    a = f["alpha_rad"].to_numpy(float) + draw()
    b = f["beta_rad"].to_numpy(float) + draw()
    f["alpha_rad"], f["beta_rad"] = a, b
    f["alpha_r_rad"], f["phi_r_rad"] = total_angles(a, b)
    return f


def simex_estimates(fd: pd.DataFrame, y_by_channel: dict[str, np.ndarray], design, sigma_rad: float,
                    cutoff_hz: float | None) -> dict[str, np.ndarray]:
    """Corrected coefficient vectors per channel.

    fd: the flight data of the fit (sorted as fitted). y_by_channel: the responses.
    design: fd -> {channel: (n, k) regressor matrix} (the models on that frame's signals).
    sigma_rad: the vanes' raw noise 1-sigma [rad]; cutoff_hz: the vane low-pass corner.
    """
    rng = np.random.default_rng(SEED)
    groups = (fd["flight"].astype(str) + "/" + fd["segment"].astype(str)).to_numpy()

    def fit_all(frame: pd.DataFrame) -> dict[str, np.ndarray]:
        X = design(frame)
        return {ch: np.linalg.lstsq(X[ch], y, rcond=None)[0] for ch, y in y_by_channel.items()}

    naive = fit_all(fd)
    curves = {ch: [b] for ch, b in naive.items()}
    for lam in LAMBDAS:
        acc = {ch: np.zeros_like(b) for ch, b in naive.items()}
        for _ in range(REPLICATES):
            f = with_angle_noise(fd, rng, groups, sigma_rad * np.sqrt(lam), cutoff_hz)
            for ch, est in fit_all(f).items():
                acc[ch] += est / REPLICATES
        for ch in curves:
            curves[ch].append(acc[ch])
    lams = np.array((0.0, *LAMBDAS))
    out = {}
    for ch, rows in curves.items():
        E = np.array(rows)  # (len(lams), k)
        out[ch] = np.array([np.polyval(np.polyfit(lams, E[:, j], 2), -1.0) for j in range(E.shape[1])])
    return out
