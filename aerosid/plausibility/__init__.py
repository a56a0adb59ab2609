"""Plausibility of inputs and results against the vehicle's flight envelope.

``envelope``: the ``[plausibility]`` table of a vehicle file (ranges of rates, specific
force, airspeed, altitude, dynamic pressure, angle of attack; the preflight factor) with
defaults per vehicle class.  ``units``: a raw telemetry channel whose values fit another
unit far better than the declared one (deg/s for rad/s, g for m/s^2, km or ft for m, kt
for m/s) is refused naming the column and the likely unit.  ``estimates``: estimates far
from their preflight values are reported.
"""
from aerosid.plausibility.envelope import Plausibility, plausibility_for

__all__ = ["Plausibility", "plausibility_for"]
