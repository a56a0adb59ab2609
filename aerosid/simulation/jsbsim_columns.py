"""From JSBSim's records to aerosid's columns: the exact unit conversions, the state and
coefficient columns every JSBSim flight shares (jsbsim_flight.py and jsbsim_aircraft.py),
and the noisy telemetry with its faults.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from aerosid.simulation.case import ATTITUDE_NOISE_DEG, FaultSpec
from aerosid.simulation.sensors import (ATTITUDE_COLUMNS, IMU_COLUMNS, RAW_COLUMNS, apply_faults, attitude_angles,
                                       with_extra_channels)
from aerosid.vehicles.rigid_body import lever_arm_acceleration

VANE_COLUMNS = ["alpha_vane_rad", "beta_vane_rad"]
#: appended last, so each earlier channel keeps its own child of the seed (its noise unchanged)
TELEMETRY_COLUMNS = RAW_COLUMNS + VANE_COLUMNS + ATTITUDE_COLUMNS

# unit conversions (exact definitions)
FT = 0.3048                    # m
INCH = 0.0254                  # m
LBF = 4.4482216152605          # N
SLUG = LBF / FT                # kg (14.5939...)
SLUG_FT2 = SLUG * FT * FT      # kg m^2
PSF = LBF / (FT * FT)          # Pa
SLUG_FT3 = SLUG / FT**3        # kg/m^3
DEG = math.pi / 180.0


def sensor_sigma(sens: dict) -> dict[str, float]:
    """1-sigma noise per telemetry channel from a [sensors] table (simulation.toml)."""
    sigma = dict(zip(IMU_COLUMNS, (*sens["accel_noise_m_s2"], *(g * DEG for g in sens["gyro_noise_deg_s"]))))
    sigma.update({f"d{i}_rad": sens["surface_noise_deg"] * DEG for i in range(1, 5)})
    sigma.update({"V_m_s": sens["V_noise_m_s"], "h_m": sens["h_noise_m"],
                  "alpha_vane_rad": sens["vane_noise_deg"] * DEG, "beta_vane_rad": sens["vane_noise_deg"] * DEG})
    sigma.update({c: sens.get("attitude_noise_deg", ATTITUDE_NOISE_DEG) * DEG for c in ATTITUDE_COLUMNS})
    return sigma


def make_telemetry(clean: dict[str, np.ndarray], truth: pd.DataFrame, sens: dict, fcfg: dict, seed: int,
                   faults: bool):
    """Noise ([sensors]) and faults ([faults]) on the clean signals and on the attitude of `truth`
    (phi_rad, theta_rad: the INS's, ATTITUDE_COLUMNS): each channel's noise
    from its own child of SeedSequence(seed).  Adds the fault masks (fault_*) and the
    noise actually added (noise_*) to `truth`.  Returns (telemetry, masks, FaultSpec, sigma)."""
    t = clean["t_s"]
    n = len(t)
    clean = {**clean, **{c: truth[c].to_numpy() for c in ATTITUDE_COLUMNS}}  # the INS's attitude: the true one
    sigma = sensor_sigma(sens)
    channels = TELEMETRY_COLUMNS[1:]
    children = np.random.SeedSequence(seed).spawn(2 + len(channels))
    rng_drop, rng_out = np.random.default_rng(children[0]), np.random.default_rng(children[1])
    noisy = {"t_s": t.copy()}
    for child, col in zip(children[2:], channels):
        noisy[col] = clean[col] + sigma[col] * np.random.default_rng(child).standard_normal(n)
    noisy.update(attitude_angles(noisy["phi_rad"], noisy["theta_rad"]))
    spec = FaultSpec(
        dropout_rate_per_s=fcfg["dropout_rate_per_s"], dropout_length_s=tuple(fcfg["dropout_length_s"]),
        dropout_nan_fraction=fcfg["dropout_nan_fraction"], outlier_probability=fcfg["outlier_probability"],
        outlier_size_sigma=tuple(fcfg["outlier_size_sigma"]), sync_gap_at=fcfg["sync_gap_at"],
        sync_gap_s=fcfg["sync_gap_s"])
    if not faults:
        spec = spec.without_faults()
    sigma_imu = np.array([sigma[c] for c in IMU_COLUMNS])
    telemetry, masks = apply_faults({c: noisy[c] for c in RAW_COLUMNS}, sigma_imu, spec, rng_drop, rng_out)
    telemetry = with_extra_channels(telemetry, masks, noisy, VANE_COLUMNS + ATTITUDE_COLUMNS)[TELEMETRY_COLUMNS]
    for col in masks.columns[1:]:
        truth[f"fault_{col}"] = masks[col].to_numpy()
    for col in channels:
        truth[f"noise_{col}"] = noisy[col] - clean[col]
    return telemetry, masks, spec, sigma


def rates_at_the_moments(x: np.ndarray, x_dot: np.ndarray, dt: float) -> np.ndarray:
    """Body rates re-timed to the instant of the sample's moments.

    JSBSim integrates the body rates with rectangular Euler (its default
    simulation/integrator/rate/rotational = 1): x[k+1] = x[k] + dt x_dot[k], where
    x_dot[k] comes from the moments of sample k.  Those moments therefore act at
    t_k + dt/2 as far as the rates are concerned: the logged rates run half a step late
    relative to the logged moments and accelerations (a derivative of the logged q is
    (q_dot[k-1] + q_dot[k])/2, not q_dot[k]; docs/jsbsim.md).  The rate at t_k + dt/2 is
    exactly x[k] + dt/2 x_dot[k] (x is linear over the step); as the gyros' reading at
    sample k, its derivative matches the moment of sample k."""
    return x + 0.5 * dt * x_dot

#: rec key of JSBSim's body-rate integrator during the flight (jsbsim_flight._fly records it,
#: :func:`state_columns` reads it)
INTEGRATOR_KEY = "simulation/integrator/rate/rotational"


def state_columns(rec: dict, t: np.ndarray, dt: float, accel_offset_m) -> tuple[dict, np.ndarray]:
    """The truth columns every JSBSim flight shares, from its record: air data, attitude, the
    gyros' rates (with _fly's Adams-Bashforth 2 the state JSBSim's aerodynamics used, whose
    central difference is centred on the sample's moments; with rectangular Euler re-timed half
    a step, :func:`rates_at_the_moments`; the state stays in p/q/r_state_rad_s), angular accelerations, the specific force at the CG (all external
    non-gravitational forces / mass: JSBSim's forces/fb*-total are aero + propulsion + ground +
    external) and at the accelerometer (offset [m], body axes), alpha, beta, alpha-dot.
    Returns (columns in the truth frame's order, mass [kg] per sample)."""
    mass_kg = rec["inertia/mass-slugs"] * SLUG
    xdot = [rec[f"accelerations/{a}dot-rad_sec2"] for a in "pqr"]
    state = [rec[f"velocities/{a}-rad_sec"] for a in "pqr"]
    if INTEGRATOR_KEY in rec and int(rec[INTEGRATOR_KEY][0]) != 1:  # AB2 (_fly): the state is centred already
        p, q, r = state
    else:  # rectangular Euler: re-timed half a step
        p, q, r = (rates_at_the_moments(x, xd, dt) for x, xd in zip(state, xdot))
    f_cg = [rec[f"forces/fb{a}-total-lbs"] * LBF / mass_kg for a in "xyz"]
    f_sensor = [f + lv for f, lv in zip(f_cg, lever_arm_acceleration(p, q, r, *xdot, accel_offset_m))]
    cols = {
        "t_s": t,
        "h_m": rec["position/h-sl-ft"] * FT, "V_m_s": rec["velocities/vt-fps"] * FT, "mach": rec["velocities/mach"],
        "qbar_pa": rec["aero/qbar-psf"] * PSF,
        "rho_kg_m3": rec["atmosphere/rho-slugs_ft3"] * SLUG_FT3, "g_m_s2": rec["accelerations/gravity-ft_sec2"] * FT,
        "phi_rad": rec["attitude/phi-rad"], "theta_rad": rec["attitude/theta-rad"], "psi_rad": rec["attitude/psi-rad"],
        "p_rad_s": p, "q_rad_s": q, "r_rad_s": r,
        "p_state_rad_s": state[0], "q_state_rad_s": state[1], "r_state_rad_s": state[2],
        "p_dot_rad_s2": xdot[0], "q_dot_rad_s2": xdot[1], "r_dot_rad_s2": xdot[2],
        "ax_cg_m_s2": f_cg[0], "ay_cg_m_s2": f_cg[1], "az_cg_m_s2": f_cg[2],
        "ax_sensor_m_s2": f_sensor[0], "ay_sensor_m_s2": f_sensor[1], "az_sensor_m_s2": f_sensor[2],
        "alpha_rad": rec["aero/alpha-rad"], "beta_rad": rec["aero/beta-rad"],
        "alpha_dot_rad_s": rec["aero/alphadot-rad_sec"],
    }
    return cols, mass_kg


def coefficient_columns(rec: dict, S_ft2: float, cbar_ft: float, b_ft: float) -> dict:
    """The aerodynamic force and moment coefficients (moments about the CG) and the
    propulsive ones, non-dimensionalised alike (the accelerometers and gyros feel both)."""
    qS_lbs = rec["aero/qbar-psf"] * S_ft2
    return {
        "CA": -rec["forces/fbx-aero-lbs"] / qS_lbs, "CY": rec["forces/fby-aero-lbs"] / qS_lbs,
        "CN": -rec["forces/fbz-aero-lbs"] / qS_lbs,
        "Cl": rec["moments/l-aero-lbsft"] / (qS_lbs * b_ft), "Cm": rec["moments/m-aero-lbsft"] / (qS_lbs * cbar_ft),
        "Cn": rec["moments/n-aero-lbsft"] / (qS_lbs * b_ft),
        "CX_prop": rec["forces/fbx-prop-lbs"] / qS_lbs, "CZ_prop": rec["forces/fbz-prop-lbs"] / qS_lbs,
        "Cl_prop": rec["moments/l-prop-lbsft"] / (qS_lbs * b_ft),
        "Cm_prop": rec["moments/m-prop-lbsft"] / (qS_lbs * cbar_ft),
        "Cn_prop": rec["moments/n-prop-lbsft"] / (qS_lbs * b_ft),
    }
