"""Simulated flights with known truth (``aerosid simulate``).

``simulate(case, effects, seed)`` flies the 6-DOF model, derives the SDINS and
fin telemetry, adds noise and faults, and returns a ``SimulatedFlight`` holding
the raw telemetry (as a flight would deliver it), the per-sample truth and the
true flight coefficients (SI per radian, moments about the CG).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from aerosid.modelling.aeromodel import AeroModel, flight_signals
from aerosid.modelling.effects import Effect
from aerosid.vehicles.rigid_body import body_rate_derivatives, lever_arm_acceleration
from aerosid.simulation.case import SimulationCase, load_case
from aerosid.simulation.dynamics import Plant, aero_angles, euler_from_quat, integrate, quat_from_euler, quat_to_dcm, schedule
from aerosid.simulation.sensors import (ATTITUDE_COLUMNS, IMU_COLUMNS, apply_faults, attitude_angles, noisy_channels,
                                       with_extra_channels)

__all__ = ["SimulatedFlight", "simulate", "load_case", "flight_model"]


@dataclass(frozen=True)
class SimulatedFlight:
    """A simulated flight: raw telemetry, per-sample truth and the true coefficients."""

    case: str
    seed: int
    effects: tuple[tuple[str, float], ...]
    telemetry: pd.DataFrame
    truth: pd.DataFrame
    coefficients: dict[str, float]
    info: dict = field(default_factory=dict)
    #: other files that belong with the telemetry, name -> text (a generated vehicle.toml)
    files: dict[str, str] = field(default_factory=dict)
    #: uncatalogued effects (aerosid.simulation.hidden): their truth.json entries
    hidden: tuple = ()

    def truth_document(self) -> dict:
        """The content of truth.json."""
        return {
            "case": self.case,
            "seed": self.seed,
            "units": self.info.get("units", "SI per radian; moments about the CG; pitch/yaw fin terms per radian "
                                            "of delta/2"),
            "moment_reference": "cg",
            "effects": [{"name": n, "scale": s} for n, s in self.effects],
            "coefficients": self.coefficients,
            "info": self.info,
            **({"hidden_effects": list(self.hidden)} if self.hidden else {}),
        }

    def summary(self) -> str:
        i = self.info
        at = f" at M {i['mach_reference']:.3g}" if "mach_reference" in i else ""
        lines = [
            f"simulated flight {self.case} seed {self.seed}, effects: "
            f"{', '.join(f'{n}x{s:g}' for n, s in self.effects) or 'none'}"
            + (f"; not in the diagnosis catalogue: {_hidden_names(self.hidden)}" if self.hidden else ""),
            f"  {i['n_samples']} samples at {i['sample_rate_hz']:g} Hz, {len(self.telemetry)} telemetry rows "
            f"({i['n_dropout']} dropout samples, {i['n_outliers']} outliers, sync gap {i['sync_gap_s']:g} s)",
            f"  Mach {i['mach_min']:.2f}..{i['mach_max']:.2f}, h {i['h_min_m'] / 1e3:.1f}..{i['h_max_m'] / 1e3:.1f} km, "
            f"qbar {i['qbar_min_pa'] / 1e3:.1f}..{i['qbar_max_pa'] / 1e3:.1f} kPa, alpha {i['alpha_min_deg']:.2f}..{i['alpha_max_deg']:.2f} deg",
            f"  pitch-plane SNR{at} (std of true manoeuvre signal / noise sigma): "
            + ", ".join(f"{k} {v:.2f}" for k, v in i["snr"].items()),
        ]
        air = i.get("turbulence", {})
        if air.get("level", "none") != "none":
            lines.append(f"  turbulence: {air['level']} ({air.get('model', '')}, severity index "
                         f"{air.get('severity_index')}): analyse with [estimation] turbulent_air = true in the vehicle file")
        return "\n".join(lines)

    def write(self, out_dir: str | Path) -> dict[str, Path]:
        """Write telemetry.parquet, truth.parquet and truth.json (and `files`, e.g. a
        generated vehicle.toml, which the telemetry's metadata then names as
        ``aerosid.vehicle``, a path relative to the telemetry) atomically into out_dir."""
        from aerosid.io import write_json_atomic, write_parquet_atomic, write_text_atomic

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        meta = {"aerosid.kind": "raw_telemetry", "aerosid.case": self.case, "aerosid.seed": str(self.seed),
                "aerosid.sample_rate_hz": str(self.info["sample_rate_hz"])}
        extra = {name: write_text_atomic(text, out / name) for name, text in self.files.items()}
        if "vehicle.toml" in self.files:
            meta["aerosid.vehicle"] = "vehicle.toml"
        paths = {
            **{Path(name).stem: path for name, path in extra.items()},
            "telemetry": write_parquet_atomic(self.telemetry, out / "telemetry.parquet", metadata=meta),
            "truth": write_parquet_atomic(self.truth, out / "truth.parquet", metadata={"aerosid.kind": "truth"}),
            "truth_json": write_json_atomic(self.truth_document(), out / "truth.json"),
        }
        return paths


def _hidden_names(hidden) -> str:
    return ", ".join(f"{h['name']}x{h['scale']:g}" for h in hidden)


def flight_model(case: SimulationCase, effects: tuple[tuple[Effect, float], ...] = ()) -> AeroModel:
    """The true flight aerodynamics: preflight + the case's deviations + hidden effects."""
    return AeroModel.preflight(case.vehicle).with_deviations(**case.deviations).with_effects(effects)


