"""Atmospheric turbulence for a JSBSim flight: JSBSim's MIL-F-8785C model switched on after the
trim (aerosid.simulation.jsbsim_flight.simulate_jsbsim, jsbsim_aircraft)."""
from __future__ import annotations


#: Atmospheric turbulence a JSBSim flight can be flown in (``simulate_jsbsim(turbulence=...)``,
#: ``aerosid simulate --jsbsim AIRCRAFT --turbulence LEVEL``): JSBSim's MIL-F-8785C model in its
#: Tustin form (atmosphere/turb-type 4) at this probability-of-exceedance severity index, with its
#: rotational gusts (the aerodynamics answer to the rates relative to the air; the gyros measure
#: the rates relative to the ground).  Measured on c172x at 1360 m and 47 m/s over 30 s of level
#: flight: vertical gust 0.21 / 0.55 / 1.4 m/s rms and p - p_air 0.008 / 0.021 / 0.051 rad/s rms at
#: severity 1 / 2 / 3.  "light" is 2, "moderate" 3.  The realisation follows the flight's seed.
TURBULENCE_SEVERITY = {"none": 0, "light": 2, "moderate": 3}
#: The wind at 20 ft the low-altitude part of the model scales with [ft/s] (15 kt, the model's
#: light-turbulence value; above 2000 ft the severity alone sets the intensity).
TURBULENCE_WIND_20FT_FPS = 25.3


def checked_turbulence(level: str) -> str:
    """``level`` if it is a TURBULENCE_SEVERITY key, else a ValueError naming the choices."""
    if level not in TURBULENCE_SEVERITY:
        raise ValueError(f"unknown turbulence level {level!r}; choices: {', '.join(TURBULENCE_SEVERITY)}")
    return level


def start_turbulence(fdm, level: str, seed: int) -> dict:
    """Turn JSBSim's turbulence on at ``level`` (a TURBULENCE_SEVERITY key; "none": nothing is set),
    its random sequence from ``seed``; after the trim, before the flight.  Returns what was set
    (the flight's ``info["turbulence"]``)."""
    if TURBULENCE_SEVERITY[checked_turbulence(level)] == 0:
        return {"level": level}
    fdm["atmosphere/randomseed"] = int(seed) + 1  # JSBSim treats 0 as its default sequence
    fdm["atmosphere/turb-type"] = 4
    fdm["atmosphere/turbulence/milspec/windspeed_at_20ft_fps"] = TURBULENCE_WIND_20FT_FPS
    fdm["atmosphere/turbulence/milspec/severity"] = TURBULENCE_SEVERITY[level]
    return {"level": level, "model": "JSBSim MIL-F-8785C, Tustin form (atmosphere/turb-type 4)",
            "severity_index": TURBULENCE_SEVERITY[level], "wind_20ft_fps": TURBULENCE_WIND_20FT_FPS,
            "randomseed": int(seed) + 1}
