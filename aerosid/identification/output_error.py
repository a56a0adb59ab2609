"""Output-error refinement of one identified axis, started from the equation-error estimates.

Estimation Before Modeling fits every channel by equation error: the regressors (alpha, the
rates, alpha-dot) are measured, so their noise biases the slopes (errors in variables) and
the derivatives' low-pass attenuates them.  The output-error method fits the same model by
*simulating* it with the measured controls and comparing the simulated outputs with the
measured ones: the sensors' noise is then output noise, which biases nothing (Maine & Iliff;
Morelli & Klein, *Aircraft System Identification*, ch. 6; SIDPAC's ``oe``).  Its price is a
simulation per parameter per iteration, and it needs a start close enough to converge: the
equation-error result, which is what this module refines.

The simulation is :mod:`aerosid.identification.output_prediction` (one axis; the other
axis's states, V, dynamic pressure and the attitude measured).  The fit:

* **Cost:** sum over outputs j and samples k of ((y_jk - yhat_jk - b_js) / s_j)^2, with a
  constant b_js per output and span (the sensors' biases and the trim's offsets, removed as
  the prediction's ``offsets`` treatment does) and s_j the output's noise level.
* **Noise levels:** the relaxation of Maine & Iliff: s_j = the residual std of output j,
  re-estimated after each Gauss-Newton pass (``RELAXATIONS`` passes), which for a diagonal R
  is the maximum-likelihood estimate.
* **Minimisation:** scipy's trust-region least squares with forward-difference sensitivities.
* **Uncertainty:** the Cramer-Rao bound inv(S'S) from the sensitivities S of the scaled
  outputs, and the Morelli-Klein coloured-residual sandwich inv(S'S) (sum_j S_j' R_j S_j)
  inv(S'S), per output with its own residual autocovariance R_j (Parzen window, within each
  span; aerosid.identification.residual_covariance); the sandwich's sigma is the reported one:
  output-error residuals on real data are far from white (modelling error, turbulence).

Not a default: ``aerosid refine`` runs it on a finished run (docs/refine.md: what it does, how
it was measured and why it is not the default).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy.optimize import least_squares

from aerosid.identification.identified import IdentifiedModel
from aerosid.identification.output_prediction import (AXIS_CHANNELS, AXIS_OUTPUTS, DIVERGED_RESIDUAL,
                                                      check_simulation_inputs, predicted_outputs, span_offsets,
                                                      theil_inequality)
from aerosid.identification.residual_covariance import _group_slices, auto_max_lag, morelli_klein_middle
from aerosid.vehicles.vehicle import Vehicle

__all__ = ["OutputErrorFit", "output_error_fit", "axis_coefficients", "free_coefficients", "RELAXATIONS"]

#: Gauss-Newton passes, each followed by a new estimate of the outputs' noise levels.
RELAXATIONS = 3
#: Relative step of the central differences that give the output sensitivities.
SENSITIVITY_STEP = 1e-4


@dataclass(frozen=True)
class OutputErrorFit:
    """An output-error fit of one axis (module doc).  estimate / sigma / sigma_white /
    start: coefficient -> value; noise_std, tic_start, tic_end: output -> value."""

    axis: str
    names: tuple[str, ...]
    start: dict
    estimate: dict
    sigma: dict           # Morelli-Klein (coloured residuals): the reported one
    sigma_white: dict     # Cramer-Rao bound with the fitted noise levels
    noise_std: dict       # per output: the residual std at the end [output unit]
    tic_start: dict       # per output: Theil's inequality coefficient of the start's simulation
    tic_end: dict
    n_samples: int
    n_spans: int
    n_eff: float          # effective samples, summed over the outputs
    converged: bool
    message: str
    nfev: int
    model: IdentifiedModel = field(repr=False)
    covariance: np.ndarray = field(repr=False, compare=False, default=None)  # reported (coloured-residual), `names` order
    notes: tuple[str, ...] = ()

    def combination(self, weights: dict[str, float]) -> tuple[float, float]:
        """(estimate, sigma) of sum_k w_k theta_k (e.g. Cm_q + Cm_alpha_dot), with the covariance."""
        w = np.array([float(weights.get(k, 0.0)) for k in self.names])
        unknown = set(weights) - set(self.names)
        if unknown:
            raise KeyError(f"{sorted(unknown)} not among the refined coefficients {list(self.names)}")
        est = float(w @ np.array([self.estimate[k] for k in self.names]))
        return est, float(math.sqrt(max(float(w @ self.covariance @ w), 0.0)))

    def conf_int(self, level: float = 0.95) -> dict[str, tuple[float, float]]:
        """Normal-quantile intervals from the reported (coloured-residual) sigma."""
        from scipy.stats import norm

        z = float(norm.ppf(0.5 + level / 2))
        return {k: (self.estimate[k] - z * self.sigma[k], self.estimate[k] + z * self.sigma[k]) for k in self.names}

    def to_dict(self) -> dict:
        f = lambda x: float(x) if math.isfinite(x) else None  # noqa: E731
        return {"axis": self.axis, "converged": self.converged, "message": self.message, "nfev": self.nfev,
                "n_samples": self.n_samples, "n_spans": self.n_spans, "n_eff": f(self.n_eff),
                "coefficients": {k: {"equation_error": f(self.start[k]), "estimate": f(self.estimate[k]),
                                     "std_error": f(self.sigma[k]), "std_error_crb": f(self.sigma_white[k])}
                                 for k in self.names},
                "covariance": [[f(x) for x in row] for row in np.asarray(self.covariance, float)],
                "outputs": {o: {"noise_std": f(self.noise_std[o]), "tic_start": f(self.tic_start[o]),
                                "tic_end": f(self.tic_end[o])} for o in self.noise_std},
                "notes": list(self.notes)}

    def summary(self) -> str:
        lines = [f"output-error refinement of the {self.axis} axis: {self.n_samples} samples in {self.n_spans} "
                 f"span(s), N_eff = {self.n_eff:.0f} (summed over the outputs); "
                 f"{'converged' if self.converged else 'NOT converged'} ({self.message}; {self.nfev} simulations)",
                 f"{'coefficient':<16}{'equation error':>16}{'output error':>14}{'sigma':>11}{'sigma CRB':>11}"
                 f"{'change/sigma':>14}"]
        for k in self.names:
            s = self.sigma[k]
            ch = (self.estimate[k] - self.start[k]) / s if s > 0 else float("nan")
            lines.append(f"{k:<16}{self.start[k]:>16.5g}{self.estimate[k]:>14.5g}{s:>11.2g}{self.sigma_white[k]:>11.2g}"
                         f"{ch:>+14.1f}")
        lines.append("outputs: " + "; ".join(f"{o} noise {self.noise_std[o]:.3g}, TIC {self.tic_start[o]:.3f} -> "
                                             f"{self.tic_end[o]:.3f}" for o in self.noise_std))
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


def axis_coefficients(model: IdentifiedModel, axis: str) -> list[str]:
    """The coefficients of the model's channels that the axis's simulation reads."""
    return [t.coefficient for ch in AXIS_CHANNELS[axis] if ch in model.models for t in model.models[ch].terms]


def free_coefficients(model: IdentifiedModel, axis: str, free=None) -> list[str]:
    """The axis's coefficients to refine: `free` (each once; ValueError naming any outside the
    axis's channels, without a value to start from or fixed at the preflight database's value), or
    every identified one (not those in ``model.preflight``)."""
    own = axis_coefficients(model, axis)
    if free is None:
        return [k for k in own if math.isfinite(float(model.values[k])) and k not in model.preflight]
    names = list(dict.fromkeys(free))  # once each: a repeated name would be a zero sensitivity
    bad = [k for k in names if k not in own]
    if bad:
        raise ValueError(f"coefficient(s) {bad} are not in the {axis} axis's channels "
                         f"({', '.join(ch for ch in AXIS_CHANNELS[axis] if ch in model.models)}); its coefficients: "
                         f"{own}")
    fixed = [k for k in names if k in model.preflight]
    if fixed:
        raise ValueError(f"coefficient(s) {fixed} are the preflight database's, not estimates (alpha, beta are "
                         "inverted from their channel): leave them out of the refinement")
    unknown = [k for k in names if not math.isfinite(float(model.values[k]))]
    if unknown:
        raise ValueError(f"coefficient(s) {unknown} were not identifiable in the run (no value to start from): "
                         "leave them out of the refinement")
    return names


def _record_labels(spans: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """A record label per stacked sample of one output (rows: their row numbers): a new record
    at every change of span and at every hole (a sample not measured or left out) in a span."""
    return np.cumsum(np.r_[0, (spans[1:] != spans[:-1]) | (np.diff(rows) != 1)])


def output_error_fit(model: IdentifiedModel, inputs: pd.DataFrame, measured: pd.DataFrame, vehicle: Vehicle,
                     axis: str = "lon", free=None, controls: str = "linear", relaxations: int = RELAXATIONS,
                     max_nfev: int = 40, tol: float = 1e-8) -> OutputErrorFit:
    """Refine `model`'s `axis` coefficients (`free`: their names; default every identified one
    of the axis's channels) by output error on one manoeuvre.  inputs / measured: as
    :func:`aerosid.identification.output_prediction.predict_axis` takes them (rows with span
    >= 0 are fitted; measured holds the axis's outputs, NaN where not measured).  max_nfev
    and tol: each Gauss-Newton pass's budget of cost evaluations and its tolerances."""
    check_simulation_inputs(inputs, axis, controls, "output-error")
    names = free_coefficients(model, axis, free)
    if not names:
        raise ValueError(f"no identified coefficient to refine in the {axis} axis")
    inputs = inputs.reset_index(drop=True)
    outs = AXIS_OUTPUTS[axis]
    spans = inputs["span"].to_numpy()
    use = spans >= 0
    meas = np.column_stack([measured[o].to_numpy(float) if o in measured else np.full(len(inputs), np.nan)
                            for o in outs])
    ok = np.isfinite(meas) & use[:, None]
    outs_used = [j for j in range(len(outs)) if ok[:, j].sum() > 10]
    if not outs_used:
        raise ValueError(f"no measured {axis} output ({', '.join(outs)}) on the fitted rows")
    simulations = [0]

    def predict(x) -> np.ndarray:
        simulations[0] += 1
        return predicted_outputs(model, inputs, vehicle, axis, dict(zip(names, map(float, x))), controls)[0]

    def residual_matrix(pred) -> np.ndarray:
        return meas - pred - span_offsets(meas, pred, spans)

    def stacked(res, scale, diverged: float | None = DIVERGED_RESIDUAL) -> np.ndarray:
        """Output-major, time order within each output; diverged None: NaN stays NaN."""
        parts = [res[ok[:, j], j] / scale[j] for j in outs_used]
        v = np.concatenate(parts)
        return v if diverged is None else np.where(np.isfinite(v), v, diverged)

    x0 = np.array([float(model.values[k]) for k in names])
    pred0 = predict(x0)
    if not np.isfinite(pred0[use]).all():
        raise ValueError(f"the {axis} simulation of the starting model leaves the envelope: no output-error fit "
                         "from this start (validate the run first: aerosid validate)")
    def noise_levels(pred) -> np.ndarray:  # the residual std per output (1 for an unused one)
        res = residual_matrix(pred)
        out = np.array([float(np.nanstd(res[ok[:, j], j])) if j in outs_used else 1.0 for j in range(len(outs))])
        out[~(out > 0)] = 1.0
        return out

    scale = noise_levels(pred0)
    x, sol = x0, None
    for _ in range(max(1, int(relaxations))):
        sol = least_squares(lambda z: stacked(residual_matrix(predict(z)), scale), x, x_scale="jac",
                            method="trf", max_nfev=max_nfev, ftol=tol, xtol=tol, gtol=tol)
        x = sol.x
        pred = predict(x)
        new = noise_levels(pred)
        done = np.all(np.abs(new / scale - 1.0) < 0.01)
        scale = new
        if done:
            break
    # uncertainty at the solution (pred), with the final noise levels; samples a simulation
    # leaves the envelope on (at the solution or one step off it) carry no sensitivity: left out
    v = stacked(residual_matrix(pred), scale, None)
    J = np.empty((v.size, len(names)))  # sensitivities of the scaled outputs (central differences)
    for i in range(len(names)):
        h = SENSITIVITY_STEP * max(abs(x[i]), 1e-3)
        up, down = x.copy(), x.copy()
        up[i] += h
        down[i] -= h
        J[:, i] = (stacked(residual_matrix(predict(down)), scale, None)
                   - stacked(residual_matrix(predict(up)), scale, None)) / (2 * h)
    good = np.isfinite(v) & np.all(np.isfinite(J), axis=1)
    p = len(names)
    edges = np.cumsum([0] + [int(ok[:, j].sum()) for j in outs_used])
    blocks = [(j, slice(int(a), int(b))) for j, a, b in zip(outs_used, edges[:-1], edges[1:])]  # as `stacked`
    # an output with no more usable samples than coefficients adds nothing to either matrix
    for _, seg in blocks:
        if good[seg].sum() <= p:
            good[seg] = False
    if good.sum() <= p:
        raise ValueError(f"the {axis} simulations leave the envelope on all but {int(good.sum())} samples: "
                         "no uncertainty can be given (validate the run first: aerosid validate)")
    m_inv = np.linalg.pinv(J[good].T @ J[good])
    cov_white = m_inv * float(v[good] @ v[good]) / max(int(good.sum()) - p, 1)
    # Morelli-Klein, output by output (each with its own residual autocovariance, within each
    # record): the outputs' cross-covariances are left out (a diagonal approximation)
    middle, n_eff = np.zeros((p, p)), 0.0
    for j, seg in blocks:
        keep = good[seg]
        if not keep.any():
            continue
        rows = np.flatnonzero(ok[:, j])[keep]
        vj, Jj = v[seg][keep], J[seg][keep]
        labels = _record_labels(spans[rows], rows)
        mid, ne = morelli_klein_middle(Jj, vj, auto_max_lag(vj, groups=labels), _group_slices(labels))
        middle += mid
        n_eff += ne
    cov = m_inv @ middle @ m_inv * (n_eff / max(n_eff - p, 1.0))
    notes = []
    if not np.isfinite(pred[use]).all():
        notes.append("the refined model's simulation leaves the envelope in part of the manoeuvre")
    if (~good).any():
        notes.append(f"{int((~good).sum())} sample(s) where a simulation left the envelope are not in sigma")
    est = dict(zip(names, map(float, x)))
    tic = lambda P: {outs[j]: theil_inequality(meas[ok[:, j], j], (P + span_offsets(meas, P, spans))[ok[:, j], j])  # noqa: E731
                     for j in outs_used}
    return OutputErrorFit(
        axis=axis, names=tuple(names), start=dict(zip(names, map(float, x0))), estimate=est,
        sigma={k: float(math.sqrt(max(cov[i, i], 0.0))) for i, k in enumerate(names)},
        sigma_white={k: float(math.sqrt(max(cov_white[i, i], 0.0))) for i, k in enumerate(names)},
        noise_std={outs[j]: float(scale[j]) for j in outs_used}, tic_start=tic(pred0), tic_end=tic(pred),
        n_samples=int(use.sum()), n_spans=int(len(np.unique(spans[use]))), n_eff=float(n_eff),
        converged=bool(sol.status > 0), message=str(sol.message), nfev=simulations[0],
        model=model.with_values(**est), covariance=cov, notes=tuple(notes))
