"""A localisation finding (:mod:`aerosid.diagnosis.localise`) and its text for the diagnosis."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from aerosid.diagnosis.rule import _f  # JSON-safe float

__all__ = ["Finding", "localisation_text", "localisation_hint"]


@dataclass(frozen=True)
class Finding:
    """One localisation finding: ``channel += coefficient * suggested_expression``."""

    channel: str
    kind: str  # "shape", "trend" or "lag"
    variable: str  # the signal it is about (alpha, delta_p, t, mach, ...)
    significant: bool
    suggested_coefficient: str
    suggested_expression: str
    estimate: float
    std_error: float
    t_value: float
    p_value: float
    variance_share: float
    window_consistency: float
    n_eff: float
    message: str
    coefficient: str | None = None  # the model coefficient a trend or lag is about (Cm_alpha, Cm_delta_p)
    evidence: dict = field(default_factory=dict)
    confused_with: tuple[str, ...] = ()  # ids (kind:coefficient-or-channel:variable) it cannot be told from
    reasons: tuple[str, ...] = ()  # why not significant
    #: the added column minus what the model's terms explain of it (for the confusability check)
    perp: np.ndarray | None = field(default=None, repr=False, compare=False)
    #: the added column itself (for the shadow check)
    column: np.ndarray | None = field(default=None, repr=False, compare=False)
    #: columns tested beside it, ((name, column), ...): a schedule's main effect (for the shadow check)
    given: tuple = field(default=(), repr=False, compare=False)

    @property
    def id(self) -> str:
        return f"{self.kind}:{self.coefficient or self.channel}:{self.variable}"

    @property
    def spec_line(self) -> str:
        return f"{self.suggested_coefficient} = {self.suggested_expression}"

    @property
    def score(self) -> float:
        return float(self.t_value ** 2) if math.isfinite(self.t_value) else -1.0

    def to_dict(self) -> dict:
        ev = {k: (_f(v) if isinstance(v, (int, float, np.floating)) else v) for k, v in self.evidence.items()}
        return {"id": self.id, "channel": self.channel, "kind": self.kind, "variable": self.variable,
                "coefficient": self.coefficient, "significant": bool(self.significant),
                "suggested_coefficient": self.suggested_coefficient,
                "suggested_expression": self.suggested_expression, "spec_line": self.spec_line,
                "estimate": _f(self.estimate), "std_error": _f(self.std_error), "t_value": _f(self.t_value),
                "p_value": _f(self.p_value), "variance_share": _f(self.variance_share),
                "window_consistency": _f(self.window_consistency), "n_eff": _f(self.n_eff),
                "message": self.message, "evidence": ev, "confused_with": list(self.confused_with),
                "reasons": list(self.reasons)}


def localisation_hint(localisation: dict) -> str:
    """One sentence for the diagnosis message: the significant localisation findings."""
    sig = sorted((f for fs in localisation.values() for f in fs if f.significant), key=lambda f: -f.score)
    if not sig:
        return ""
    first = sig[0]
    more = f" ({len(sig) - 1} more in the localisation)" if len(sig) > 1 else ""
    return f" Outside the catalogue, the localisation finds: {first.message}{more}."


def localisation_text(localisation: dict) -> str:
    """The findings for Diagnosis.summary()."""
    if not localisation:
        return ""
    lines = ["Localisation (where each channel's model fails, as a term; * = passes the rule):"]
    for ch, fs in localisation.items():
        if not fs:
            continue
        for f in fs:
            tail = f"  [not told apart from {', '.join(f.confused_with)}]" if f.confused_with else ""
            why = "" if f.significant else f"  (not significant: {f.reasons[0]})" if f.reasons else ""
            lines.append(f"  {'*' if f.significant else ' '} {f.message}{tail}{why}")
    if len(lines) == 1:
        lines.append("  nothing to localise")
    return "\n".join(lines)
