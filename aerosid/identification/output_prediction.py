"""Output prediction: fly the identified model through another manoeuvre.

The model is simulated driven by the manoeuvre's MEASURED controls, airspeed,
dynamic pressure and attitude, from its measured initial state, and its outputs
are compared with the measured ones, as SIDPAC checks a Twin Otter model
(identify on one manoeuvre, predict another; Morelli & Klein, *Aircraft System
Identification*, the totter demo's ``nldyn`` prediction).  Two axes, simulated
separately so that a poor model of one axis does not spoil the other:

* ``lon``: states alpha, q; beta, p, r measured; CN and Cm from the model;
  outputs alpha [rad], q [rad/s], a_z [m/s^2] at the accelerometer.
* ``lat``: states beta, p, r; alpha, q measured; CY, Cl, Cn from the model;
  outputs beta, p, r, a_y at the accelerometer.

Equations (body axes, V measured so V-dot is not a state; specific forces from the
model for the simulated axis, from the manoeuvre's smoothed flight data for the
other; gravity g(h) along the measured attitude, less the centrifugal relief
(V cos gamma)^2/(R_E + h) the seed-rlv simulator applies)::

    u, v, w = V cos a cos b, V sin b, V sin a cos b
    u' = r v - q w + a_x - g sin(theta)
    v' = p w - r u + a_y + g sin(phi) cos(theta)
    w' = q u - p v + a_z + g cos(phi) cos(theta)
    alpha' = (u w' - w u')/(u^2 + w^2)        beta' = (V v' - v V')/(V^2 cos b),  V' = (u u' + v v' + w w')/V
    a_z = -CN qbar S/m,  a_y = CY qbar S/m
    p', q', r' = Euler's equations (aerosid.vehicles.rigid_body) with L = Cl qbar S b, M = Cm qbar S c, N = Cn qbar S b

Integration: classical RK4 on the sample grid (sub-steps of at most ``MAX_STEP_S``),
inputs linear between samples.  Terms that read alpha_dot_hat (beta_dot_hat) in
the force channel are solved by fixed-point iteration.

Bias treatment (``BIAS_MODES``), because trim, sensor biases and the model's
intercepts differ from manoeuvre to manoeuvre:

* ``none``: the model as identified; nothing adjusted.
* ``offsets``: then a constant per output and span, the mean of measured minus
  predicted, is added (what SIDPAC's totter demo does before it plots the
  prediction: ``bias = ones \\ (z - yp)``).  The default.
* ``intercepts``: the simulated channels' constant terms (CN_0, Cm_0, ...) are
  re-estimated on this manoeuvre by output error (least squares, each output
  scaled by its measured standard deviation), plus the output offsets; every
  other coefficient stays as identified.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy.optimize import least_squares

from aerosid.identification.identified import IdentifiedModel, weighted_sum
from aerosid.identification.inversion import total_angles
from aerosid.vehicles.rigid_body import body_rate_derivatives, lever_arm_acceleration
from aerosid.vehicles.vehicle import Vehicle

AXES = ("lon", "lat")
BIAS_MODES = ("none", "offsets", "intercepts")
#: simulated channels and outputs per axis
AXIS_CHANNELS = {"lon": ("CN", "Cm"), "lat": ("CY", "Cl", "Cn")}
AXIS_OUTPUTS = {"lon": ("alpha_rad", "q_rad_s", "az_m_s2"), "lat": ("beta_rad", "p_rad_s", "r_rad_s", "ay_m_s2")}
OUTPUT_UNITS = {"alpha_rad": "rad", "beta_rad": "rad", "p_rad_s": "rad/s", "q_rad_s": "rad/s", "r_rad_s": "rad/s",
                "az_m_s2": "m/s^2", "ay_m_s2": "m/s^2"}
#: columns a prediction-inputs frame must hold (see prediction_inputs)
INPUT_COLUMNS = ("t_s", "span", "V_m_s", "mach", "qbar_pa", "g_m_s2", "phi_rad", "theta_rad",
                 "delta_p_rad", "delta_y_rad", "delta_r_rad", "alpha_rad", "beta_rad", "p_rad_s", "q_rad_s",
                 "r_rad_s", "alpha_dot_hat", "beta_dot_hat", "ax_cg_m_s2", "ay_cg_m_s2", "az_cg_m_s2",
                 "p_dot_rad_s2", "q_dot_rad_s2", "r_dot_rad_s2")
#: how controls vary between samples: linear (sampled continuous signals), hold (zero-order hold, as a
#: digital controller commands them; the seed-rlv simulator holds its fins over each step)
CONTROL_MODES = ("linear", "hold")
_CONTROLS = ("delta_p_rad", "delta_y_rad", "delta_r_rad")
MAX_STEP_S = 0.01
R_EARTH_M = 6_371_000.0  # as aerosid.simulation.dynamics
MAX_ANGLE_RAD = 1.5  # a simulated alpha or beta beyond this has left any model's range: stop
#: Residual [in output noise levels] given to a sample after the simulation left the envelope
#: by the output-error fits (the intercepts here, aerosid.identification.output_error).
DIVERGED_RESIDUAL = 10.0


def theil_inequality(y, yhat) -> float:
    """Theil's inequality coefficient sqrt(mean((y - yhat)^2)) / (sqrt(mean(y^2)) + sqrt(mean(yhat^2))):
    0 for a perfect prediction, 1 at worst."""
    y, yhat = np.asarray(y, float), np.asarray(yhat, float)
    den = math.sqrt(np.mean(y * y)) + math.sqrt(np.mean(yhat * yhat))
    return float(math.sqrt(np.mean((y - yhat) ** 2)) / den) if den > 0 else float("nan")


# --------------------------------------------------------------------------- inputs
def gravity_less_relief(h_m, V_m_s, alpha, beta, phi, theta) -> np.ndarray:
    """g(h) [m/s^2] less the centrifugal relief (V cos gamma)^2/(R_E + h), gamma from the
    attitude and the aerodynamic angles (no wind)."""
    from aerosid.vehicles.atmosphere import gravity_m_s2

    sg = (np.cos(alpha) * np.cos(beta) * np.sin(theta)
          - (np.sin(beta) * np.sin(phi) + np.sin(alpha) * np.cos(beta) * np.cos(phi)) * np.cos(theta))
    v_h2 = (np.asarray(V_m_s, float) ** 2) * (1.0 - np.clip(sg, -1, 1) ** 2)
    return gravity_m_s2(h_m) - v_h2 / (R_EARTH_M + np.asarray(h_m, float))


def prediction_inputs(fd: pd.DataFrame, vehicle: Vehicle, phi_rad, theta_rad, span,
                      wideband_controls: bool = False) -> pd.DataFrame:
    """The inputs frame of a manoeuvre from its flight data (aerosid.identification.flight_data columns,
    sorted by time within each segment), the attitude [rad] on the same rows and a span
    id per row (contiguous samples simulated together; negative: not simulated).
    wideband_controls: drive the simulation with the fins' deflections before the band
    path's low-pass (``delta_*_wideband_rad``, when the flight data carry them) instead of the
    low-passed ones the regression reads: what an output-error fit compares with unfiltered
    measurements needs (c172x seed 0: the low-passed 3-2-1-1 moved its C_m,delta by +9.4 %)."""
    from aerosid.identification.band_order import WIDEBAND_COLUMNS
    from aerosid.modelling.models import vehicle_signals

    if wideband_controls:  # where a wide-band value is missing, the low-passed one
        fd = fd.assign(**{c: np.where(np.isfinite(fd[w].to_numpy(float)), fd[w].to_numpy(float), fd[c].to_numpy(float))
                          for c, w in WIDEBAND_COLUMNS.items() if c.startswith("delta_") and w in fd})
    sig = vehicle_signals(fd, vehicle)
    qS = fd["qbar_pa"].to_numpy(float) * vehicle.S_m2
    m = vehicle.mass_kg
    b, c = vehicle.length_lateral_m, vehicle.length_pitch_m
    p, q, r = (fd[k].to_numpy(float) for k in ("p_rad_s", "q_rad_s", "r_rad_s"))
    L_hat = fd["Cl"].to_numpy(float) * qS * b / vehicle.Ixx_kg_m2
    M_hat = fd["Cm"].to_numpy(float) * qS * c / vehicle.Iyy_kg_m2
    N_hat = fd["Cn"].to_numpy(float) * qS * b / vehicle.Izz_kg_m2
    pd_, qd_, rd_ = body_rate_derivatives(p, q, r, L_hat, M_hat, N_hat, vehicle.inertia)
    alpha, beta = fd["alpha_rad"].to_numpy(float), fd["beta_rad"].to_numpy(float)
    phi, theta = np.asarray(phi_rad, float), np.asarray(theta_rad, float)
    return pd.DataFrame({
        "t_s": fd["t_s"].to_numpy(float), "span": np.asarray(span, int),
        "V_m_s": fd["V_m_s"].to_numpy(float), "mach": fd["mach"].to_numpy(float),
        "qbar_pa": fd["qbar_pa"].to_numpy(float),
        "g_m_s2": gravity_less_relief(fd["h_m"].to_numpy(float), fd["V_m_s"].to_numpy(float), alpha, beta, phi, theta),
        "phi_rad": phi, "theta_rad": theta,
        "delta_p_rad": sig["delta_p"], "delta_y_rad": sig["delta_y"], "delta_r_rad": sig["delta_r"],
        "alpha_rad": alpha, "beta_rad": beta, "p_rad_s": p, "q_rad_s": q, "r_rad_s": r,
        "alpha_dot_hat": sig["alpha_dot_hat"], "beta_dot_hat": sig["beta_dot_hat"],
        "ax_cg_m_s2": -fd["CA"].to_numpy(float) * qS / m, "ay_cg_m_s2": fd["CY"].to_numpy(float) * qS / m,
        "az_cg_m_s2": -fd["CN"].to_numpy(float) * qS / m,
        "p_dot_rad_s2": pd_, "q_dot_rad_s2": qd_, "r_dot_rad_s2": rd_,
    })


# --------------------------------------------------------------------------- the plant
class _Plant:
    """Right-hand side of one axis's equations with the model's coefficients."""

    def __init__(self, model: IdentifiedModel, vehicle: Vehicle, axis: str, values: dict | None):
        self.model, self.axis, self.values = model, axis, values or {}
        self.S, self.m = vehicle.S_m2, vehicle.mass_kg
        self.c, self.b = vehicle.length_pitch_m, vehicle.length_lateral_m
        self.inertia = vehicle.inertia
        self.offset = vehicle.accel_offset_m
        force = "CN" if axis == "lon" else "CY"
        rate = "alpha_dot_hat" if axis == "lon" else "beta_dot_hat"
        self.iterations = 4 if rate in model.reads(force) else 1
        # per channel, what IdentifiedModel.evaluate sums, looked up once instead of at every call
        self._terms = {ch: model.weighted_terms(ch, self.values) for ch in model.models}

    def _signals(self, u: dict, alpha, beta, p, q, r) -> dict:
        V = u["V_m_s"]
        alpha_r, phi_r = total_angles(alpha, beta)
        return {"alpha": alpha, "beta": beta, "alpha_r": alpha_r, "phi_r": phi_r, "mach": u["mach"], "V": V,
                "qbar": u["qbar_pa"], "delta_p": u["delta_p_rad"], "delta_y": u["delta_y_rad"],
                "delta_r": u["delta_r_rad"], "p": p, "q": q, "r": r, "p_hat": p * self.b / (2 * V),
                "q_hat": q * self.c / (2 * V), "r_hat": r * self.b / (2 * V),
                "alpha_dot_hat": u["alpha_dot_hat"], "beta_dot_hat": u["beta_dot_hat"], "t": u["t_s"]}

    def _coef(self, channel: str, s: dict) -> float:
        return float(weighted_sum(self._terms.get(channel, ()), s))

    def rhs(self, x, u: dict):
        """State derivative and the outputs at (x, u)."""
        V, qS, g = u["V_m_s"], u["qbar_pa"] * self.S, u["g_m_s2"]
        th, ph = u["theta_rad"], u["phi_rad"]
        sth, cth, sph, cph = math.sin(th), math.cos(th), math.sin(ph), math.cos(ph)
        gx, gy, gz = -g * sth, g * sph * cth, g * cph * cth
        if self.axis == "lon":
            alpha, q = x
            beta, p, r = u["beta_rad"], u["p_rad_s"], u["r_rad_s"]
        else:
            beta, p, r = x
            alpha, q = u["alpha_rad"], u["q_rad_s"]
        ub, vb, wb = V * math.cos(alpha) * math.cos(beta), V * math.sin(beta), V * math.sin(alpha) * math.cos(beta)
        s = self._signals(u, alpha, beta, p, q, r)
        ax = u["ax_cg_m_s2"]
        if self.axis == "lon":
            adot = 0.0
            for _ in range(self.iterations):
                s["alpha_dot_hat"] = adot * self.c / (2 * V)
                az = -self._coef("CN", s) * qS / self.m
                udot = r * vb - q * wb + ax + gx
                wdot = q * ub - p * vb + az + gz
                adot = (ub * wdot - wb * udot) / (ub * ub + wb * wb)
            s["alpha_dot_hat"] = adot * self.c / (2 * V)
            M_hat = self._coef("Cm", s) * qS * self.c / self.inertia.Iyy
            _, qdot, _ = body_rate_derivatives(p, q, r, 0.0, M_hat, 0.0, self.inertia)
            lz = lever_arm_acceleration(p, q, r, u["p_dot_rad_s2"], qdot, u["r_dot_rad_s2"], self.offset)[2]
            return (adot, qdot), (alpha, q, az + lz)
        bdot = 0.0
        az = u["az_cg_m_s2"]
        for _ in range(self.iterations):
            s["beta_dot_hat"] = bdot * self.b / (2 * V)
            ay = self._coef("CY", s) * qS / self.m
            udot = r * vb - q * wb + ax + gx
            vdot = p * wb - r * ub + ay + gy
            wdot = q * ub - p * vb + az + gz
            Vdot = (ub * udot + vb * vdot + wb * wdot) / V
            bdot = (V * vdot - vb * Vdot) / (V * V * math.cos(beta))
        s["beta_dot_hat"] = bdot * self.b / (2 * V)
        L_hat = self._coef("Cl", s) * qS * self.b / self.inertia.Ixx
        N_hat = self._coef("Cn", s) * qS * self.b / self.inertia.Izz
        pdot, _, rdot = body_rate_derivatives(p, q, r, L_hat, 0.0, N_hat, self.inertia)
        ly = lever_arm_acceleration(p, q, r, pdot, u["q_dot_rad_s2"], rdot, self.offset)[1]
        return (bdot, pdot, rdot), (beta, p, r, ay + ly)


def simulate_span(model: IdentifiedModel, inputs: pd.DataFrame, vehicle: Vehicle, axis: str,
                  values: dict | None = None, controls: str = "linear") -> tuple[np.ndarray, float | None]:
    """Predicted outputs (n, n_outputs) of one contiguous span of the inputs frame,
    from its first sample's measured (smoothed) state; NaN after a divergence, whose
    time is returned (else None)."""
    plant = _Plant(model, vehicle, axis, values)
    names = list(INPUT_COLUMNS[2:]) + ["t_s"]
    U = inputs[names].to_numpy(float)
    n = len(U)
    out = np.full((n, len(AXIS_OUTPUTS[axis])), np.nan)
    first = dict(zip(names, U[0]))
    x = np.array([first["alpha_rad"], first["q_rad_s"]] if axis == "lon"
                 else [first["beta_rad"], first["p_rad_s"], first["r_rad_s"]])
    t = U[:, -1]
    held = [names.index(c) for c in _CONTROLS] if controls == "hold" else []

    def f(k: int, frac: float, state):
        row = U[k] if frac == 0.0 else U[k] + frac * (U[k + 1] - U[k])
        if held and frac:
            row[held] = U[k, held]
        d, y = plant.rhs(state, dict(zip(names, row)))
        return np.asarray(d), y

    for k in range(n):
        d0, y = f(k, 0.0, x)
        out[k] = y
        if not (np.all(np.isfinite(x)) and abs(x[0]) < MAX_ANGLE_RAD and np.all(np.isfinite(y))):
            out[k] = np.nan
            return out, float(t[k])
        if k == n - 1:
            break
        dt = t[k + 1] - t[k]
        nsub = max(1, int(math.ceil(dt / MAX_STEP_S - 1e-9)))
        h = dt / nsub
        for j in range(nsub):
            a = j / nsub
            k1 = d0 if j == 0 else f(k, a, x)[0]
            k2 = f(k, a + 0.5 / nsub, x + 0.5 * h * k1)[0]
            k3 = f(k, a + 0.5 / nsub, x + 0.5 * h * k2)[0]
            k4 = f(k, a + 1.0 / nsub, x + h * k3)[0]
            x = x + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
    return out, None


# --------------------------------------------------------------------------- the prediction
@dataclass(frozen=True)
class AxisPrediction:
    """One axis predicted over every span: the frame holds t_s, span and, per output,
    ``measured_<output>``, ``predicted_<output>`` (after the bias treatment) and
    ``offset_<output>`` (the constant added; 0 without offsets)."""

    axis: str
    bias: str
    frame: pd.DataFrame
    intercepts: dict  # coefficient -> (identified, re-estimated) with bias "intercepts"
    diverged: dict  # span -> time [s] where the simulation left the envelope
    notes: tuple = field(default=())

    @property
    def outputs(self) -> tuple[str, ...]:
        return AXIS_OUTPUTS[self.axis]


def predicted_outputs(model, inputs: pd.DataFrame, vehicle: Vehicle, axis: str, values: dict | None = None,
                      controls: str = "linear") -> tuple[np.ndarray, dict]:
    """(predicted outputs (len(inputs), n_outputs), NaN on rows span < 0 and after a divergence;
    {span: time of the divergence [s]}): every span of `inputs` (index 0..n-1) simulated."""
    pred = np.full((len(inputs), len(AXIS_OUTPUTS[axis])), np.nan)
    diverged = {}
    for sp, rows in inputs.groupby("span", sort=True):
        if sp < 0:
            continue
        y, t_div = simulate_span(model, rows, vehicle, axis, values, controls)
        if t_div is not None:
            diverged[int(sp)] = t_div
        pred[rows.index.to_numpy()] = y
    return pred, diverged


def span_offsets(meas: np.ndarray, pred: np.ndarray, spans: np.ndarray) -> np.ndarray:
    """Per span and output: mean(measured - predicted) over the finite samples, on every row."""
    off = np.zeros_like(pred)
    for sp in np.unique(spans):
        rows = spans == sp
        d = meas[rows] - pred[rows]
        with np.errstate(invalid="ignore"):
            mean = np.array([np.nanmean(col) if np.isfinite(col).any() else 0.0 for col in d.T])
        off[rows] = mean
    return off


def check_simulation_inputs(inputs: pd.DataFrame, axis: str, controls: str, what: str) -> None:
    """ValueError naming what is wrong with an axis's simulation request (`what`: whose inputs)."""
    if axis not in AXES:
        raise ValueError(f"unknown axis {axis!r}; axes: {', '.join(AXES)}")
    if controls not in CONTROL_MODES:
        raise ValueError(f"unknown control interpolation {controls!r}; choose one of {', '.join(CONTROL_MODES)}")
    missing = [c for c in INPUT_COLUMNS if c not in inputs.columns]
    if missing:
        raise ValueError(f"the {what} inputs lack column(s) {missing}")


