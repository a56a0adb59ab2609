"""Analytic aerodynamic model of a cruciform slender body (preflight or flight).

Resultant-plane formulation (method.md §10): the normal force and pitching
moment act in the plane of the total angle of attack alpha_r, whose orientation
is the aerodynamic roll angle phi_r.  With k(M) the Mach multiplier of the
slopes:

    CN_R      = CN_alpha k alpha_r                 C_mR(nose) = Cm_alpha_nose k alpha_r
    CN        = CN_R cos phi_r + CN_0 + CN_delta_p delta_p/2          (normal force, up)
    CY        = -CN_R sin phi_r + CY_delta_y delta_y/2                (side force, right)
    Cm(nose)  = C_mR cos phi_r + Cm_0_nose + Cm_delta_p_nose delta_p/2
    Cn(nose)  = -C_mR sin phi_r + Cn_delta_y_nose delta_y/2
    Cm(cg)    = Cm(nose) + CN x_cg/d          Cn(cg) = Cn(nose) + CY x_cg/d
    Cl        = Cl_0 + Cl_alpha_r alpha_r + Cl_cos4phi cos 4 phi_r + Cl_delta_r delta_r
    CA        = CA_0 + CA_alpha2 alpha_r^2

plus any catalogue effects (aerosid.modelling.effects).  The body-axis force
coefficients are (C_X, C_Y, C_Z) = (-CA, CY, -CN).  Everything is vectorised.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

from aerosid.modelling.effects import Effect
from aerosid.vehicles.vehicle import PreflightAero, Vehicle


@dataclass(frozen=True)
class AeroModel:
    """Aerodynamic coefficients of one vehicle: preflight values, optionally with
    flight deviations and hidden effects (effect, scale)."""

    aero: PreflightAero
    xcg_over_d: float
    d_m: float
    effects: tuple[tuple[Effect, float], ...] = ()

    @classmethod
    def preflight(cls, vehicle: Vehicle) -> "AeroModel":
        return cls(vehicle.preflight, vehicle.xcg_over_d, vehicle.d_m)

    def with_deviations(self, **values: float) -> "AeroModel":
        known = {f.name for f in fields(PreflightAero)}
        unknown = set(values) - known
        if unknown:
            raise KeyError(f"unknown aerodynamic coefficient(s) {sorted(unknown)}; known: {sorted(known)}")
        return replace(self, aero=replace(self.aero, **values))

    def with_effects(self, effects: tuple[tuple[Effect, float], ...]) -> "AeroModel":
        return replace(self, effects=tuple(effects))

    def coefficients(self, alpha_r, phi_r, mach, delta_p, delta_y, delta_r, p=0.0, q=0.0, r=0.0, V=1.0, qbar=1.0):
        """Coefficients (CA, CY, CN, Cl, Cm, Cn) with moments about the CG.

        alpha_r, phi_r [rad]; mach [-]; delta_p, delta_y, delta_r mixed fin
        deflections [rad]; p, q, r body rates [rad/s] and V [m/s] (for the rate
        terms of effects); qbar [Pa] (for effects that use it).
        """
        a = self.aero
        k = a.slope_multiplier(mach)
        cnr = a.CN_alpha * k * alpha_r
        cmr = a.Cm_alpha_nose * k * alpha_r
        cphi, sphi = np.cos(phi_r), np.sin(phi_r)
        cn = cnr * cphi + a.CN_0 + a.CN_delta_p * delta_p / 2.0
        cy = -cnr * sphi + a.CY_delta_y * delta_y / 2.0
        cm = cmr * cphi + a.Cm_0_nose + a.Cm_delta_p_nose * delta_p / 2.0 + cn * self.xcg_over_d
        cnn = -cmr * sphi + a.Cn_delta_y_nose * delta_y / 2.0 + cy * self.xcg_over_d
        cl = a.Cl_0 + a.Cl_alpha_r * alpha_r + a.Cl_cos4phi * np.cos(4.0 * phi_r) + a.Cl_delta_r * delta_r
        ca = a.CA_0 + a.CA_alpha2 * alpha_r * alpha_r
        out = {"CA": ca, "CY": cy, "CN": cn, "Cl": cl, "Cm": cm, "Cn": cnn}
        if self.effects:
            signals = flight_signals(alpha_r, phi_r, mach, delta_p, delta_y, delta_r, p, q, r, V, qbar, self.d_m)
            for effect, scale in self.effects:
                out[effect.channel] = out[effect.channel] + effect.contribution(signals, scale)
        return out

    def linear_truth(self) -> dict[str, float]:
        """The coefficients of the linear models (method.md §11) at the reference
        Mach, SI per radian, moments about the CG, named as in truth.json."""
        a, x = self.aero, self.xcg_over_d
        cm_alpha = a.Cm_alpha_nose + a.CN_alpha * x
        truth = {
            "CN_0": a.CN_0,
            "CN_alpha": a.CN_alpha,
            "CN_delta_p": a.CN_delta_p,
            "Cm_0": a.Cm_0_nose + a.CN_0 * x,
            "Cm_alpha": cm_alpha,
            "Cm_delta_p": a.Cm_delta_p_nose + a.CN_delta_p * x,
            "CY_0": 0.0,
            "CY_beta": -a.CN_alpha,
            "CY_delta_y": a.CY_delta_y,
            "Cn_0": 0.0,
            "Cn_beta": -cm_alpha,
            "Cn_delta_y": a.Cn_delta_y_nose + a.CY_delta_y * x,
            "Cl_0": a.Cl_0,
            "Cl_alpha_r": a.Cl_alpha_r,
            "Cl_cos4phi": a.Cl_cos4phi,
            "Cl_delta_r": a.Cl_delta_r,
        }
        for effect, scale in self.effects:
            truth[effect.coefficient] = truth.get(effect.coefficient, 0.0) + scale * effect.value
        return truth


def flight_signals(alpha_r, phi_r, mach, delta_p, delta_y, delta_r, p, q, r, V, qbar, d_m):
    """The named signals effect terms and model specs are written over (aerosid.modelling.effects)."""
    alpha_r = np.asarray(alpha_r, dtype=float)
    ta = np.tan(alpha_r)
    two_v = 2.0 * np.asarray(V, dtype=float)
    return {
        "alpha": np.arctan(ta * np.cos(phi_r)),
        "beta": np.arctan(ta * np.sin(phi_r)),
        "alpha_r": alpha_r,
        "phi_r": np.asarray(phi_r, dtype=float),
        "mach": np.asarray(mach, dtype=float),
        "V": np.asarray(V, dtype=float),
        "qbar": np.asarray(qbar, dtype=float),
        "delta_p": np.asarray(delta_p, dtype=float),
        "delta_y": np.asarray(delta_y, dtype=float),
        "delta_r": np.asarray(delta_r, dtype=float),
        "p": np.asarray(p, dtype=float),
        "q": np.asarray(q, dtype=float),
        "r": np.asarray(r, dtype=float),
        "p_hat": p * d_m / two_v,
        "q_hat": q * d_m / two_v,
        "r_hat": r * d_m / two_v,
    }


def per_degree(name: str, value: float) -> float:
    """A coefficient per radian -> per degree when its name says it is a slope."""
    slope = not (name.endswith("_0") or name == "Cl_cos4phi")
    return value * math.pi / 180.0 if slope else value
