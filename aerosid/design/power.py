"""Power setting of a designed JSBSim manoeuvre (``aerosid design --power trim|idle``).

c172x's gyros feel the propeller's pitching moment, which JSBSim's aerodynamic truth (and
aerosid's aerodynamic model) leaves out.  At the trimmed power of the validation flight it
varies with alpha and speed along the manoeuvre and projects onto q_hat and alpha_dot_hat:
the model error that kept Cm_q and Cm_alpha_dot apart by more than 10 %
(bench/results/design_c172x_oracle_scan.md).  Flight tests of damping derivatives are flown
power-off or at constant low power for this reason; ``--power idle`` flies the design in a
glide trimmed at idle throttle (the input file's ``throttle_cmd_norm`` = 0, aerosid.design.io),
and a design at the trim's power whose separation fails on the model error alone says so in
its verdict (:func:`power_hint`).
"""
from __future__ import annotations

#: --power: None = the simulator's own trim; a number = a glide trimmed at that fixed throttle
POWER_SETTINGS = {"trim": None, "idle": 0.0}


def power_hint(oracle: dict, rel_sigma_pct: dict, power: str, flyer) -> str:
    """The proposal to fly power-off when the model error (more than the noise, 2 sigma) is what
    stops the separation of a target on a JSBSim aircraft flown at the trim's power; '' otherwise.
    oracle: model error per target [%]; rel_sigma_pct: sigma per target [% of its size]."""
    if power != "trim" or not oracle or not hasattr(flyer, "throttle"):
        return ""
    # a target that misses the bar (|model error| + 2 sigma > 10 %) mostly through the model error
    bad = {t: v for t, v in oracle.items()
           if abs(v) + 2.0 * rel_sigma_pct.get(t, 0.0) > 10.0 and abs(v) >= 2.0 * rel_sigma_pct.get(t, 0.0)}
    if not bad:
        return ""
    return ("PROPOSAL: the model error (" + ", ".join(f"{t} {v:+.1f} %" for t, v in bad.items())
            + ") stops the separation more than the noise does; on c172x it is mostly the propeller's pitching moment, which "
              "the gyros feel and the aerodynamic model does not have (bench/results/design_c172x_poweroff.md): "
              "fly the manoeuvre power-off (a glide trimmed at idle throttle): "
              "aerosid design ... --power idle (docs/design.md).")