def _initial_state(case: SimulationCase, model: AeroModel) -> np.ndarray:
    ap = case.autopilot
    # trim alpha with the trim fin: Cm_0 + Cm_alpha alpha + Cm_delta_p dp/2 = 0 (about the CG)
    truth = model.linear_truth()
    alpha0 = -(truth["Cm_0"] + truth["Cm_delta_p"] * ap["delta_p_half_trim_rad"]) / truth["Cm_alpha"]
    theta0 = case.gamma0_rad + alpha0
    q = quat_from_euler(0.0, theta0, case.heading0_rad)
    vn = case.V0_m_s * math.cos(case.gamma0_rad) * math.cos(case.heading0_rad)
    ve = case.V0_m_s * math.cos(case.gamma0_rad) * math.sin(case.heading0_rad)
    vd = -case.V0_m_s * math.sin(case.gamma0_rad)
    return np.array([0.0, 0.0, -case.h0_m, vn, ve, vd, *q, 0.0, 0.0, 0.0])


def _controller(case: SimulationCase):
    ap, veh = case.autopilot, case.vehicle
    limit = veh.fin_limit_rad

    gamma_integral = [0.0, 0.0]  # integral of the flight-path error [rad s], time of the last call [s]
    # a designed input (aerosid design, `simulate --input`) replaces the plan of its axis
    # (zero outside the input's time span); the autopilot and guidance stay in the loop
    tables = {k: (np.asarray(v[0], float), np.asarray(v[1], float)) for k, v in case.inputs.items()}

    def plan(t: float, key: str, plan, factor: float) -> float:
        if key in tables:
            ti, vi = tables[key]
            return factor * float(np.interp(t, ti, vi, left=0.0, right=0.0))
        return schedule(t, plan, case.period_s, case.ramp_s)

    def control(t: float, x: np.ndarray):
        q0, q1, q2, q3 = x[6:10]
        p, q, r = x[10:13]
        phi = math.atan2(2 * (q0 * q1 + q2 * q3), 1 - 2 * (q1 * q1 + q2 * q2))
        # guidance: a slow PI loop on the flight-path angle following a gently
        # descending command, so that long flights glide instead of diving in
        gamma = math.asin(-x[5] / math.sqrt(x[3] ** 2 + x[4] ** 2 + x[5] ** 2))
        gamma_cmd = max(ap["gamma_floor_rad"], case.gamma0_rad - ap["gamma_rate_rad_s"] * t)
        err = gamma_cmd - gamma
        gamma_integral[0] += err * (t - gamma_integral[1])
        gamma_integral[1] = t
        guidance = ap["kgamma"] * err + ap["kgamma_i"] * gamma_integral[0]
        dp_half = (ap["delta_p_half_trim_rad"] + guidance + plan(t, "delta_p_cmd_rad", case.pitch_plan, 0.5)
                   - ap["kq"] * q)
        phi_cmd = plan(t, "phi_cmd_rad", case.roll_plan, 1.0)
        dr = ap["kphi"] * (phi - phi_cmd) + ap["kp"] * p
        dy_half = plan(t, "delta_y_cmd_rad", case.yaw_plan, 0.5) - ap["kr"] * r
        fins = np.clip(veh.unmix(dr, 2.0 * dp_half, 2.0 * dy_half), -limit, limit)
        delta_r, delta_p, delta_y = veh.mix(*fins)
        return delta_p, delta_y, delta_r

    return control


