"""The truth of a JSBSim flight: the linear model linearised at the trim point from the
aircraft's own aerodynamic tables (``coefficients``), its check against JSBSim's
coefficients along the flight, and the statistics of the flight every info shares.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from aerosid.simulation.jsbsim_columns import DEG
from aerosid.simulation.jsbsim_tables import AeroTables, body_coefficients
from aerosid.simulation.sensors import IMU_COLUMNS

_LINEAR_VARS = ["alpha", "beta", "delta_p", "delta_r", "delta_y", "p_hat", "q_hat", "r_hat", "alpha_dot_hat"]


#: The central-difference step of the linear truth (every variable of _LINEAR_VARS).
STEP = 1e-4


def central_differences(evaluate, point: dict, h: float = STEP) -> dict[str, dict]:
    """{"value": C, "d": {variable: {coefficient: dC/dvariable}}} by central differences of
    ``evaluate`` (variables -> {coefficient: value}) at ``point``.  The point's variables may
    be arrays over a flight's samples (aerosid.simulation.jsbsim_truth_avg): every entry is
    then the mean over the samples; for scalars it is the plain central difference."""
    value = {k: float(np.mean(v)) for k, v in evaluate(point).items()}
    deriv = {}
    for var in _LINEAR_VARS:
        hi, lo = dict(point), dict(point)
        hi[var] = point[var] + h
        lo[var] = point[var] - h
        ch, cl = evaluate(hi), evaluate(lo)
        deriv[var] = {k: float(np.mean((np.asarray(ch[k]) - np.asarray(cl[k])) / (2 * h))) for k in value}
    return {"value": value, "d": deriv}


def _linearise(tables: AeroTables, point: dict, arm_ft, cbar_ft, span_ft) -> dict[str, dict[str, float]]:
    """Derivatives of CA, CY, CN and the moment coefficients (about the CG and the
    AERORP) at the trim point by central differences of c172x's own tables."""

    def evaluate(x):
        c = tables.coefficients(x["alpha"], x["beta"], x["delta_p"], x["delta_r"], x["delta_y"],
                                x["p_hat"], x["q_hat"], x["r_hat"], x["alpha_dot_hat"])
        return {k: float(v) for k, v in body_coefficients(c, x["alpha"], x["beta"], arm_ft, cbar_ft, span_ft).items()}

    return central_differences(evaluate, point)


_LINEAR_MODEL = {  # the regressors of each coefficient's linear model
    "CN": ["alpha", "q_hat", "delta_p", "alpha_dot_hat"],
    "CA": ["alpha", "delta_p"],
    "Cm": ["alpha", "q_hat", "delta_p", "alpha_dot_hat"],
    "CY": ["beta", "p_hat", "r_hat", "delta_r", "delta_y"],
    "Cl": ["beta", "p_hat", "r_hat", "delta_r", "delta_y"],
    "Cn": ["beta", "p_hat", "r_hat", "delta_r", "delta_y"],
}
_VAR_SUFFIX = {"alpha": "alpha", "beta": "beta", "delta_p": "delta_p", "delta_r": "delta_r", "delta_y": "delta_y",
               "p_hat": "p", "q_hat": "q", "r_hat": "r", "alpha_dot_hat": "alpha_dot"}


def _coefficient_table(lin: dict, point: dict, moment: str = "cg") -> dict[str, float]:
    """The linear truth: derivatives and intercepts (so that the linear model passes
    through the trim point).  moment="rp": the moments about the AERORP instead."""
    out = {}
    for coef, regs in _LINEAR_MODEL.items():
        key = coef if (moment == "cg" or coef in ("CN", "CA", "CY")) else f"{coef}_rp"
        intercept = lin["value"][key]
        for r in regs:
            d = lin["d"][r][key]
            out[f"{coef}_{_VAR_SUFFIX[r]}"] = d
            intercept -= d * point[r]
        out[f"{coef}_0"] = intercept
    out["Cm_q_plus_alpha_dot"] = out["Cm_q"] + out["Cm_alpha_dot"]
    return out


def _regressors(truth: pd.DataFrame, names: list[str]) -> np.ndarray:
    cols = {"alpha": "alpha_rad", "beta": "beta_rad", "delta_p": "delta_p_rad", "delta_r": "delta_r_rad",
            "delta_y": "delta_y_rad", "p_hat": "p_hat", "q_hat": "q_hat", "r_hat": "r_hat",
            "alpha_dot_hat": "alpha_dot_hat"}
    return np.column_stack([np.ones(len(truth))] + [truth[cols[n]].to_numpy() for n in names])


def linear_prediction(truth: pd.DataFrame, coefficients: dict, coef: str) -> np.ndarray:
    """A coefficient (CN, CA, Cm, CY, Cl, Cn) of the truth frame predicted by the linear truth."""
    regs = _LINEAR_MODEL[coef]
    X = _regressors(truth, regs)
    beta = np.array([coefficients[f"{coef}_0"]] + [coefficients[f"{coef}_{_VAR_SUFFIX[r]}"] for r in regs])
    return X @ beta


