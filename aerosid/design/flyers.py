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
    """A JSBSim aircraft; the designed elevator command ``elevator_cmd_rad``, the candidate shapes
    flown at reference_rad (c172x: 0.08; a generated aircraft: its flight design's 3-2-1-1 size).  throttle: None
    flies the simulator's own trim; a value (0 = idle) a glide trimmed at that fixed throttle
    (the input's ``throttle_cmd_norm`` column, aerosid.design.io)."""

    column = "elevator_cmd_rad"

    def __init__(self, aircraft: str, duration_s: float, dt: float = 0.01, extra: pd.DataFrame | None = None,
                 throttle: float | None = None, reference_rad: float = 0.08):
        self.aircraft = aircraft
        self.reference_rad = reference_rad  # the elevator amplitude [rad] the candidate shapes are flown at
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


def default_flyer(vehicle, limits, coefs: dict, effect: str | None, size: float, say, power: str = "trim"):
    """(flyer, baseline truth, input start [s], input end [s], linearised?) for the run's vehicle:
    seed-rlv in the built-in simulator, c172x and any JSBSim aircraft aerosid can fly (the
    generated ones: pa28, OV10, T37, F4N, ...; its name is the vehicle file's) in JSBSim.
    power: "trim" (the simulator's trim) or "idle" (JSBSim aircraft: a glide at idle throttle)."""
    from aerosid.design.core import DesignError
    from aerosid.design.power import POWER_SETTINGS

    if power != "trim" and vehicle.name == "seed-rlv":
        raise DesignError(f"--power {power}: the built-in simulator (seed-rlv) has no throttle; it is an option "
                          "of the JSBSim aircraft")
    if vehicle.name == "seed-rlv":
        from aerosid.identification.identify import mach_window_mask

        flyer = RLVFlyer(coefs, effect, size)
        say("flying the baseline and the impulse response (built-in simulator, identified pitch model)")
        base = flyer.baseline()
        in_win = mach_window_mask(base["mach"].to_numpy(float), vehicle.mach_reference, 0.5)
        t_win = base["t_s"].to_numpy(float)[in_win]
        start = float(t_win.min()) + 0.5
        return flyer, base, start, min(float(t_win.max()), start + limits.duration_max_s), True
    from aerosid.simulation.jsbsim_flight import SUPPORTED_AIRCRAFT

    if vehicle.name not in SUPPORTED_AIRCRAFT and not generated_for_jsbsim(vehicle):
        raise DesignError(f"no simulator for vehicle {vehicle.name!r} ({vehicle.source}): the design flies candidates in "
                          "the built-in simulator (seed-rlv), JSBSim's c172x, or the JSBSim aircraft whose vehicle file "
                          "`aerosid simulate --jsbsim AIRCRAFT` generated; a vehicle file of your own is not flown in a "
                          "JSBSim model that happens to share its name")
    sizes = jsbsim_input_sizes(vehicle.name)
    duration = limits.duration_max_s
    h = sizes["half_s"]
    end = duration - max(16.0, 6.0 + 4.0 * h + max(5.0, 3.0 * h))  # room for the two lateral doublets
    extra = lateral_doublets(np.arange(int(round(duration / 0.01)) + 1) * 0.01, end, sizes["aileron_rad"],
                             sizes["rudder_rad"], sizes["half_s"])
    flyer = JSBSimFlyer(vehicle.name, duration, extra=extra, throttle=POWER_SETTINGS[power],
                        reference_rad=sizes["elevator_rad"])
    say(f"flying the baseline in JSBSim ({duration:g} s{', power-off glide at idle throttle' if power == 'idle' else ''})")
    return flyer, flyer.fly(np.zeros_like(flyer.t)), 3.0, end, False


