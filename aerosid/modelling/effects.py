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

import math

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
            sizing="Cm_q = -2 sum CN_alpha,i ((x_i - x_cg)/d)^2 over the normal-force distribution of the 4.5 m "
                   "body and its tail fins: -10 ... -30 per rad (d-based); the upper end is taken. At M 12 "
                   "q d/(2V) ~ 1e-5, so it moves Cm by only ~5 % of its variation",
            value=-30.0,
            regressor=lambda s: s["q_hat"],
        ),
        Effect(
            name="alpha_nonlinearity",
            channel="Cm",
            coefficient="Cm_alpha_abs_alpha",
            term="alpha*abs(alpha)",
            description="non-linear static stability: cross-flow (viscous) lift grows as alpha|alpha|",
            sizing="viscous cross-flow (Allen & Perkins): CN_cf = eta Cd_c (S_plan/S) alpha^2 ~ 0.6*1.2*5.7 alpha^2 "
                   "acting ~0.58 d behind the CG, Cm_cf ~ -2.4 alpha^2; the flight's cross-flow ~18 % stronger than "
                   "the preflight database's: -0.43 alpha|alpha| (~25 % of the Cm variation on seed-rlv)",
            value=-0.43,
            regressor=lambda s: s["alpha"] * np.abs(s["alpha"]),
        ),
        Effect(
            name="mach_cm_alpha",
            channel="Cm",
            coefficient="Cm_alpha_mach",
            term="alpha*(mach - 12.4)",
            description="Mach dependence of static stability: the centre of pressure moves with Mach",
            sizing="centre of pressure moving aft by 3.5 % of d per unit Mach (hypersonic slender bodies are nearly "
                   "Mach independent): dCm_alpha/dM = CN_alpha * 0.035 = 0.06 per rad (~25 % of the Cm variation)",
            value=0.06,
            regressor=lambda s: s["alpha"] * (s["mach"] - 12.4),
        ),
        Effect(
            name="control_alpha",
            channel="Cm",
            coefficient="Cm_alpha_delta_p",
            term="alpha*delta_p/2",
            description="control-alpha interaction: fin effectiveness changes with angle of attack (windward fin compression)",
            sizing="windward-fin compression raises the pitch fins' effectiveness ~ 12 % per 2 deg of alpha: "
                   "0.12 * Cm_delta_p / 0.035 rad = 0.15 (~25 % of the Cm variation)",
            value=0.15,
            regressor=lambda s: s["alpha"] * s["delta_p"] / 2.0,
        ),
        Effect(
            name="roll_orientation",
            channel="Cl",
            coefficient="Cl_a2_sin4phi",
            term="alpha_r**2*sin(4*phi_r)",
            description="induced roll of a cruciform: fin-body vortices give Cl ~ alpha_r^2 sin(4 phi_r)",
            sizing="induced roll of cruciform missiles (Nielsen): ~0.17 alpha_r^2 (~25 % of the Cl variation)",
            value=0.17,
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


def parse_scaled_spec(spec: str, table: dict, what: str = "effect"):
    """``NAME`` or ``NAME=SCALE`` (SCALE multiplies the default size) -> (table[NAME], scale);
    KeyError for an unknown name, ValueError for a scale that is not a finite number."""
    name, _, scale_text = spec.partition("=")
    name = name.strip()
    if name not in table:
        raise KeyError(f"unknown {what} {name!r}; known: {', '.join(table)}")
    try:
        scale = float(scale_text) if scale_text else 1.0
    except ValueError as exc:
        raise ValueError(f"{what} {spec!r}: scale {scale_text!r} is not a number") from exc
    if not math.isfinite(scale):
        raise ValueError(f"{what} {spec!r}: scale must be finite")
    return table[name], scale


def parse_effect_spec(spec: str) -> tuple[Effect, float]:
    """``NAME`` or ``NAME=SCALE`` (SCALE multiplies the default size) -> (effect, scale)."""
    return parse_scaled_spec(spec, CATALOGUE, "effect")


def catalogue_table() -> str:
    """The catalogue as printed by ``aerosid simulate --list-effects``."""
    width = max(len(n) for n in CATALOGUE)
    lines = [f"{e.name:<{width}}  [{e.channel}, {e.coefficient} * {e.term}]  {e.description}" for e in CATALOGUE.values()]
    return "\n".join(lines)
