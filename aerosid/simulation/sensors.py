"""SDINS and control-system telemetry from the true flight: noise and faults.

Every random draw comes from its own child of one ``numpy.random.SeedSequence``
so a seed reproduces a flight exactly and changing one fault setting does not
reshuffle the noise of the others.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from aerosid.simulation.case import FaultSpec, SensorSpec

RAW_COLUMNS = ["t_s", "ax_m_s2", "ay_m_s2", "az_m_s2", "p_rad_s", "q_rad_s", "r_rad_s",
               "d1_rad", "d2_rad", "d3_rad", "d4_rad", "V_m_s", "h_m"]
IMU_COLUMNS = RAW_COLUMNS[1:7]
#: The inertial navigation system's roll and pitch attitude [rad]: optional raw columns that the
#: estimation does not read (its 21-state model carries no attitude); ``aerosid validate`` and
#: ``aerosid refine`` need them for the gravity terms of their simulation.
ATTITUDE_COLUMNS = ["phi_rad", "theta_rad"]


def noisy_channels(clean: dict[str, np.ndarray], spec: SensorSpec, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Add white Gaussian noise of the configured 1-sigma to every channel."""
    sigma = dict(zip(IMU_COLUMNS, (*spec.accel_noise_m_s2, *spec.gyro_noise_rad_s)))
    sigma.update({f"d{i}_rad": spec.fin_noise_rad for i in range(1, 5)})
    sigma.update({"V_m_s": spec.V_noise_m_s, "h_m": spec.h_noise_m})
    n = len(clean["t_s"])
    out = {"t_s": clean["t_s"].copy()}
    for col in RAW_COLUMNS[1:]:
        out[col] = clean[col] + sigma[col] * rng.standard_normal(n)
    return out


def dropout_mask(t: np.ndarray, spec: FaultSpec, rng: np.random.Generator) -> np.ndarray:
    """Bursts of loss of all channels: a Poisson process of starts with uniform lengths."""
    duration = t[-1] - t[0]
    n_bursts = rng.poisson(spec.dropout_rate_per_s * duration)
    mask = np.zeros(len(t), dtype=bool)
    starts = rng.uniform(t[0], t[-1], n_bursts)
    lengths = rng.uniform(*spec.dropout_length_s, n_bursts)
    for s, length in zip(starts, lengths):
        mask |= (t >= s) & (t < s + length)
    return mask


def sync_gap_mask(t: np.ndarray, spec: FaultSpec) -> np.ndarray:
    start = t[0] + spec.sync_gap_at * (t[-1] - t[0])
    return (t >= start) & (t < start + spec.sync_gap_s)


def apply_faults(noisy: dict[str, np.ndarray], sigma_imu: np.ndarray, spec: FaultSpec,
                 rng_drop: np.random.Generator, rng_out: np.random.Generator):
    """Returns (telemetry frame, fault masks frame on the full grid)."""
    t = noisy["t_s"]
    n = len(t)
    drop = dropout_mask(t, spec, rng_drop)
    as_nan = drop & (rng_drop.uniform(size=n) < spec.dropout_nan_fraction)
    sync = sync_gap_mask(t, spec)
    missing_row = (drop & ~as_nan) | sync
    masks = {"t_s": t, "dropout": drop | sync, "dropout_missing_row": missing_row, "dropout_nan": as_nan & ~sync,
             "sync_gap": sync}
    data = {k: v.copy() for k, v in noisy.items()}
    for j, col in enumerate(IMU_COLUMNS):
        hit = rng_out.uniform(size=n) < spec.outlier_probability
        size = rng_out.uniform(*spec.outlier_size_sigma, n) * sigma_imu[j]
        sign = np.where(rng_out.uniform(size=n) < 0.5, -1.0, 1.0)
        data[col] = np.where(hit, data[col] + sign * size, data[col])
        masks[f"outlier_{col}"] = hit & ~(drop | sync)
    for col in RAW_COLUMNS[1:]:
        data[col][masks["dropout_nan"]] = np.nan
    frame = pd.DataFrame({c: data[c] for c in RAW_COLUMNS})[~missing_row].reset_index(drop=True)
    return frame, pd.DataFrame(masks)


def attitude_angles(phi_rad: np.ndarray, theta_rad: np.ndarray) -> dict[str, np.ndarray]:
    """Noisy roll and pitch attitude [rad] as an INS reports them: phi wrapped into [-pi, pi),
    theta kept within +-pi/2 (noise near a limit must not read as a wrong unit)."""
    phi = np.asarray(phi_rad, float)
    return {"phi_rad": (phi + np.pi) % (2 * np.pi) - np.pi,
            "theta_rad": np.clip(np.asarray(theta_rad, float), -np.pi / 2, np.pi / 2)}


def with_extra_channels(telemetry: pd.DataFrame, masks: pd.DataFrame, noisy: dict[str, np.ndarray],
                        columns) -> pd.DataFrame:
    """The telemetry with the noisy full-grid `columns` (not in RAW_COLUMNS) appended under the
    same dropouts: NaN on the rows delivered as NaN, gone with the missing rows."""
    keep = ~masks["dropout_missing_row"].to_numpy()
    nan_rows = masks["dropout_nan"].to_numpy()
    out = telemetry.copy()
    for col in columns:
        v = np.array(noisy[col], dtype=float)
        v[nan_rows] = np.nan
        out[col] = v[keep]
    return out


def with_measured_air_data(telemetry: pd.DataFrame, pressure_factor: float = 1.04,
                           temperature_offset_K: float = -12.0) -> pd.DataFrame:
    """The telemetry with measured air data where it has none, on a day that is not the standard one
    but obeys the gas law (a real day's): static pressure p_static_pa = pressure_factor x US-1976's at
    h_m, static temperature US-1976's + temperature_offset_K, density rho_kg_m3 = p / (R T), total
    temperature T_total_K = T + V^2/(2 c_p), dynamic pressure qbar_pa = 0.5 rho V^2.  The defaults: a
    cold high-pressure day, 4 % above the standard pressure and 12 K below its temperature, 9 %
    denser.  Columns it already has (a real flight's) are kept."""
    from aerosid.vehicles.atmosphere import CP_AIR_J_KG_K, H_MAX_M, H_MIN_M, R_AIR_J_KG_K, pressure_pa, temperature_K

    out = telemetry.copy()
    h = np.clip(np.nan_to_num(out["h_m"].to_numpy(float), nan=0.0), H_MIN_M, H_MAX_M)
    V = out["V_m_s"].to_numpy(float)
    p, T = pressure_factor * pressure_pa(h), temperature_K(h) + temperature_offset_K
    if "rho_kg_m3" not in out:
        out["rho_kg_m3"] = p / (R_AIR_J_KG_K * T)
    if "qbar_pa" not in out:
        out["qbar_pa"] = 0.5 * out["rho_kg_m3"].to_numpy(float) * V**2
    if "p_static_pa" not in out:
        out["p_static_pa"] = p
    if "T_total_K" not in out:
        out["T_total_K"] = T + V**2 / (2.0 * CP_AIR_J_KG_K)
    return out