def generated_for_jsbsim(vehicle) -> bool:
    """Whether the vehicle file is the one aerosid generated for JSBSim's aircraft of that name
    (aerosid.simulation.jsbsim_vehicle writes 'JSBSim NAME (class), ... generated flight design')."""
    text = str(getattr(vehicle, "description", ""))
    return text.startswith(f"JSBSim {vehicle.name} (") and text.endswith("generated flight design")


#: c172x's hand-written flight: the elevator shapes are flown at 0.08 rad (well above its elevator's
#: hysteresis, 0.05 rad wide), the lateral doublets at 0.04 rad, 1 s per half.
C172X_INPUT_SIZES = {"elevator_rad": 0.08, "aileron_rad": 0.04, "rudder_rad": 0.04, "half_s": 1.0}


def jsbsim_input_sizes(aircraft: str) -> dict:
    """The input sizes [rad of deflection] and the lateral doublets' half-width [s] of a JSBSim
    design: c172x's own, else the generated flight design's (its 3-2-1-1 and doublets are sized to
    the aircraft's surfaces and modes, aerosid.simulation.jsbsim_design).  A vehicle that is not a
    JSBSim aircraft aerosid can fly raises DesignError, saying why."""
    from aerosid.design.core import DesignError
    from aerosid.simulation.jsbsim_flight import SUPPORTED_AIRCRAFT

    if aircraft in SUPPORTED_AIRCRAFT:
        return dict(C172X_INPUT_SIZES)
    try:
        from aerosid.simulation.jsbsim_design import flight_design
        from aerosid.simulation.jsbsim_flight import _import_jsbsim

        d = flight_design(_import_jsbsim(), aircraft)
    except ImportError as exc:
        raise DesignError(f"vehicle {aircraft!r}: the design flies JSBSim, which is not installed ({exc})") from exc
    except ValueError as exc:  # UnsupportedAircraft: no such aircraft, or one aerosid cannot fly
        raise DesignError(f"no simulator for vehicle {aircraft!r}: the design flies candidates in the built-in "
                          f"simulator (seed-rlv) or in JSBSim, and JSBSim says: {exc}") from exc
    m, g = d.manoeuvre, d.gains  # the commanded steps (after the travel limit) times the static gains
    return {"elevator_rad": abs(float(m["elevator_amplitudes_norm"][0]) * float(g["pitch"])),
            "aileron_rad": abs(float(m["aileron_amplitude_norm"]) * float(g["roll"])),
            "rudder_rad": abs(float(m["rudder_amplitude_norm"]) * float(g["yaw"])),
            "half_s": float(m["aileron_half_s"])}


def lateral_doublets(t: np.ndarray, after_s: float, aileron_rad: float = 0.04, rudder_rad: float = 0.04,
                     half_s: float = 1.0) -> pd.DataFrame:
    """The lateral part of a JSBSim design: an aileron then a rudder doublet after the
    elevator input (as in the aircraft's 3211 flight), so that beta and the lateral terms stay
    excited; amplitudes [rad of deflection] and half-width [s] (c172x's by default)."""
    ail = np.zeros_like(t)
    rud = np.zeros_like(t)
    a0 = after_s + 1.0
    r0 = a0 + 2.0 * half_s + max(5.0, 3.0 * half_s)
    ail[(t >= a0) & (t < a0 + half_s)] = aileron_rad
    ail[(t >= a0 + half_s) & (t < a0 + 2 * half_s)] = -aileron_rad
    rud[(t >= r0) & (t < r0 + half_s)] = rudder_rad
    rud[(t >= r0 + half_s) & (t < r0 + 2 * half_s)] = -rudder_rad
    k = max(int(round(0.2 / (t[1] - t[0]))), 1)  # 0.2 s input ramps, as in c172x's 3211 flight
    ail = np.convolve(ail, np.full(k, 1.0 / k))[: t.size]
    rud = np.convolve(rud, np.full(k, 1.0 / k))[: t.size]
    return pd.DataFrame({"t_s": t, "aileron_cmd_rad": ail, "rudder_cmd_rad": rud})