def predict_axis(model: IdentifiedModel, inputs: pd.DataFrame, measured: pd.DataFrame, vehicle: Vehicle,
                 axis: str, bias: str = "offsets", controls: str = "linear") -> AxisPrediction:
    """Simulate one axis over every span of `inputs` (rows with span >= 0) and compare
    with `measured` (same rows; one column per output name, NaN where not measured).
    controls: how the controls vary between samples (CONTROL_MODES)."""
    if bias not in BIAS_MODES:
        raise ValueError(f"unknown bias treatment {bias!r}; choose one of {', '.join(BIAS_MODES)}")
    check_simulation_inputs(inputs, axis, controls, "prediction")
    inputs = inputs.reset_index(drop=True)
    measured = measured.reset_index(drop=True)
    outs = AXIS_OUTPUTS[axis]
    use = inputs["span"].to_numpy() >= 0
    meas = np.column_stack([measured[o].to_numpy(float) if o in measured else np.full(len(inputs), np.nan)
                            for o in outs])
    notes = []
    values, intercepts = None, {}
    if bias == "intercepts":
        names = [c for ch in AXIS_CHANNELS[axis] for c in model.intercepts(ch)]
        if not names:
            notes.append(f"no constant term in the {axis} channels' models: only output offsets are removed")
        else:
            values = _fit_intercepts(model, inputs, meas, use, vehicle, axis, names, controls)
            intercepts = {k: (float(model.values[k]), float(values[k])) for k in names}
    pred, diverged = predicted_outputs(model, inputs, vehicle, axis, values, controls)
    spans = inputs["span"].to_numpy()
    off = span_offsets(meas, pred, spans) if bias != "none" else np.zeros_like(pred)
    off[~use] = np.nan
    frame = {"t_s": inputs["t_s"].to_numpy(float), "span": spans}
    for j, o in enumerate(outs):
        frame[f"measured_{o}"] = meas[:, j]
        frame[f"predicted_{o}"] = pred[:, j] + off[:, j]
        frame[f"offset_{o}"] = off[:, j]
    for sp, t in diverged.items():
        notes.append(f"span {sp}: the {axis} simulation left the envelope at t = {t:.2f} s (NaN after)")
    return AxisPrediction(axis, bias, pd.DataFrame(frame), intercepts, diverged, tuple(notes))


def _fit_intercepts(model, inputs, meas, use, vehicle, axis, names, controls) -> dict:
    """Output-error estimate of the constant terms `names` (the other coefficients fixed),
    output offsets projected out per span, each output scaled by its measured std."""
    spans = inputs["span"].to_numpy()
    ok = np.isfinite(meas) & use[:, None]
    scale = np.array([np.std(meas[ok[:, j], j]) if ok[:, j].sum() > 1 else 1.0 for j in range(meas.shape[1])])
    scale[~(scale > 0)] = 1.0
    x0 = np.array([float(model.values[k]) if math.isfinite(float(model.values[k])) else 0.0 for k in names])

    def residuals(x):
        pred, _ = predicted_outputs(model, inputs, vehicle, axis, dict(zip(names, x)), controls)
        res = (meas - pred - span_offsets(meas, pred, spans)) / scale
        res = np.where(np.isfinite(pred), res, DIVERGED_RESIDUAL)  # a diverged simulation: far from the data
        return res[ok]

    sol = least_squares(residuals, x0, x_scale="jac", method="trf", max_nfev=60)
    return {**{k: float(v) for k, v in model.values.items()}, **dict(zip(names, map(float, sol.x)))}