def _fit(truth: pd.DataFrame, table: dict, coef: str, regs: list[str], mask: np.ndarray,
         extra: dict[str, np.ndarray] | None = None) -> dict:
    X = _regressors(truth, regs)[mask]
    names = [f"{coef}_0"] + [f"{coef}_{_VAR_SUFFIX[r]}" for r in regs]
    for k, v in (extra or {}).items():
        X = np.column_stack([X, v[mask]])
        names.append(k)
    y = truth[coef].to_numpy()[mask]
    sol, *_ = np.linalg.lstsq(X, y, rcond=None)
    resid = y - X @ sol
    return {
        "regressors": ["1"] + regs + list(extra or {}),
        "n_samples": int(mask.sum()),
        "fit": {n: float(v) for n, v in zip(names, sol)},
        "table": {n: float(table[n]) for n in names if n in table},
        "rel_diff": {n: float((v - table[n]) / table[n]) for n, v in zip(names, sol)
                     if n in table and not n.endswith("_0") and table[n] != 0},
        "rms_residual": float(np.sqrt(np.mean(resid ** 2))),
        "std_signal": float(np.std(y)),
    }


def _truth_check(truth: pd.DataFrame, table: dict, t_lateral_s: float) -> dict:
    """Least-squares fits of the noise-free truth coefficients (about the CG) next to
    the transferred table values: Cm on [1, α, q̂, δp, α̇̂] and CN on [1, α, q̂, δp]
    over the longitudinal part of the flight (before the first lateral manoeuvre),
    over the whole flight, and over the whole flight with |β| as an extra regressor
    (c172x's drag grows with |β| and the AERORP sits 0.59 m above the CG, so the
    lateral manoeuvres move Cm about the CG by ~0.067 |β|); Cl and Cn on
    [1, β, p̂, r̂, δr, δy] over the whole flight."""
    t = truth["t_s"].to_numpy()
    lon = t < t_lateral_s
    every = np.ones(len(t), dtype=bool)
    abs_beta = {"Cm_abs_beta": np.abs(truth["beta_rad"].to_numpy())}
    m_regs = ["alpha", "q_hat", "delta_p", "alpha_dot_hat"]
    n_regs = ["alpha", "q_hat", "delta_p"]
    lat = ["beta", "p_hat", "r_hat", "delta_r", "delta_y"]
    return {
        "longitudinal_window_s": [float(t[0]), float(t_lateral_s)],
        "Cm": _fit(truth, table, "Cm", m_regs, lon),
        "CN": _fit(truth, table, "CN", n_regs, lon),
        "Cm_whole_flight": _fit(truth, table, "Cm", m_regs, every),
        "Cm_whole_flight_abs_beta": _fit(truth, table, "Cm", m_regs, every, abs_beta),
        "CN_whole_flight": _fit(truth, table, "CN", n_regs, every),
        "Cl": _fit(truth, table, "Cl", lat, every),
        "Cn": _fit(truth, table, "Cn", lat, every),
    }


def flight_statistics(truth, telemetry, masks, spec, sigma, t, dt, qbar_pa, alpha, beta, V) -> dict:
    """The part of a JSBSim flight's info every flight shares: sizes, faults, ranges of the
    flight condition and the pitch-plane signal-to-noise ratios."""
    deg = 1.0 / DEG
    return {
        "n_samples": int(len(t)), "sample_rate_hz": 1.0 / dt, "duration_s": float(t[-1]),
        "n_telemetry_rows": int(len(telemetry)),
        "n_dropout": int(masks["dropout"].sum()),
        "n_outliers": int(sum(masks[f"outlier_{c}"].sum() for c in IMU_COLUMNS)),
        "sync_gap_s": float(spec.sync_gap_s),
        "mach_min": float(truth["mach"].min()), "mach_max": float(truth["mach"].max()),
        "h_min_m": float(truth["h_m"].min()), "h_max_m": float(truth["h_m"].max()),
        "qbar_min_pa": float(np.min(qbar_pa)), "qbar_max_pa": float(np.max(qbar_pa)),
        "alpha_min_deg": float(np.min(alpha) * deg), "alpha_max_deg": float(np.max(alpha) * deg),
        "beta_min_deg": float(np.min(beta) * deg), "beta_max_deg": float(np.max(beta) * deg),
        "phi_min_deg": float(truth["phi_rad"].min() * deg), "phi_max_deg": float(truth["phi_rad"].max() * deg),
        "V_min_m_s": float(np.min(V)), "V_max_m_s": float(np.max(V)),
        "snr": {
            "az": float(truth["az_sensor_m_s2"].std() / sigma["az_m_s2"]),
            "q": float(truth["q_rad_s"].std() / sigma["q_rad_s"]),
            "ax": float(truth["ax_sensor_m_s2"].std() / sigma["ax_m_s2"]),
        },
    }
