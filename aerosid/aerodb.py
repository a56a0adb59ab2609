"""The preflight aerodynamic database: tables over (Mach, alpha_r, phi_r).

File format (CSV, one row per grid point, SI/radians):
``mach, alpha_r_rad, phi_r_rad, CN_R, Cm_R_nose, Cl, CA``.  The grid must be a
full rectangular product.  C_N^R and C_m^R (nose) do not depend on phi_r for a
cruciform body but are repeated on every phi_r row so that the file is one plain
table an engineer can open.  Interpolation is linear (scipy RegularGridInterpolator).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.interpolate import RegularGridInterpolator

from aerosid.modelling.aeromodel import AeroModel

COLUMNS = ["mach", "alpha_r_rad", "phi_r_rad", "CN_R", "Cm_R_nose", "Cl", "CA"]

MACH_GRID = (2.0, 3.0, 4.0, 6.0, 8.0, 10.0, 11.0, 12.4, 14.0, 16.0, 20.0)
ALPHA_R_GRID_DEG = tuple(float(a) for a in range(0, 21))
PHI_R_GRID_DEG = tuple(float(p) for p in range(-180, 181, 5))


def tabulate(model: AeroModel) -> pd.DataFrame:
    """Tabulate a (preflight) model on the standard grid, controls at zero."""
    m, a, f = np.meshgrid(MACH_GRID, np.deg2rad(ALPHA_R_GRID_DEG), np.deg2rad(PHI_R_GRID_DEG), indexing="ij")
    c = model.coefficients(a, f, m, 0.0, 0.0, 0.0)
    aero = model.aero
    k = aero.slope_multiplier(m)
    # resultant-plane quantities straight from the model (controls and offsets excluded)
    frame = pd.DataFrame(
        {
            "mach": m.ravel(),
            "alpha_r_rad": a.ravel(),
            "phi_r_rad": f.ravel(),
            "CN_R": (aero.CN_alpha * k * a).ravel(),
            "Cm_R_nose": (aero.Cm_alpha_nose * k * a).ravel(),
            "Cl": (c["Cl"]).ravel(),
            "CA": (c["CA"]).ravel(),
        }
    )
    return frame


@dataclass(frozen=True)
class AeroDatabase:
    """Interpolating tables. Angles [rad]; coefficients [-]."""

    mach: np.ndarray
    alpha_r_rad: np.ndarray
    phi_r_rad: np.ndarray
    CN_R: np.ndarray  # (n_mach, n_alpha)
    Cm_R_nose: np.ndarray  # (n_mach, n_alpha)
    Cl: np.ndarray  # (n_mach, n_alpha, n_phi)
    CA: np.ndarray  # (n_mach, n_alpha)
    source: str = "<memory>"

    @classmethod
    def from_frame(cls, frame: pd.DataFrame, source: str = "<memory>") -> "AeroDatabase":
        missing = [c for c in COLUMNS if c not in frame.columns]
        if missing:
            raise ValueError(f"{source}: aero database lacks column(s) {missing}")
        mach = np.unique(frame["mach"].to_numpy(float))
        alpha = np.unique(frame["alpha_r_rad"].to_numpy(float))
        phi = np.unique(frame["phi_r_rad"].to_numpy(float))
        if len(frame) != len(mach) * len(alpha) * len(phi):
            raise ValueError(f"{source}: aero database is not a full (mach x alpha_r x phi_r) grid: "
                             f"{len(frame)} rows for {len(mach)}x{len(alpha)}x{len(phi)}")
        f = frame.sort_values(["mach", "alpha_r_rad", "phi_r_rad"])
        shape = (len(mach), len(alpha), len(phi))

        def grid(col):
            values = f[col].to_numpy(float).reshape(shape)
            if not np.all(np.isfinite(values)):
                raise ValueError(f"{source}: column {col} holds non-finite values")
            return values

        return cls(mach, alpha, phi, grid("CN_R")[:, :, 0], grid("Cm_R_nose")[:, :, 0], grid("Cl"),
                   grid("CA")[:, :, 0], source)

    @classmethod
    def load(cls, path: str | Path) -> "AeroDatabase":
        return cls.from_frame(pd.read_csv(path), str(path))

    def _interp2(self, table, alpha_r, mach):
        fn = RegularGridInterpolator((self.mach, self.alpha_r_rad), table, bounds_error=False, fill_value=None)
        a, m = np.broadcast_arrays(np.asarray(alpha_r, float), np.asarray(mach, float))
        return fn(np.stack([m.ravel(), a.ravel()], axis=-1)).reshape(a.shape)

    def cn_r(self, alpha_r, mach):
        """Resultant normal force C_N^R(alpha_r, M) [-]."""
        return self._interp2(self.CN_R, alpha_r, mach)

    def cm_r_nose(self, alpha_r, mach):
        """Resultant pitching moment about the nose C_m^R(alpha_r, M) [-]."""
        return self._interp2(self.Cm_R_nose, alpha_r, mach)

    def cl(self, alpha_r, phi_r, mach):
        """Rolling moment C_l(alpha_r, phi_r, M) [-] (controls at zero)."""
        fn = RegularGridInterpolator((self.mach, self.alpha_r_rad, self.phi_r_rad), self.Cl,
                                     bounds_error=False, fill_value=None)
        a, f, m = np.broadcast_arrays(np.asarray(alpha_r, float), np.asarray(phi_r, float), np.asarray(mach, float))
        wrapped = np.angle(np.exp(1j * f))
        return fn(np.stack([m.ravel(), a.ravel(), wrapped.ravel()], axis=-1)).reshape(a.shape)

    def mach_range(self) -> tuple[float, float]:
        return float(self.mach[0]), float(self.mach[-1])
