"""The flight envelope a vehicle file states (``[plausibility]``), with class defaults.

Every range is a plausibility bound for the *telemetry's summary statistics*, not a
design limit: the unit check (aerosid.plausibility.units) compares the 99th percentile
of |p|, |q|, |r| with ``rate_rad_s`` and the medians of the specific force, airspeed,
altitude and dynamic pressure with their ranges.  A vehicle that flies outside its
class's defaults states its own ranges in its file.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace


@dataclass(frozen=True)
class Plausibility:
    """Ranges are (low, high) closed intervals; SI units, radians."""

    rate_rad_s: float  # largest plausible 99th percentile of |p|, |q|, |r| [rad/s]
    specific_force_m_s2: tuple[float, float]  # median |(ax, ay, az)| [m/s^2]
    V_m_s: tuple[float, float]  # median airspeed [m/s]
    h_m: tuple[float, float]  # median altitude [m]
    qbar_pa: tuple[float, float]  # median dynamic pressure (US-1976 density) [Pa]
    alpha_rad: tuple[float, float]  # the angle of attack the flight stays within [rad]
    az_m_s2: tuple[float, float] = (-1000.0, 1000.0)  # median az [m/s^2], body z down (lift reads negative)
    cn_alpha_per_rad: tuple[float, float] = (-1e9, 1e9)  # the estimated normal-force slope C_N,alpha [1/rad]
    cl_p_per_rad: tuple[float, float] = (-1e9, 1e9)  # the estimated roll damping C_l,p [1/rad]
    vane_noise_factor: float = 3.0  # [air_data] noise_rad within this factor of the vanes' measured white noise
    preflight_factor: float = 3.0  # an estimate beyond preflight x/÷ this factor is reported
    airspeed_scale_min: float = 0.82  # V_m_s over the true airspeed the pitch kinematics imply (vanes)
    chord_ratio: tuple[float, float] = (0.0, 1e6)  # chord_m / (S_m2 / span_m) (aerosid.plausibility.geometry)

    def summary(self) -> str:
        return ", ".join(f"{f.name} {getattr(self, f.name)}" for f in fields(self))


#: Defaults per vehicle class.  Aircraft: 0.25-5 g median load, 10-1000 m/s (JSBSim's F4N
#: flies its identification manoeuvre at 470 m/s, M 1.6), below 25 km, up to 150 kPa, a negative
#: median az (z down: the lift holds it up; positive is a z-up accelerometer).  Finned (seed-rlv
#: class: missiles, re-entry and hypersonic vehicles): 2-1000 m/s^2 (a vehicle whose aerodynamic
#: forces are measurable), 30-8000 m/s, up to 100 km, 10 Pa - 500 kPa, az of either sign.
#: An aircraft's estimated lift slope C_N,alpha within 1-12 /rad (a wing gives at most about 2 pi;
#: fuselage, tail and slipstream add some: 25 JSBSim aircraft 2.9-6.1 and c172x 10.0, the Twin
#: Otter 6.6) and roll damping C_l,p within -1.5..-0.1 /rad (strip theory: -C_L,alpha/12 x
#: (1 + 3 taper)/(1 + taper); the same aircraft -0.75..-0.38): a wing area in ft^2, a span in ft,
#: a dynamic pressure in psf put them 10-50 x off (aerosid.plausibility.estimates).
#: airspeed_scale_min: the pitch kinematics' V_m_s / true airspeed (aerosid.plausibility.airspeed_scale)
#: on 130 calm JSBSim flights of 13 aircraft (seeds 0-9) with true airspeeds, 0.908-1.058 (2 without
#: a verdict; sigma 0.007-0.023); a calibrated airspeed at 6 km reads 0.55-0.76.
#: An aircraft's chord_m / (S_m2 / span_m) within 0.4-2.5: a mean aerodynamic chord is 1.0-1.33 x S/b,
#: JSBSim's aircraft 0.75-1.31, delta wings and lifting bodies up to 2.2; a chord or span in ft reads
#: x3.28, a wing area in ft^2 x0.093 (aerosid.plausibility.geometry).
CLASS_DEFAULTS: dict[str, Plausibility] = {
    "aircraft": Plausibility(rate_rad_s=2.0, specific_force_m_s2=(2.5, 50.0), V_m_s=(10.0, 1000.0),
                             h_m=(-500.0, 25000.0), qbar_pa=(20.0, 150000.0), alpha_rad=(-0.35, 0.7),
                             az_m_s2=(-50.0, 0.0), cn_alpha_per_rad=(1.0, 12.0), cl_p_per_rad=(-1.5, -0.1),
                             chord_ratio=(0.4, 2.5)),
    "finned": Plausibility(rate_rad_s=2.0, specific_force_m_s2=(2.0, 1000.0), V_m_s=(30.0, 8000.0),
                           h_m=(-500.0, 100000.0), qbar_pa=(10.0, 500000.0), alpha_rad=(-0.6, 0.6)),
}


def plausibility_for(vehicle_class: str, table: dict | None = None) -> Plausibility:
    """The class defaults with the vehicle file's [plausibility] values on top (already
    checked for kind and range by aerosid.vehicles.keys)."""
    base = CLASS_DEFAULTS[vehicle_class]
    if not table:
        return base
    return replace(base, **{k: (tuple(float(x) for x in v) if isinstance(v, list) else float(v))
                            for k, v in table.items()})
