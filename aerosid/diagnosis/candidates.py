"""Candidate physical effects the diagnosis tests for (method.md §13).

Every entry of the simulator's catalogue (:data:`aerosid.modelling.effects.CATALOGUE`) is a
candidate under the *same name*; a few extra candidates cover effects the
simulator cannot hide (rate damping in roll and yaw, alpha-dot, Mach dependence
of the trim moment and of the fin effectiveness, non-linear force terms).  Each
candidate is one extra regressor ``coefficient * term`` in one channel, with a
one-line physical meaning.

Terms are written in the model-spec expression language (``aerosid.modelling.expressions``)
so that a finding can be pasted into a spec file (``alpha_dot_hat`` is alpha-dot
d/(2V) from a smoothing derivative of the recovered alpha, see aerosid.identification.derivatives).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aerosid.modelling.effects import CATALOGUE
from aerosid.modelling.expressions import evaluate

from aerosid.identification.derivatives import DERIVATIVE_HALF_WINDOW_S, smooth_derivative  # noqa: F401  (re-exported)


@dataclass(frozen=True)
class Candidate:
    """One candidate effect: ``channel += coefficient * term``."""

    name: str  # catalogue name for catalogue effects
    channel: str
    coefficient: str
    term: str  # expression over the signals (see aerosid.modelling.effects)
    meaning: str  # one line of physics
    catalogue: bool = False  # True: the simulator can hide it (aerosid simulate --effect NAME)
    addable: bool = True  # False: the term uses a derived signal the model specs do not offer
    alias_of: str | None = None  # when confusable with this candidate on a flight, it is reported under it

    @property
    def spec_term(self) -> str | None:
        """What to put in a model spec file to add it (None when not addable)."""
        if not self.addable:
            return None
        if self.catalogue or _EXTRA_NAMES.get(self.name) == (self.channel, self.coefficient):
            return self.name  # a model spec takes every default candidate by name (aerosid.modelling.models.parse_term)
        return f"{self.coefficient} = {self.term}"

    def regressor(self, signals: dict[str, np.ndarray]) -> np.ndarray:
        n = len(signals["alpha"])
        return evaluate(self.term, signals, n)


#: catalogue effects that only a cruciform finned body has
FINNED_ONLY = ("roll_orientation", "fin_misalignment")


def catalogue_candidates(mach_reference: float = 12.4, vehicle_class: str = "finned") -> tuple[Candidate, ...]:
    """The simulator's catalogue as candidates; Mach terms about the vehicle's own reference
    Mach; the cruciform-only effects are left out for an aircraft."""
    return tuple(Candidate(e.name, e.channel, e.coefficient,
                           e.term.replace("(mach - 12.4)", f"(mach - {mach_reference:g})"), e.description,
                           catalogue=True)
                 for e in CATALOGUE.values() if vehicle_class == "finned" or e.name not in FINNED_ONLY)


def extra_candidates(mach_reference: float = 12.4) -> tuple[Candidate, ...]:
    m = f"(mach - {mach_reference:g})"
    return (
        Candidate("alpha_dot", "Cm", "Cm_alpha_dot", "alpha_dot_hat",
                  "alpha-dot damping: the fins feel the body's downwash with a lag, Cm_alpha_dot * alpha_dot d/(2V)",
                  alias_of="pitch_damping"),
        Candidate("mach_cm0", "Cm", "Cm_0_mach", m,
                  "Mach dependence of the trim moment: Cm_0 drifts with Mach (base flow, boundary layer)"),
        Candidate("mach_cm_delta", "Cm", "Cm_delta_p_mach", f"delta_p/2*{m}",
                  "Mach dependence of pitch-fin effectiveness (fin pressure rise changes with Mach)"),
        Candidate("roll_damping", "Cl", "Cl_p", "p_hat",
                  "roll damping: the fins oppose the roll rate, Cl_p * p d/(2V)"),
        Candidate("roll_control_alpha", "Cl", "Cl_delta_r_alpha_r", "alpha_r*delta_r",
                  "roll-fin effectiveness changes with total angle of attack (leeward fin shielding)"),
        Candidate("yaw_damping", "Cn", "Cn_r", "r_hat",
                  "yaw damping: moment opposing yaw rate, Cn_r * r d/(2V)"),
        Candidate("beta_nonlinearity", "Cn", "Cn_beta_abs_beta", "beta*abs(beta)",
                  "non-linear directional stability: cross-flow force grows as beta|beta|"),
        Candidate("control_beta", "Cn", "Cn_beta_delta_y", "beta*delta_y/2",
                  "control-sideslip interaction: yaw-fin effectiveness changes with sideslip"),
        Candidate("cn_alpha_nonlinearity", "CN", "CN_alpha_abs_alpha", "alpha*abs(alpha)",
                  "non-linear normal force: cross-flow (viscous) lift grows as alpha|alpha|"),
        Candidate("mach_cn_alpha", "CN", "CN_alpha_mach", f"alpha*{m}",
                  "Mach dependence of the normal-force slope"),
        Candidate("cy_beta_nonlinearity", "CY", "CY_beta_abs_beta", "beta*abs(beta)",
                  "non-linear side force: cross-flow force grows as beta|beta|"),
    )


def aircraft_candidates() -> tuple[Candidate, ...]:
    """Effects of an aircraft's layout that its default model leaves out (docs/real-flight.md,
    "Writing the file by hand")."""
    return (
        Candidate("cm_abs_beta", "Cm", "Cm_abs_beta", "abs(beta)",
                  "pitching moment from sideslip: the drag grows with |beta| and acts above or below the CG "
                  "(an aerodynamic reference point off the CG's height; c182, c172x)"),
    )


def named_candidates(mach_reference: float = 12.4) -> dict[str, Candidate]:
    """The candidates a model spec accepts by name that are not catalogue effects: the extras and
    an aircraft's layout's."""
    return {c.name: c for c in extra_candidates(mach_reference) + aircraft_candidates()}


#: name -> (channel, coefficient) of the extra candidates: a model spec accepts them by name
_EXTRA_NAMES = {name: (c.channel, c.coefficient) for name, c in named_candidates().items()}


def default_candidates(mach_reference: float = 12.4, vehicle_class: str = "finned") -> tuple[Candidate, ...]:
    """The catalogue (same names as ``aerosid simulate --effect``) followed by the extras, and
    for an aircraft its layout's (aircraft_candidates)."""
    return (catalogue_candidates(mach_reference, vehicle_class) + extra_candidates(mach_reference)
            + (aircraft_candidates() if vehicle_class == "aircraft" else ()))


def derived_signals(signals: dict[str, np.ndarray], d_m: float, lateral_m: float | None = None
                    ) -> dict[str, np.ndarray]:
    """The model signals (aerosid.modelling.models.signals_from_flight_data, which holds alpha_dot_hat
    and beta_dot_hat with the regression's own derivative window) plus ``alpha_dot`` and
    ``beta_dot`` [rad/s] (d_m: pitch reference length [m]; lateral_m: that of beta_dot_hat,
    default d_m)."""
    out = dict(signals)
    two_v = 2.0 * signals["V"]
    out["alpha_dot"] = signals["alpha_dot_hat"] * two_v / d_m
    out["beta_dot"] = signals["beta_dot_hat"] * two_v / (d_m if lateral_m is None else lateral_m)
    return out
