"""The catalogue of aerodynamic effects the default linear models leave out.

The simulator hides them in a flight (``aerosid simulate --effect NAME``) and the
diagnosis looks for them.  Each effect is one extra term ``coefficient * term``
added to one channel's coefficient; ``term`` is written over the flight signals
(SI, radians):

    alpha, beta, alpha_r, phi_r   aerodynamic angles [rad]
    mach [-], V [m/s], qbar [Pa]
    delta_p, delta_y, delta_r     mixed fin deflections [rad] (the models use delta_p/2, delta_y/2)
    p, q, r                       body rates [rad/s]
    p_hat, q_hat, r_hat           p d/(2V), q d/(2V), r d/(2V) [-]

Sizes are physical, not tuned to be easy to find: see each ``sizing`` line.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

Signals = Mapping[str, np.ndarray]


@dataclass(frozen=True)
class Effect:
    """One catalogue effect: channel += value * term(signals)."""

    name: str
    channel: str  # CN, CY, Cl, Cm, Cn (moments about the CG)
    coefficient: str  # its name in truth.json / coefficients.parquet
    term: str  # the regressor, in the model-spec expression language
    description: str  # one line of physics
    sizing: str  # why this value is physical
    value: float  # default size [per unit of term]
    regressor: Callable[[Signals], np.ndarray]

    def contribution(self, signals: Signals, scale: float = 1.0) -> np.ndarray:
        """Increment of the channel coefficient [-] at the given scale of the default size."""
        return scale * self.value * np.asarray(self.regressor(signals), dtype=float)


CATALOGUE: dict[str, Effect] = {
    e.name: e
    for e in (
        Effect(
            name="pitch_damping",
            channel="Cm",
            coefficient="Cm_q",
            term="q_hat",
            description="pitch damping: moment opposing pitch rate, Cm_q * q d/(2V)",
            sizing="slender body with tail fins, Cm_q ~ -CN_alpha_fin (l_fin/d)^2 * 2 ~ -30 (per rad, d-based)",
            value=-30.0,
            regressor=lambda s: s["q_hat"],
        ),
        Effect(
            name="alpha_nonlinearity",
            channel="Cm",
            coefficient="Cm_alpha_abs_alpha",
            term="alpha*abs(alpha)",
            description="non-linear static stability: cross-flow (viscous) lift grows as alpha|alpha|",
            sizing="cross-flow drag Cd_c ~ 1.2 on the body behind the CG: |Cm| increment ~ 5 alpha^2",
            value=-5.0,
            regressor=lambda s: s["alpha"] * np.abs(s["alpha"]),
        ),
        Effect(
            name="mach_cm_alpha",
            channel="Cm",
            coefficient="Cm_alpha_mach",
            term="alpha*(mach - 12.4)",
            description="Mach dependence of static stability: the centre of pressure moves with Mach",
            sizing="hypersonic slender bodies: dCm_alpha/dM ~ 0.1 of Cm_alpha,cg per unit Mach",
            value=0.12,
            regressor=lambda s: s["alpha"] * (s["mach"] - 12.4),
        ),
        Effect(
            name="control_alpha",
            channel="Cm",
            coefficient="Cm_alpha_delta_p",
            term="alpha*delta_p/2",
            description="control-alpha interaction: fin effectiveness changes with angle of attack (windward fin compression)",
            sizing="fin effectiveness up ~ 20 % per 2 deg of alpha: 0.2 * Cm_delta_p / 0.035 rad",
            value=0.3,
            regressor=lambda s: s["alpha"] * s["delta_p"] / 2.0,
        ),
        Effect(
            name="roll_orientation",
            channel="Cl",
            coefficient="Cl_a2_sin4phi",
            term="alpha_r**2*sin(4*phi_r)",
            description="induced roll of a cruciform: fin-body vortices give Cl ~ alpha_r^2 sin(4 phi_r)",
            sizing="induced roll of cruciform missiles (Nielsen): ~0.2 alpha_r^2",
            value=0.2,
            regressor=lambda s: s["alpha_r"] ** 2 * np.sin(4.0 * s["phi_r"]),
        ),
        Effect(
            name="fin_misalignment",
            channel="Cl",
            coefficient="Cl_delta_p",
            term="delta_p/2",
            description="pitch-fin misalignment: fin 4 deflects 5 % more than fin 2 for the same pitch command "
                        "(hinge/linkage rigging), so every pitch command also rolls the vehicle",
            sizing="5 % effectiveness mismatch within a pitch pair (hinge/linkage rigging and fin-area tolerance) times "
                   "one fin's roll effectiveness (Cl_delta_r = -0.017 per rad of one fin): -0.017 * 0.05 per rad "
                   "of delta_p/2 (about 20 % of the Cl signal on seed-rlv). "
                   "A constant rigging offset would be identical to Cl_0 and could never be told apart from it",
            value=-0.017 * 0.05,
            regressor=lambda s: s["delta_p"] / 2.0,
        ),
    )
}


def parse_effect_spec(spec: str) -> tuple[Effect, float]:
    """``NAME`` or ``NAME=SCALE`` (SCALE multiplies the default size) -> (effect, scale)."""
    name, _, scale_text = spec.partition("=")
    name = name.strip()
    if name not in CATALOGUE:
        raise KeyError(f"unknown effect {name!r}; known: {', '.join(CATALOGUE)}")
    try:
        scale = float(scale_text) if scale_text else 1.0
    except ValueError as exc:
        raise ValueError(f"effect {spec!r}: scale {scale_text!r} is not a number") from exc
    return CATALOGUE[name], scale


def catalogue_table() -> str:
    """The catalogue as printed by ``aerosid simulate --list-effects``."""
    width = max(len(n) for n in CATALOGUE)
    lines = [f"{e.name:<{width}}  [{e.channel}, {e.coefficient} * {e.term}]  {e.description}" for e in CATALOGUE.values()]
    return "\n".join(lines)
