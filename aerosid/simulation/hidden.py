"""Effects the simulator can hide that are NOT in the diagnosis catalogue.

They test the diagnosis' *localisation* (``aerosid.diagnosis.localise``): none of
them is a candidate of :func:`aerosid.diagnosis.default_candidates`, so the
catalogue test cannot name them, and the localisation has to say where the model
fails and suggest a term.  ``aerosid simulate --hidden NAME[=SCALE]`` hides one;
its truth goes to truth.json under ``hidden_effects`` (and the coefficient of the
term that models it, to first order, under ``coefficients``).

    alpha_cubic        Cm += Cm_alpha3 alpha^3                      (a shape: cubic in alpha)
    pitch_control_lag  Cm's fin term uses delta_p(t - tau), tau = 40 ms (a lag)
    cm_alpha_drift     Cm_alpha(t) = Cm_alpha (1 - 0.08 t / 90 s)   (a coefficient drifting with time)

Each is at most 25 % of the Cm variation on seed-rlv (std of its contribution /
std of the true Cm over |M - 12.4| <= 0.5; ``bench/results/localisation.md``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from aerosid.modelling.aeromodel import AeroModel, flight_signals

#: Flight time over which the drift reaches its stated change [s] (the 90 s reference flight).
DRIFT_REFERENCE_S = 90.0


@dataclass(frozen=True)
class HiddenEffect:
    """One uncatalogued effect in one channel; ``value`` at scale 1 in its own unit."""

    name: str
    channel: str
    kind: str  # "shape", "lag" or "drift": what the localisation should find
    coefficient: str  # truth.json name of the first-order model term's coefficient
    term: str  # that term, in the model-spec expression language
    description: str
    sizing: str
    value: float  # Cm_alpha3 [-/rad^3]; lag [s]; relative change of Cm_alpha over DRIFT_REFERENCE_S [-]

    def truth(self, model: AeroModel, scale: float) -> dict:
        """The truth.json entry: size, and the coefficient of ``term`` that models it (to first order)."""
        lin = AeroModel.linear_truth(model)  # without the hidden terms (no recursion)
        v = scale * self.value
        doc = {"name": self.name, "scale": scale, "channel": self.channel, "kind": self.kind,
               "coefficient": self.coefficient, "term": self.term, "description": self.description}
        if self.kind == "shape":
            doc["coefficient_value"] = v
        elif self.kind == "lag":
            # Cm_delta_p delta_p(t - tau)/2 ~ Cm_delta_p delta_p/2 - tau Cm_delta_p delta_p_dot/2
            doc["lag_s"] = v
            doc["coefficient_value"] = -v * lin["Cm_delta_p"]
        else:
            doc["relative_change"] = v
            doc["over_s"] = DRIFT_REFERENCE_S
            doc["coefficient_value"] = v * lin["Cm_alpha"] / DRIFT_REFERENCE_S
        return doc


HIDDEN: dict[str, HiddenEffect] = {
    e.name: e
    for e in (
        HiddenEffect(
            name="alpha_cubic", channel="Cm", kind="shape", coefficient="Cm_alpha3", term="alpha**3",
            description="cubic static stability: the pitching moment bends as alpha^3 (vortex lift on the "
                        "body's lee side growing faster than alpha|alpha| at the larger angles)",
            sizing="-4.8 alpha^3: at 6 deg (0.105 rad) 21 % of the linear Cm_alpha alpha term there; "
                   "about 25 % of the Cm variation on seed-rlv (the catalogue's alpha_nonlinearity: 26 %)",
            value=-4.8,
        ),
        HiddenEffect(
            name="pitch_control_lag", channel="Cm", kind="lag", coefficient="Cm_delta_p_dot",
            term="delta_p_dot/2",
            description="control lag: the pitch fins' moment follows the measured deflection 40 ms late "
                        "(flow establishment over the fin / actuator position sensed upstream of the linkage)",
            sizing="40 ms transport delay of the fin moment: Cm_delta_p (delta_p(t - 0.04) - delta_p(t))/2; "
                   "at the 0.3-1 Hz manoeuvres and the rate autopilot's faster activity about 10-20 % of "
                   "the Cm variation",
            value=0.040,
        ),
        HiddenEffect(
            name="cm_alpha_drift", channel="Cm", kind="drift", coefficient="Cm_alpha_t", term="alpha*t",
            description="static stability drifting with time, as a centre-of-gravity drift would make it: "
                        "Cm_alpha changes by -8 % over 90 s",
            sizing="-8 % of Cm_alpha in 90 s is a CG shift of 0.08 |Cm_alpha| / CN_alpha d = 1.2 % of d "
                   "(12 mm; propellant or coolant migration, ablation)",
            value=-0.08,
        ),
    )
}


def parse_hidden_spec(spec: str) -> tuple[HiddenEffect, float]:
    """``NAME`` or ``NAME=SCALE`` -> (hidden effect, scale)."""
    from aerosid.modelling.effects import parse_scaled_spec

    return parse_scaled_spec(spec, HIDDEN, "hidden (uncatalogued) effect")


def hidden_table() -> str:
    """The uncatalogued effects as printed by ``aerosid simulate --list-effects``."""
    width = max(len(n) for n in HIDDEN)
    lines = ["", "Not in the diagnosis catalogue (for testing localisation; aerosid simulate --hidden NAME):"]
    lines += [f"{e.name:<{width}}  [{e.channel}, {e.kind}; models as {e.coefficient} * {e.term}]  {e.description}"
              for e in HIDDEN.values()]
    return "\n".join(lines)


@dataclass(frozen=True)
class HiddenAeroModel(AeroModel):
    """The flight aerodynamics plus uncatalogued effects; the plant passes it the time and
    the lagged pitch deflection as extra control entries (see :func:`lagged_controller`)."""

    hidden: tuple = ()  # ((HiddenEffect, scale), ...)

    def coefficients(self, alpha_r, phi_r, mach, delta_p, delta_y, delta_r, p=0.0, q=0.0, r=0.0, V=1.0, qbar=1.0,
                     t_s=0.0, delta_p_lagged=None):
        out = super().coefficients(alpha_r, phi_r, mach, delta_p, delta_y, delta_r, p, q, r, V, qbar)
        if not self.hidden:
            return out
        lin = super().linear_truth()
        alpha = flight_signals(alpha_r, phi_r, mach, delta_p, delta_y, delta_r, p, q, r, V, qbar, self.d_m)["alpha"]
        for e, scale in self.hidden:
            if e.kind == "shape":
                add = scale * e.value * alpha ** 3
            elif e.kind == "lag":
                lagged = delta_p if delta_p_lagged is None else delta_p_lagged
                add = lin["Cm_delta_p"] * (np.asarray(lagged, float) - np.asarray(delta_p, float)) / 2.0
            else:
                add = scale * e.value * lin["Cm_alpha"] * alpha * np.asarray(t_s, float) / DRIFT_REFERENCE_S
            out[e.channel] = out[e.channel] + add
        return out

    def linear_truth(self) -> dict[str, float]:
        truth = super().linear_truth()
        for e, scale in self.hidden:
            truth[e.coefficient] = e.truth(self, scale)["coefficient_value"]
        return truth

    def lag_s(self) -> float:
        return sum(scale * e.value for e, scale in self.hidden if e.kind == "lag")


def with_hidden(model: AeroModel, hidden) -> AeroModel:
    """The model with uncatalogued effects (the model itself when there are none)."""
    hidden = tuple(hidden)
    if not hidden:
        return model
    base = {f: getattr(model, f) for f in ("aero", "xcg_over_d", "d_m", "effects")}
    return HiddenAeroModel(**base, hidden=hidden)


def lagged_controller(control, lag_s: float, sample_rate_hz: float):
    """Wrap a controller so that it also returns (t, delta_p(t - lag)): the plant passes
    them to :class:`HiddenAeroModel`.  Controls are held over a sample, so the lagged
    value is the one commanded ``lag`` earlier, linearly interpolated between samples."""
    history: list[float] = []

    def run(t: float, x: np.ndarray):
        dp, dy, dr = control(t, x)
        history.append(float(dp))
        k = len(history) - 1
        back = lag_s * sample_rate_hz
        pos = k - back
        if lag_s <= 0 or pos >= k:
            lagged = float(dp)
        elif pos <= 0:
            lagged = history[0]
        else:
            i = int(math.floor(pos))
            w = pos - i
            lagged = (1 - w) * history[i] + w * history[min(i + 1, k)]
        return dp, dy, dr, float(t), lagged

    return run


def describe(hidden) -> str:
    return ", ".join(f"{e.name}x{s:g}" for e, s in hidden)


__all__ = ["HIDDEN", "HiddenEffect", "HiddenAeroModel", "parse_hidden_spec", "hidden_table", "with_hidden",
           "lagged_controller", "DRIFT_REFERENCE_S"]
