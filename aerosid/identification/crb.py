"""Cramér–Rao bounds of a run's coefficients: the limit of what the flight's data can give.

What is bounded
---------------
For the coefficients θ of every channel (C_N, C_Y, C_l, C_m, C_n = X(t) θ), the
Cramér–Rao bound is the square root of the diagonal of M⁻¹, with the **output-error
information matrix**

    M = Σ_k S_kᵀ R_k⁻¹ S_k ,      S_k = ∂y_k/∂θ ,

over the regression's samples k.  y_k are the *measured outputs*: the three
accelerometers at their offset r from the CG and the three gyros (method.md §5);
R_k = diag(σ²) is the measurement-noise covariance the run estimated -- the R the
EKF used (``EBMResult.R_sigma``, carried per sample in the flight data as
``R_sigma_<channel>`` columns; a segment has one R).

How the sensitivities are computed (the documented choice)
----------------------------------------------------------
The outputs are simulated from the identified model **driven by the measured inputs**:
every signal a model term reads (α, β, the fin deflections, the band-limited rates, V,
...) is taken as the known input it is in the regression (the EBM partition), and
the outputs follow from the model through the rigid-body equations of method.md §5:

* CG specific forces  a_cg,y = q̄S/m · C_Y,  a_cg,z = −q̄S/m · C_N;
* aerodynamic angular accelerations (L1, M1, N1) = q̄S·(b C_l/I_xx, c C_m/I_yy, b C_n/I_zz);
* ω̇ = coupling(ω) + B (L1, M1, N1) (B from the inertia constants; the gyroscopic
  coupling is evaluated on the measured rates, an input like the others);
* the gyros see ω(t) = ω(t₀) + ∫ ω̇ dt over each contiguous run of samples -- the
  initial rates of every run are unknown nuisance parameters of the information matrix;
* the accelerometers see a_cg + ω̇ × r + ω × (ω × r).

The outputs are then linear in θ (and in the nuisance rates), so the sensitivity
equations integrate in closed form: S_ω(t) = ∫ B ∂(L1,M1,N1)/∂θ dt (trapezoidal rule on
the sample grid), S_a = ∂a_cg/∂θ + S_ω̇ × r + S_ω × (ω × r) + ω × (S_ω × r).  They equal
finite differences of the output simulation to rounding (a test checks it).  All
coefficients are bounded jointly (one information matrix, the lever arm couples the
channels); the bound of a coefficient is its diagonal element of the inverse, i.e. with
every other coefficient and the initial rates unknown.

What it is a bound of
---------------------
The variance of any unbiased estimator of θ from these gyros and accelerometers *if the
inputs were known exactly*.  The pipeline's regressors are measured (vanes, or angles
inverted from the accelerometers): errors in variables, the band limit, residual
colour and model error all put an estimator's scatter above it, never below.
``crb_linear`` gives the equation-error form σ·sqrt(diag((XᵀX)⁻¹)) of a static linear
model with white noise, which is what the force channels reduce to without a lever arm.
The ``crb_std`` column of coefficients.parquet is the output-error bound above.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from aerosid.vehicles.rigid_body import inertia_constants

#: Per-sample measurement-noise 1-sigma the run estimated (the EKF's R), flight-data columns,
#: in the order of the measured outputs (ax, ay, az, p, q, r).
OUTPUTS = ("ax", "ay", "az", "p", "q", "r")
R_COLUMNS = ("R_sigma_ax_m_s2", "R_sigma_ay_m_s2", "R_sigma_az_m_s2",
             "R_sigma_p_rad_s", "R_sigma_q_rad_s", "R_sigma_r_rad_s")
#: Channels whose coefficients act on a force (row of the specific force) and on a moment.
FORCE_AXIS = {"CY": (1, 1.0), "CN": (2, -1.0)}
MOMENT_AXIS = {"Cl": 0, "Cm": 1, "Cn": 2}
#: Relative eigenvalue below which a direction of the information matrix counts as unobserved.
RCOND = 1e-13


@dataclass(frozen=True)
class CramerRaoBounds:
    """Cramér–Rao bound on the std of each coefficient (same unit as the estimate).

    std: coefficient -> bound (NaN: not bounded, e.g. not identifiable or no noise R);
    n_samples, n_runs: samples and contiguous runs used; noise_sigma: median R 1-sigma of
    (ax, ay, az [m/s^2], p, q, r [rad/s]); method: how M was formed."""

    std: dict
    n_samples: int
    n_runs: int
    noise_sigma: tuple
    method: str = "output-error information, measured inputs, gyros + accelerometers"
    note: str = ""

    def summary(self) -> str:
        head = (f"Cramér–Rao bounds ({self.method}): {self.n_samples} samples in {self.n_runs} run(s), "
                f"noise sigma ax ay az {', '.join(f'{v:.3g}' for v in self.noise_sigma[:3])} m/s^2, "
                f"p q r {', '.join(f'{v:.3g}' for v in self.noise_sigma[3:])} rad/s")
        rows = [f"  {k:<20}{v:.3g}" for k, v in self.std.items()]
        return "\n".join([head, *rows, *([f"  note: {self.note}"] if self.note else [])])


def crb_linear(X: np.ndarray, sigma: float) -> np.ndarray:
    """Equation-error bound of y = X θ + white noise of 1-sigma ``sigma``: the std
    sqrt(diag(σ² (XᵀX)⁻¹)), one per column of X (NaN for a column the data cannot tell)."""
    X = np.asarray(X, float)
    return np.sqrt(np.diag(_inverse(X.T @ X)) * float(sigma) ** 2)


def _inverse(M: np.ndarray) -> np.ndarray:
    """Inverse of a symmetric information matrix, scaled to unit diagonal first; directions
    with relative eigenvalue < RCOND are unobserved: every parameter touching them gets inf."""
    M = 0.5 * (M + M.T)
    d = np.sqrt(np.clip(np.diag(M), 0.0, None))
    ok = d > 0
    out = np.full(M.shape, np.inf)
    if not ok.any():
        return out
    Ms = M[np.ix_(ok, ok)] / np.outer(d[ok], d[ok])
    w, V = np.linalg.eigh(Ms)
    good = w > RCOND * max(w.max(), 0.0)
    inv = (V[:, good] / w[good]) @ V[:, good].T
    bad = np.abs(V[:, ~good]).max(axis=1) > 1e-6 if (~good).any() else np.zeros(len(w), bool)
    inv = inv / np.outer(d[ok], d[ok])
    diag = np.diag(inv).copy()
    diag[bad] = np.inf
    np.fill_diagonal(inv, diag)
    out[np.ix_(ok, ok)] = inv
    return out


def runs_of(t_s: np.ndarray, groups=None, gap_factor: float = 1.5) -> list[slice]:
    """Contiguous runs of samples: split where a time step exceeds ``gap_factor`` x the median
    step, goes backwards, or the group (flight, segment) changes."""
    t = np.asarray(t_s, float)
    if t.size == 0:
        return []
    dt = np.diff(t)
    step = float(np.median(dt)) if dt.size else 1.0
    cut = (dt > gap_factor * step) | (dt <= 0)
    if groups is not None:
        g = np.asarray(groups)
        cut |= g[1:] != g[:-1]
    bounds = np.concatenate([[0], np.flatnonzero(cut) + 1, [t.size]])
    return [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


def rate_coupling_matrix(inertia_kg_m2) -> np.ndarray:
    """B with ω̇ = coupling(ω) + B (L1, M1, N1), L1..N1 = moment / inertia (method.md §5)."""
    c = inertia_constants(*[float(v) for v in inertia_kg_m2])
    return np.array([[c.c3 * c.Ixx, 0.0, c.c4 * c.Izz], [0.0, 1.0, 0.0], [c.c4 * c.Ixx, 0.0, c.c9 * c.Izz]])


def output_sensitivities(t_s: np.ndarray, dforce: np.ndarray, dmoment: np.ndarray, rates_rad_s: np.ndarray,
                         inertia_kg_m2, offset_m, runs: list[slice]) -> np.ndarray:
    """S (N, 6, P + 3·len(runs)): sensitivities of (ax, ay, az, p, q, r) at the sensor to the P
    parameters and to the initial rates (p, q, r) of every run (the last 3·len(runs) columns).

    dforce (N, 3, P): ∂a_cg/∂θ [m/s^2 per unit]; dmoment (N, 3, P): ∂(L1, M1, N1)/∂θ [rad/s^2
    per unit]; rates_rad_s (N, 3): the measured (band-limited) rates the lever-arm terms use."""
    t = np.asarray(t_s, float)
    n, _, p = dforce.shape
    nn = p + 3 * len(runs)
    B = rate_coupling_matrix(inertia_kg_m2)
    dwdot = np.zeros((n, 3, nn))
    dwdot[:, :, :p] = np.einsum("ij,njp->nip", B, dmoment)
    dw = np.zeros((n, 3, nn))
    for i, r in enumerate(runs):
        seg = dwdot[r]
        if seg.shape[0] > 1:
            h = np.diff(t[r])[:, None, None]
            dw[r.start + 1:r.stop] = np.cumsum(0.5 * h * (seg[1:] + seg[:-1]), axis=0)
        dw[r, :, p + 3 * i:p + 3 * i + 3] += np.eye(3)[None]
    dacc = np.zeros((n, 3, nn))
    dacc[:, :, :p] = dforce
    off = np.asarray(offset_m, float)
    if np.any(off != 0):
        w = np.asarray(rates_rad_s, float)
        wxr = np.cross(w, off)  # (N, 3)
        dacc += np.cross(dwdot, off[None, :, None], axisa=1, axisb=1, axisc=1)
        dacc += np.cross(dw, wxr[:, :, None], axisa=1, axisb=1, axisc=1)
        dacc += np.cross(w[:, :, None], np.cross(dw, off[None, :, None], axisa=1, axisb=1, axisc=1),
                         axisa=1, axisb=1, axisc=1)
    return np.concatenate([dacc, dw], axis=1)


def information_matrix(S: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """M = Σ_k S_kᵀ R_k⁻¹ S_k with R_k = diag(sigma_k²); S (N, m, P), sigma (m,) or (N, m)."""
    s = np.broadcast_to(np.asarray(sigma, float), S.shape[:2])
    Sw = S / s[:, :, None]
    Sw = Sw.reshape(-1, S.shape[2])
    return Sw.T @ Sw


def coefficient_bounds(fd: pd.DataFrame, vehicle, designs: dict, report: dict | None = None,
                       outputs: tuple = OUTPUTS) -> CramerRaoBounds:
    """The bounds of one identification.  fd: the flight data the fits used (t_s, flight,
    segment, qbar_pa, p/q/r_rad_s and the R_sigma_* columns); designs: channel ->
    (X (N, k) regressor matrix on fd's rows, names, usable (k,) bool -- False for a column the
    fit could not identify); report: channel -> bool, whether the channel's bounds are
    reported (an identity channel's coefficients stay unknown parameters but get NaN);
    outputs: the measured outputs whose information counts (default all six; e.g. the gyros
    alone: ("p", "q", "r"))."""
    names = [nm for ch, (X, nms, use) in designs.items() for nm, u in zip(nms, use) if u]
    nan_all = {nm: float("nan") for ch, (X, nms, use) in designs.items() for nm in nms}
    missing = [c for c in R_COLUMNS if c not in fd.columns]
    n = len(fd)
    if missing or n == 0:
        return CramerRaoBounds(nan_all, n, 0, (float("nan"),) * 6,
                               note=f"no measurement-noise R in the flight data (columns {missing}); "
                                    "re-run the pipeline to get the bounds" if missing else "no samples")
    sigma = fd[list(R_COLUMNS)].to_numpy(float)
    if not np.all(np.isfinite(sigma)) or np.any(sigma <= 0):
        return CramerRaoBounds(nan_all, n, 0, tuple(np.nanmedian(sigma, axis=0)), note="R not positive and finite")
    unknown = set(outputs) - set(OUTPUTS)
    if unknown:
        raise ValueError(f"unknown output(s) {sorted(unknown)}; the measured outputs are {OUTPUTS}")
    sigma_used = np.where(np.isin(np.array(OUTPUTS), list(outputs))[None, :], sigma, np.inf)
    qs = fd["qbar_pa"].to_numpy(float) * vehicle.S_m2
    lengths = {"Cl": vehicle.length_lateral_m, "Cm": vehicle.length_pitch_m, "Cn": vehicle.length_lateral_m}
    inertia = {"Cl": vehicle.Ixx_kg_m2, "Cm": vehicle.Iyy_kg_m2, "Cn": vehicle.Izz_kg_m2}
    P = len(names)
    dforce = np.zeros((n, 3, P))
    dmoment = np.zeros((n, 3, P))
    j = 0
    for ch, (X, nms, use) in designs.items():
        X = np.nan_to_num(np.asarray(X, float)[:, np.asarray(use, bool)])
        k = X.shape[1]
        if ch in FORCE_AXIS:
            axis, sign = FORCE_AXIS[ch]
            dforce[:, axis, j:j + k] = sign * (qs / vehicle.mass_kg)[:, None] * X
        elif ch in MOMENT_AXIS:
            dmoment[:, MOMENT_AXIS[ch], j:j + k] = (qs * lengths[ch] / inertia[ch])[:, None] * X
        j += k
    groups = fd["flight"].astype(str) + "/" + fd["segment"].astype(str) if {"flight", "segment"} <= set(fd) else None
    runs = runs_of(fd["t_s"].to_numpy(float), None if groups is None else groups.to_numpy())
    rates = fd[["p_rad_s", "q_rad_s", "r_rad_s"]].to_numpy(float)
    inert = (vehicle.Ixx_kg_m2, vehicle.Iyy_kg_m2, vehicle.Izz_kg_m2, vehicle.Ixz_kg_m2)
    S = output_sensitivities(fd["t_s"].to_numpy(float), dforce, dmoment, rates, inert, vehicle.accel_offset_m, runs)
    cov = _inverse(information_matrix(S, sigma_used))
    std = dict(nan_all)
    report = report or {}
    for i, nm in enumerate(names):
        ch = next(c for c, (X, nms, use) in designs.items() if nm in nms)
        if report.get(ch, True):
            v = cov[i, i]
            std[nm] = float(np.sqrt(v)) if np.isfinite(v) and v >= 0 else float("nan")
    method = CramerRaoBounds.method if tuple(outputs) == OUTPUTS else \
        f"output-error information, measured inputs, outputs {', '.join(outputs)} only"
    return CramerRaoBounds(std, n, len(runs), tuple(float(v) for v in np.median(sigma, axis=0)), method)


def identification_bounds(fd: pd.DataFrame, vehicle, models: dict, fits: dict, identities=(),
                          outputs: tuple = OUTPUTS) -> CramerRaoBounds:
    """The bounds of the fits of aerosid.identification.identify.identify: fd the flight data they used (inside
    the Mach window, sorted by flight and time), models/fits per channel, identities the
    channels reported without numbers."""
    from aerosid.modelling.models import vehicle_signals

    signals = vehicle_signals(fd, vehicle)
    designs = {ch: (model.design(signals)[0].to_numpy(float), model.names, np.asarray(fits[ch].identifiable))
               for ch, model in models.items() if ch in fits}
    return coefficient_bounds(fd, vehicle, designs, {ch: ch not in identities for ch in designs}, outputs)