def simulate(case: SimulationCase | str = "seed-rlv", effects: tuple[tuple[Effect, float], ...] = (),
             seed: int = 0, progress=None, hidden: tuple = ()) -> SimulatedFlight:
    """Fly the case with the given hidden effects; noise and faults from `seed`.
    progress: an optional callback progress(stage, fraction) (the CLI's display).
    hidden: ((HiddenEffect, scale), ...) effects outside the diagnosis catalogue
    (aerosid.simulation.hidden), for testing the diagnosis' localisation."""
    from aerosid.simulation.hidden import lagged_controller, with_hidden

    if isinstance(case, str):
        case = load_case(case)
    veh = case.vehicle
    model = with_hidden(flight_model(case, effects), hidden)
    plant = Plant(veh, model)
    n = int(round(case.duration_s * case.sample_rate_hz)) + 1
    t = np.arange(n) / case.sample_rate_hz
    controller = _controller(case)
    if hidden:
        controller = lagged_controller(controller, model.lag_s(), case.sample_rate_hz)
    states, controls = integrate(plant, _initial_state(case, model), t, controller, progress)

    truth = truth_frame(plant, t, states, controls)
    clean = {"t_s": t}
    for col in IMU_COLUMNS[:3]:
        clean[col] = truth[f"{col[:2]}_sensor_m_s2"].to_numpy()
    for col, src in zip(IMU_COLUMNS[3:], ("p_rad_s", "q_rad_s", "r_rad_s")):
        clean[col] = truth[src].to_numpy()
    fins = np.stack([veh.unmix(*c) for c in controls[:, [2, 0, 1]]])
    for i in range(4):
        clean[f"d{i + 1}_rad"] = fins[:, i]
    clean["V_m_s"] = truth["V_m_s"].to_numpy()
    clean["h_m"] = truth["h_m"].to_numpy()

    # the attitude's noise has the fourth child: the other channels' draws are those of a flight without it
    children = np.random.SeedSequence(seed).spawn(4)
    rng_noise, rng_drop, rng_out, rng_att = (np.random.default_rng(c) for c in children)
    noisy = noisy_channels(clean, case.sensors, rng_noise)
    sigma_imu = np.array([*case.sensors.accel_noise_m_s2, *case.sensors.gyro_noise_rad_s])
    telemetry, masks = apply_faults(noisy, sigma_imu, case.faults, rng_drop, rng_out)
    attitude = attitude_angles(*(truth[c].to_numpy() + case.sensors.attitude_noise_rad * rng_att.standard_normal(n)
                                 for c in ATTITUDE_COLUMNS))
    telemetry = with_extra_channels(telemetry, masks, attitude, ATTITUDE_COLUMNS)
    for col in masks.columns[1:]:
        truth[f"fault_{col}"] = masks[col].to_numpy()
    # ground truth of the noise actually added, for checks downstream
    for col in IMU_COLUMNS:
        truth[f"noise_{col}"] = noisy[col] - clean[col]
    for col in ATTITUDE_COLUMNS:
        truth[f"noise_{col}"] = attitude[col] - truth[col].to_numpy()

    info = flight_info(case, truth, telemetry)
    return SimulatedFlight(
        case=case.name,
        seed=int(seed),
        effects=tuple((e.name, float(s)) for e, s in effects),
        telemetry=telemetry,
        truth=truth,
        coefficients=model.linear_truth(),
        info=info,
        hidden=tuple(e.truth(model, float(sc)) for e, sc in hidden),
    )


