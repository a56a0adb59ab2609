"""The flight-averaged linear truth of a JSBSim flight: for every derivative, the mean over
the flight's samples of the central difference (h = 1e-4) of the aircraft's own
aerodynamic model at that sample's state (alpha, beta, the surfaces, the rates and every
other input the model reads as recorded; moments about the sample's CG), beside the
at-trim truth (the same central difference at the trim point only).

Why: JSBSim's tables interpolate linearly between breakpoints, so the at-trim derivative
is the slope of ONE table segment, and which segment depends on where the trim point
falls relative to a breakpoint (pa28's C_L(alpha): 5.743/rad below alpha = 0, 5.914
above; trim at -0.48 deg, the flight spans -2.6..+1.7 deg).  A linear model identified
from the flight estimates something else: by Stein's lemma, for jointly Gaussian
excursions x the least-squares coefficients of a smooth f on x are
Sigma^-1 Cov(x, f(x)) = E[grad f(x)], the mean derivative over the excursions -- for
piecewise-linear tables, the segment slopes weighted by the time the flight spends on
each.  The flight's excursions are not Gaussian (3-2-1-1s and doublets from a trim), so
this is a physically motivated target, not an identity; the bench reports both truths.
Measured on the bench flights (bench/results/generalisation.md, truth_weighting.md): the
average is within 0.6 % of the at-trim truth everywhere (pa28 CN_alpha +0.14 %), while the
least-squares slope of the same table along alpha alone is +0.93 % on pa28: a least-squares
fit weights the local slope by the large excursions, the uniform mean by time.

``flight_average(evaluate, x)`` is the generic part (any vectorised model evaluation);
``generated_state`` and ``c172x_state`` build the model evaluation of the two JSBSim
simulators from their per-sample record.  The result is a table in the at-trim truth's
names (jsbsim_flight._coefficient_table): derivatives are the averages; the intercepts
are the least-squares ones under the same argument, mean(C) - sum_j mean(dC/dx_j) mean(x_j).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from aerosid.simulation.jsbsim_tables import AeroTables, body_coefficients
from aerosid.simulation.jsbsim_truth import STEP  # the central-difference step of the at-trim truth

__all__ = ["STEP", "flight_average", "generated_state", "c172x_state", "generated_flight_average",
           "c172x_flight_average"]

NOTE = ("flight-averaged linear truth = mean over the flight's samples of the central difference (h = 1e-4) of "
        "the aircraft's own aerodynamic model at each sample's state (every input of the model as recorded; "
        "moments about the sample's CG); intercepts = mean(C) - sum mean(dC/dx) mean(x) "
        "(aerosid.simulation.jsbsim_truth_avg)")

Evaluate = Callable[[dict], dict]


def flight_average(evaluate: Evaluate, x: dict[str, np.ndarray], h: float = STEP) -> dict[str, float]:
    """The flight-averaged truth table.  evaluate(x) -> {coefficient: array over the
    samples} (CA, CY, CN, Cl, Cm, Cn about the CG and Cl_rp, Cm_rp, Cn_rp), vectorised over
    the samples; x: the model's variables (jsbsim_flight._LINEAR_VARS) per sample."""
    from aerosid.simulation.jsbsim_truth import _LINEAR_VARS, _coefficient_table, central_differences

    missing = [v for v in _LINEAR_VARS if v not in x]
    if missing:
        raise ValueError(f"flight_average: the state lacks {missing}")
    x = {k: np.asarray(v, float) for k, v in x.items()}
    n = len(x["alpha"])
    if n == 0:
        raise ValueError("flight_average: the flight has no samples")
    lin = central_differences(evaluate, x, h)
    point = {k: float(np.mean(x[k])) for k in _LINEAR_VARS}
    return _coefficient_table(lin, point, "cg")


