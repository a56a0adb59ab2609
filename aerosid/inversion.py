"""Angle of attack and sideslip from the preflight force database (method.md §10).

Unknowns per sample: (alpha_r, phi_r, alpha, beta) with

    tan alpha = tan alpha_r cos phi_r,   tan beta = tan alpha_r sin phi_r
    C_N(alpha) =  C_N^R(alpha_r, M) cos phi_r     (control and offset removed first)
    C_Y(beta)  = -C_N^R(alpha_r, M) sin phi_r

The seed minimised J = e1^2 + e2^2 + e3^2 with fmincon per sample.  Where the
table C_N^R(., M) is monotone in alpha_r (checked per sample) the minimum is
J = 0 and has a closed form, computed here for all samples at once:

    C_N^R target = hypot(C_N, C_Y),  phi_r = atan2(-C_Y, C_N),
    alpha_r      = inverse of the piecewise-linear table at the sample's Mach.

Where the target lies outside the table (alpha_r beyond its last row), alpha_r is
clipped to the table edge and J > 0 says so; where a sample's table is not
monotone, a bounded scalar search finds the alpha_r of least J.  J is reported
per sample either way.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from aerosid.vehicles.aerodb import AeroDatabase
from aerosid.vehicles.vehicle import PreflightAero


@dataclass(frozen=True)
class Inversion:
    """Per-sample result [rad]; J the residual cost [-]; clipped where outside the table."""

    alpha_r_rad: np.ndarray
    phi_r_rad: np.ndarray
    alpha_rad: np.ndarray
    beta_rad: np.ndarray
    J: np.ndarray
    clipped: np.ndarray
    n_searched: int  # samples that needed the scalar search (non-monotone table)

    def summary(self) -> str:
        return (f"alpha/beta inversion: {len(self.J)} samples, max J {np.nanmax(self.J):.2e}, "
                f"{int(self.clipped.sum())} outside the table, {self.n_searched} by scalar search")


def total_angles(alpha_rad, beta_rad) -> tuple[np.ndarray, np.ndarray]:
    """Total angle of attack alpha_r and aerodynamic roll angle phi_r [rad] from alpha and
    beta [rad] (the inverse of alpha = atan(tan alpha_r cos phi_r), beta = atan(tan alpha_r sin phi_r))."""
    ta, tb = np.tan(alpha_rad), np.tan(beta_rad)
    return np.arctan(np.hypot(ta, tb)), np.arctan2(tb, ta)


def aero_force_targets(CN, CY, delta_p, delta_y, aero: PreflightAero):
    """Remove the preflight control (and offset) parts: the angle-only force coefficients."""
    cn_alpha = np.asarray(CN, float) - aero.CN_0 - aero.CN_delta_p * np.asarray(delta_p, float) / 2.0
    cy_beta = np.asarray(CY, float) - aero.CY_delta_y * np.asarray(delta_y, float) / 2.0
    return cn_alpha, cy_beta


def _table_at_mach(db: AeroDatabase, mach: np.ndarray) -> np.ndarray:
    """C_N^R on the alpha_r grid at each sample's Mach, (N, n_alpha), linear in Mach
    (the same bilinear interpolation AeroDatabase.cn_r uses, clamped at the ends)."""
    m = np.clip(mach, db.mach[0], db.mach[-1])
    i = np.clip(np.searchsorted(db.mach, m, side="right") - 1, 0, len(db.mach) - 2)
    w = (m - db.mach[i]) / (db.mach[i + 1] - db.mach[i])
    return (1.0 - w)[:, None] * db.CN_R[i] + w[:, None] * db.CN_R[i + 1]


def invert_alpha_beta(CN, CY, mach, delta_p, delta_y, db: AeroDatabase, aero: PreflightAero) -> Inversion:
    """(alpha_r, phi_r, alpha, beta) per sample from flight C_N, C_Y [-], Mach [-] and
    the pitch/yaw deflections delta_p, delta_y [rad] (the models use delta/2)."""
    cn, cy = aero_force_targets(CN, CY, delta_p, delta_y, aero)
    mach = np.asarray(mach, float)
    target = np.hypot(cn, cy)
    phi_r = np.arctan2(-cy, cn)
    table = _table_at_mach(db, mach)
    grid = db.alpha_r_rad
    monotone = np.all(np.diff(table, axis=1) > 0, axis=1)
    n = len(target)
    alpha_r = np.full(n, np.nan)
    # closed form: find the cell with table[j] <= target < table[j+1]
    j = np.sum(table <= target[:, None], axis=1) - 1
    j = np.clip(j, 0, len(grid) - 2)
    rows = np.arange(n)
    lo, hi = table[rows, j], table[rows, j + 1]
    frac = np.clip((target - lo) / (hi - lo), 0.0, 1.0)
    alpha_r = grid[j] + frac * (grid[j + 1] - grid[j])
    clipped = (target > table[:, -1]) | (target < table[:, 0])
    searched = np.flatnonzero(~monotone & np.isfinite(target))
    for k in searched:
        res = minimize_scalar(lambda a: (np.interp(a, grid, table[k]) - target[k]) ** 2,
                              bounds=(grid[0], grid[-1]), method="bounded", options={"xatol": 1e-10})
        alpha_r[k] = res.x
    cnr_db = np.array([np.interp(a, grid, t) for a, t in zip(alpha_r[searched], table[searched])])
    cnr = np.einsum("ij,ij->i", _interp_weights(alpha_r, grid), table)
    if len(searched):
        cnr[searched] = cnr_db
    e1 = cy - (-cnr * np.sin(phi_r))
    e2 = cn - cnr * np.cos(phi_r)
    e3 = target - cnr
    J = e1 * e1 + e2 * e2 + e3 * e3
    ta = np.tan(alpha_r)
    bad = ~np.isfinite(target)
    for arr in (alpha_r, phi_r, J):
        arr[bad] = np.nan
    return Inversion(
        alpha_r_rad=alpha_r,
        phi_r_rad=phi_r,
        alpha_rad=np.arctan(ta * np.cos(phi_r)),
        beta_rad=np.arctan(ta * np.sin(phi_r)),
        J=J,
        clipped=clipped & ~bad,
        n_searched=len(searched),
    )


def _interp_weights(x: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """(N, n_grid) linear-interpolation weights of x on grid (clamped)."""
    xc = np.clip(np.nan_to_num(x, nan=grid[0]), grid[0], grid[-1])
    j = np.clip(np.searchsorted(grid, xc, side="right") - 1, 0, len(grid) - 2)
    f = (xc - grid[j]) / (grid[j + 1] - grid[j])
    w = np.zeros((len(x), len(grid)))
    rows = np.arange(len(x))
    w[rows, j] = 1.0 - f
    w[rows, j + 1] += f
    return w
