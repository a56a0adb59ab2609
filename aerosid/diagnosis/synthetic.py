"""FlightData-like frames from simulator truth plus estimation errors (for tests and demos).

The real pipeline's flight data carry the errors of the Kalman smoother and of the
database inversion: slowly varying (coloured) errors on the coefficients and on
the recovered angles.  :func:`flight_data_from_truth` imitates them by adding
white Gaussian noise low-pass filtered at ``cutoff_hz`` (zero-phase 2nd-order
Butterworth), scaled to the given standard deviations.

The default levels (:data:`MEASURED_NOISE`) are the errors of the real pipeline
(preprocess -> EKF + MBF smoother -> flight data) on the seed-rlv reference flight,
measured against the simulator's truth on |M - 12.4| <= 0.5 (seeds 0 and 1): std of
(flight-derived - true) per channel; the errors' median frequency is 0.5-1.5 Hz
(autocorrelation zero crossing 0.2-0.5 s), which a 1 Hz 2nd-order low-pass imitates.
In the real pipeline the alpha error is the C_N error divided by C_N_alpha (the angles
come from inverting the force database); here they are drawn independently.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
import scipy.signal

from aerosid.identification.inversion import total_angles


@dataclass(frozen=True)
class NoiseLevels:
    """1-sigma of the coloured estimation errors added to the truth (SI, radians)."""

    CN: float = 4.4e-3
    CY: float = 2.3e-3
    Cm: float = 8.3e-4
    Cn: float = 2.5e-4
    Cl: float = 2.5e-4
    alpha_rad: float = 2.5e-3
    beta_rad: float = 1.3e-3
    rates_rad_s: float = 5.4e-3  # smoothed p, q, r
    cutoff_hz: float = 1.0  # low-pass corner of the coloured noise

    def scaled(self, factor: float) -> "NoiseLevels":
        return NoiseLevels(*(factor * getattr(self, f) for f in
                             ("CN", "CY", "Cm", "Cn", "Cl", "alpha_rad", "beta_rad", "rates_rad_s")),
                           cutoff_hz=self.cutoff_hz)


#: The real pipeline's estimation errors on seed-rlv (see module doc).
MEASURED_NOISE = NoiseLevels()
#: No estimation error at all (the truth itself).
NO_NOISE = NoiseLevels(0, 0, 0, 0, 0, 0, 0, 0)


def coloured_noise(rng: np.random.Generator, n: int, sigma: float, cutoff_hz: float, fs_hz: float) -> np.ndarray:
    """White noise low-pass filtered at cutoff_hz, scaled to sample std sigma."""
    if sigma == 0 or n == 0:
        return np.zeros(n)
    w = rng.standard_normal(n)
    if cutoff_hz < 0.5 * fs_hz:
        sos = scipy.signal.butter(2, cutoff_hz, fs=fs_hz, output="sos")
        w = scipy.signal.sosfiltfilt(sos, w)
    return sigma * w / w.std()


def flight_data_from_truth(truth: pd.DataFrame, noise: NoiseLevels = MEASURED_NOISE, seed: int = 0,
                           flight: str = "sim") -> pd.DataFrame:
    """A FlightData frame (schemas/flight_data.py columns) from a SimulatedFlight.truth frame.

    alpha_r and phi_r are recomputed from the noisy alpha and beta, so the roll
    signals carry the inversion error as they would in flight.
    """
    t = truth["t_s"].to_numpy(float)
    n = t.size
    fs = 1.0 / float(np.median(np.diff(t)))
    rng = np.random.default_rng(seed)

    def noisy(col: str, sigma: float) -> np.ndarray:
        return truth[col].to_numpy(float) + coloured_noise(rng, n, sigma, noise.cutoff_hz, fs)

    out = {
        "t_s": t, "flight": flight, "segment": "seg00",
        "V_m_s": truth["V_m_s"].to_numpy(float), "h_m": truth["h_m"].to_numpy(float),
        "rho_kg_m3": truth["rho_kg_m3"].to_numpy(float), "mach": truth["mach"].to_numpy(float),
        "qbar_pa": truth["qbar_pa"].to_numpy(float), "CA": truth["CA"].to_numpy(float),
    }
    for ch in ("CY", "CN", "Cl", "Cm", "Cn"):
        out[ch] = noisy(ch, getattr(noise, ch))
    for ch in ("CY", "CN", "Cl", "Cm", "Cn"):  # the errors' own 1-sigma (an honest sigma column)
        out[f"sigma_{ch}"] = np.full(n, getattr(noise, ch))
    alpha = noisy("alpha_rad", noise.alpha_rad)
    beta = noisy("beta_rad", noise.beta_rad)
    out["alpha_rad"], out["beta_rad"] = alpha, beta
    out["alpha_r_rad"], out["phi_r_rad"] = total_angles(alpha, beta)
    out["inversion_J"] = np.zeros(n)
    for c in ("delta_p_rad", "delta_y_rad", "delta_r_rad"):
        out[c] = truth[c].to_numpy(float)
    for c in ("p_rad_s", "q_rad_s", "r_rad_s"):
        out[c] = noisy(c, noise.rates_rad_s)
    return pd.DataFrame(out)
