"""Flying a candidate input noise-free, to get the regressors it would excite.

* :class:`RLVFlyer` (seed-rlv, the built-in simulator): the identified pitch model
  (Cm_0, Cm_alpha, Cm_delta_p of the run, moved to the nose reference the simulator
  takes) with the case's autopilot and guidance.  The search uses the *linearised*
  simulator: a baseline flight without pitch manoeuvres plus the response to a
  one-sample pitch-command impulse, convolved with each candidate (the closed loop is
  linear in the command to well within the search's needs); the chosen design is then
  flown in full.
* :class:`JSBSimFlyer` (JSBSim aircraft): every candidate is flown by JSBSim itself
  (about a second per flight), the true aircraft standing in for the identified model.

Both return a truth frame (the simulator's noise-free per-sample truth).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import scipy.signal

from aerosid.modelling.effects import CATALOGUE

#: truth columns that respond to the pitch command (linearised about the baseline)
_RESPONSE = ("alpha_rad", "q_rad_s", "delta_p_rad", "d1_rad", "d2_rad", "d3_rad", "d4_rad", "az_cg_m_s2", "mach",
             "V_m_s", "qbar_pa", "beta_rad", "p_rad_s", "r_rad_s", "delta_y_rad", "delta_r_rad")


class RLVFlyer:
    """seed-rlv through the built-in simulator, pitch command ``delta_p_cmd_rad``."""

    column = "delta_p_cmd_rad"

    def __init__(self, coefficients: dict, effect_name: str | None = None, effect_value: float | None = None,
                 case_name: str = "seed-rlv"):
        from aerosid.simulation import load_case

        case = load_case(case_name)
        veh = case.vehicle
        x = veh.xcg_over_d
        pre = veh.preflight
        dev = dict(case.deviations)
        # the identified moment coefficients about the CG -> the simulator's nose reference
        for cg, nose, cn in (("Cm_0", "Cm_0_nose", pre.CN_0), ("Cm_alpha", "Cm_alpha_nose", pre.CN_alpha),
                             ("Cm_delta_p", "Cm_delta_p_nose", pre.CN_delta_p)):
            if np.isfinite(coefficients.get(cg, np.nan)):
                dev[nose] = float(coefficients[cg]) - cn * x
        effects = []
        if effect_name in CATALOGUE and effect_value is not None:
            e = CATALOGUE[effect_name]
            effects.append((e, float(effect_value) / e.value))
        self.case = replace(case, deviations=dev, faults=case.faults.without_faults(), pitch_plan=())
        self.effects = tuple(effects)
        self.vehicle = veh
        self.dt = 1.0 / case.sample_rate_hz
        self.t = np.arange(int(round(case.duration_s * case.sample_rate_hz)) + 1) * self.dt
        self._baseline = None
        self._impulse = None

    def fly(self, u: np.ndarray | None) -> pd.DataFrame:
        from aerosid.simulation import simulate

        case = self.case if u is None else replace(self.case, inputs={self.column: (self.t, np.asarray(u, float))})
        truth = simulate(case, self.effects, seed=0).truth
        # the fin deflections d1..d4 (the simulator's truth holds the mixed ones)
        pinv = np.linalg.pinv(np.asarray(self.vehicle.mixing, float))
        mixed = truth[["delta_r_rad", "delta_p_rad", "delta_y_rad"]].to_numpy(float)
        fins = mixed @ pinv.T
        for i in range(4):
            truth[f"d{i + 1}_rad"] = fins[:, i]
        return truth

    def noisy(self, u: np.ndarray, seed: int) -> pd.DataFrame:
        """Raw telemetry of u flown with the case's sensor noise and faults (seed)."""
        from aerosid.simulation import load_case, simulate

        case = replace(self.case, faults=load_case(self.case.name).faults,
                       inputs={self.column: (self.t, np.asarray(u, float))})
        return simulate(case, self.effects, seed=seed).telemetry

    def _linear(self):
        if self._baseline is None:
            self._baseline = self.fly(None)
            amp = 0.2  # rad of delta_p command during one sample
            u = np.zeros_like(self.t)
            k0 = int(round(2.0 / self.dt))
            u[k0] = amp
            imp = self.fly(u)
            h = {c: np.zeros_like(self.t) for c in _RESPONSE}
            for c in _RESPONSE:
                d = (imp[c].to_numpy(float) - self._baseline[c].to_numpy(float)) / (amp * self.dt)
                h[c][: self.t.size - k0] = d[k0:]
            self._impulse = h
        return self._baseline, self._impulse

    def baseline(self) -> pd.DataFrame:
        return self._linear()[0]

    def linear_response(self, u: np.ndarray) -> pd.DataFrame:
        """The truth frame of input u, linearised about the baseline (impulse-response convolution)."""
        base, h = self._linear()
        out = base.copy()
        n = self.t.size
        for c in _RESPONSE:
            out[c] = base[c].to_numpy(float) + scipy.signal.fftconvolve(h[c], u)[:n] * self.dt
        return out


class JSBSimFlyer:
    """A JSBSim aircraft; the designed elevator command ``elevator_cmd_rad``.  throttle: None
    flies the simulator's own trim; a value (0 = idle) a glide trimmed at that fixed throttle
    (the input's ``throttle_cmd_norm`` column, aerosid.design.io)."""

    column = "elevator_cmd_rad"

    def __init__(self, aircraft: str, duration_s: float, dt: float = 0.01, extra: pd.DataFrame | None = None,
                 throttle: float | None = None):
        self.aircraft = aircraft
        self.dt = dt
        self.t = np.arange(int(round(duration_s / dt)) + 1) * dt
        self.extra = extra  # other axes' inputs (e.g. the lateral doublets), on self.t
        self.throttle = throttle

    def table(self, u: np.ndarray) -> pd.DataFrame:
        df = pd.DataFrame({"t_s": self.t, self.column: np.asarray(u, float)})
        if self.extra is not None:
            for c in self.extra.columns:
                if c != "t_s":
                    df[c] = self.extra[c].to_numpy(float)
        if self.throttle is not None:
            df["throttle_cmd_norm"] = float(self.throttle)
        return df

    def fly(self, u: np.ndarray) -> pd.DataFrame:
        from aerosid.simulation.jsbsim_flight import simulate_jsbsim

        flight = simulate_jsbsim(self.aircraft, "3211", seed=0, faults=False, input_table=self.table(u))
        self.coefficients = dict(flight.coefficients)  # the simulator's own linear truth at trim
        return flight.truth

    def noisy(self, u: np.ndarray, seed: int) -> pd.DataFrame:
        """Raw telemetry of u flown with the aircraft's sensor noise and faults (seed)."""
        from aerosid.simulation.jsbsim_flight import simulate_jsbsim

        return simulate_jsbsim(self.aircraft, "3211", seed=seed, faults=True, input_table=self.table(u)).telemetry