def generated_state(tables: AeroTables, rec: dict, controls, slopes: dict | None = None,
                    steady_cl_squared: bool = True) -> tuple[Evaluate, dict]:
    """(evaluate, x) for a flight of aerosid.simulation.jsbsim_aircraft: every leaf property
    of the model and the geometry from the record `rec` (arrays over the samples), the
    state mapped onto the model's properties as the at-trim truth does
    (jsbsim_linear.state_values, model_coefficients).  steady_cl_squared: aero/cl-squared
    from the model's own C_L (as the at-trim truth; False: as recorded, JSBSim's
    previous-frame value, which reproduces JSBSim's coefficients)."""
    from aerosid.simulation.jsbsim_linear import model_coefficients, state_values

    names = set(tables.leaf_properties()) | {controls.pitch, controls.roll, controls.yaw}
    names |= {"aero/alpha-rad", "aero/beta-rad", "aero/qbar-psf", "aero/ci2vel", "aero/bi2vel",
              "metrics/Sw-sqft", "metrics/cbarw-ft", "metrics/bw-ft",
              "metrics/aero-rp-x-in", "metrics/aero-rp-y-in", "metrics/aero-rp-z-in"}
    names |= {s for s, _ in controls.siblings} | {c for _, c in controls.siblings}
    missing = sorted(p for p in names if p not in rec)
    if missing:
        raise ValueError(f"flight-averaged truth: the flight's record lacks {missing}")
    base = {p: np.asarray(rec[p], float) for p in names}
    cg = tuple(np.asarray(rec[f"inertia/cg-{a}-in"], float) for a in "xyz")
    x = {"alpha": base["aero/alpha-rad"], "beta": base["aero/beta-rad"], "delta_p": base[controls.pitch],
         "delta_r": base[controls.roll], "delta_y": base[controls.yaw],
         "p_hat": np.asarray(rec["velocities/p-aero-rad_sec"], float) * base["aero/bi2vel"],
         "q_hat": np.asarray(rec["velocities/q-aero-rad_sec"], float) * base["aero/ci2vel"],
         "r_hat": np.asarray(rec["velocities/r-aero-rad_sec"], float) * base["aero/bi2vel"],
         "alpha_dot_hat": np.asarray(rec["aero/alphadot-rad_sec"], float) * base["aero/ci2vel"]}

    def evaluate(s):
        values = state_values(base, controls, s, slopes)
        return model_coefficients(tables, values, s["alpha"], s["beta"], cg, cl_squared_from_lift=steady_cl_squared)

    return evaluate, x


def c172x_state(tables: AeroTables, rec: dict, x: dict, arm_ft, cbar_ft: float, b_ft: float) -> tuple[Evaluate, dict]:
    """(evaluate, x) for the hand-written c172x flight (aerosid.simulation.jsbsim_flight):
    ``AeroTables.coefficients`` with the flaps, the height over the span and the stall
    hysteresis as recorded, the AERORP-to-CG arm per sample [ft]."""
    extra = {"flaps_deg": np.asarray(rec["fcs/flap-pos-deg"], float),
             "h_over_b": np.asarray(rec["aero/h_b-mac-ft"], float),
             "stall_hyst": np.asarray(rec["aero/stall-hyst-norm"], float)}

    def evaluate(s):
        c = tables.coefficients(s["alpha"], s["beta"], s["delta_p"], s["delta_r"], s["delta_y"],
                                s["p_hat"], s["q_hat"], s["r_hat"], s["alpha_dot_hat"], **extra)
        return body_coefficients(c, s["alpha"], s["beta"], arm_ft, cbar_ft, b_ft)

    return evaluate, {k: np.asarray(v, float) for k, v in x.items()}


def generated_flight_average(tables: AeroTables, rec: dict, controls, slopes: dict | None = None) -> dict:
    """The info entries of a generated flight (aerosid.simulation.jsbsim_aircraft)."""
    return {"coefficients_flight_average": flight_average(*generated_state(tables, rec, controls, slopes)),
            "flight_average_note": NOTE}


def c172x_flight_average(tables: AeroTables, rec: dict, truth, arm_ft, cbar_ft: float, b_ft: float) -> dict:
    """The info entries of the c172x flight (aerosid.simulation.jsbsim_flight); `truth` its
    truth frame (alpha, beta, surfaces, non-dimensional rates), delta_r =
    fcs/effective-aileron-pos as its at-trim truth."""
    x = {"alpha": truth["alpha_rad"], "beta": truth["beta_rad"], "delta_p": truth["delta_p_rad"],
         "delta_r": rec["fcs/effective-aileron-pos"], "delta_y": truth["delta_y_rad"],
         **{k: truth[k] for k in ("p_hat", "q_hat", "r_hat", "alpha_dot_hat")}}
    return {"coefficients_flight_average": flight_average(*c172x_state(tables, rec, x, arm_ft, cbar_ft, b_ft)),
            "flight_average_note": NOTE}