def truth_frame(plant: Plant, t: np.ndarray, states: np.ndarray, controls: np.ndarray) -> pd.DataFrame:
    """Per-sample truth on the full sample grid (vectorised re-evaluation of the plant)."""
    veh, model = plant.vehicle, plant.model
    q0, q1, q2, q3 = states[:, 6:10].T
    p, q, r = states[:, 10:13].T
    C = quat_to_dcm(q0, q1, q2, q3)  # (3,3,N)
    v_body = np.einsum("jin,nj->ni", C, states[:, 3:6])
    V, alpha_r, phi_r = aero_angles(*v_body.T)
    h = -states[:, 2]
    atm = [plant.atmosphere(hk) for hk in h]
    rho = np.array([a[0] for a in atm])
    a_sound = np.array([a[1] for a in atm])
    mach = V / a_sound
    qbar = 0.5 * rho * V * V
    dp, dy, dr = controls[:, :3].T
    c = model.coefficients(alpha_r, phi_r, mach, dp, dy, dr, p, q, r, V, qbar, *controls[:, 3:].T)
    qs = qbar * veh.S_m2
    fx, fy, fz = -c["CA"] * qs / veh.mass_kg, c["CY"] * qs / veh.mass_kg, -c["CN"] * qs / veh.mass_kg
    L_hat = c["Cl"] * qs * veh.d_m / veh.Ixx_kg_m2
    M_hat = c["Cm"] * qs * veh.d_m / veh.Iyy_kg_m2
    N_hat = c["Cn"] * qs * veh.d_m / veh.Izz_kg_m2
    pd_, qd_, rd_ = body_rate_derivatives(p, q, r, L_hat, M_hat, N_hat, veh.inertia)
    lx, ly, lz = lever_arm_acceleration(p, q, r, pd_, qd_, rd_, veh.accel_offset_m)
    sig = flight_signals(alpha_r, phi_r, mach, dp, dy, dr, p, q, r, V, qbar, veh.d_m)
    phi, theta, psi = euler_from_quat(q0, q1, q2, q3)
    return pd.DataFrame({
        "t_s": t,
        "north_m": states[:, 0], "east_m": states[:, 1], "h_m": h,
        "V_m_s": V, "mach": mach, "qbar_pa": qbar, "rho_kg_m3": rho,
        "phi_rad": phi, "theta_rad": theta, "psi_rad": psi,
        "p_rad_s": p, "q_rad_s": q, "r_rad_s": r,
        "p_dot_rad_s2": pd_, "q_dot_rad_s2": qd_, "r_dot_rad_s2": rd_,
        "L_hat_rad_s2": L_hat, "M_hat_rad_s2": M_hat, "N_hat_rad_s2": N_hat,
        "ax_cg_m_s2": fx, "ay_cg_m_s2": fy, "az_cg_m_s2": fz,
        "ax_sensor_m_s2": fx + lx, "ay_sensor_m_s2": fy + ly, "az_sensor_m_s2": fz + lz,
        "alpha_rad": sig["alpha"], "beta_rad": sig["beta"], "alpha_r_rad": alpha_r, "phi_r_rad": phi_r,
        "delta_p_rad": dp, "delta_y_rad": dy, "delta_r_rad": dr,
        "CA": c["CA"], "CY": c["CY"], "CN": c["CN"], "Cl": c["Cl"], "Cm": c["Cm"], "Cn": c["Cn"],
    })


def flight_info(case: SimulationCase, truth: pd.DataFrame, telemetry: pd.DataFrame) -> dict:
    """Numbers for the summary and truth.json: envelope and pitch-plane SNR near M 12.4."""
    near = (truth["mach"] - case.vehicle.mach_reference).abs() < 0.3
    seg = truth[near] if near.sum() > 100 else truth
    s = case.sensors
    snr = {
        "az": float(seg["az_sensor_m_s2"].std() / s.accel_noise_m_s2[2]),
        "q": float(seg["q_rad_s"].std() / s.gyro_noise_rad_s[1]),
        "ax": float(seg["ax_sensor_m_s2"].std() / s.accel_noise_m_s2[0]),
    }
    deg = 180.0 / math.pi
    return {
        "n_samples": int(len(truth)),
        "sample_rate_hz": case.sample_rate_hz,
        "n_dropout": int(truth["fault_dropout"].sum()),
        "n_outliers": int(sum(truth[f"fault_outlier_{c}"].sum() for c in IMU_COLUMNS)),
        "sync_gap_s": case.faults.sync_gap_s,
        "mach_min": float(truth["mach"].min()), "mach_max": float(truth["mach"].max()),
        "h_min_m": float(truth["h_m"].min()), "h_max_m": float(truth["h_m"].max()),
        "qbar_min_pa": float(truth["qbar_pa"].min()), "qbar_max_pa": float(truth["qbar_pa"].max()),
        "alpha_min_deg": float(truth["alpha_rad"].min() * deg), "alpha_max_deg": float(truth["alpha_rad"].max() * deg),
        "snr": snr,
        "mach_reference": case.vehicle.mach_reference,
        "noise_sigma": {"accel_m_s2": list(s.accel_noise_m_s2), "gyro_rad_s": list(s.gyro_noise_rad_s),
                        "attitude_rad": s.attitude_noise_rad},
    }
