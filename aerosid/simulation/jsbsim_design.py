"""What aerosid needs to know about a JSBSim aircraft before flying it, read from the
aircraft itself: which properties its aerodynamics use as the elevator, aileron and
rudder deflections, how the pilot commands reach them (static gains and travel,
probed through JSBSim's FCS), its propulsion class, a trim point that suits it, the
linear aerodynamic derivatives there (central differences of its own tables, moved to
the CG), and a manoeuvre sized to its surfaces and its short-period and Dutch-roll
frequencies.  ``flight_design(jsbsim, aircraft)`` returns all of it; docs/jsbsim.md
describes the rules.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from aerosid.simulation.jsbsim_fcs import CLOSED_LOOP, closed_loop_derivatives, fcs_statics, state_feedback
from aerosid.simulation.jsbsim_linear import Controls, linear_truth, snapshot
from aerosid.simulation.jsbsim_modes import doublet_sideslip_peak, flown_doublet_sideslip_peak, mode_frequencies
from aerosid.simulation.jsbsim_tables import DEG, AeroTables
from aerosid.simulation.jsbsim_trim import TrimError, TrimPoint, open_fdm, start_engines, trim
from aerosid.vehicles.vehicle import INERTIA_TRIANGLE_TOLERANCE, inertia_triangle_excess

FT = 0.3048
INCH = 0.0254
LBF = 4.4482216152605
SLUG = LBF / FT
SLUG_FT2 = SLUG * FT * FT
PSF = LBF / (FT * FT)
SLUG_FT3 = SLUG / FT**3

DT_S = 0.01  # JSBSim step = telemetry sample interval (100 Hz)

# The trim condition by propulsion class: height, the lift coefficient the trim speed is
# chosen for (V = sqrt(2 W / (rho S CL)), the upper part of a cruise/test envelope), the
# Mach cap, and the kind of flight: propeller aircraft glide with the throttles at idle
# (the propeller's moment, which the gyros feel and the aerodynamic truth leaves out,
# varies with speed along the phugoid; c172x: ~ -10 % on C_m_alpha in powered level
# flight, docs/jsbsim.md), jets fly level at the thrust that trims, an aircraft without
# usable thrust (rocket burnt out, glider) glides.
CLASS_CONDITION = {
    "propeller": {"h_m": 1500.0, "CL": 0.45, "mach_max": 0.5, "mode": "glide"},
    "jet": {"h_m": 6000.0, "CL": 0.30, "mach_max": 0.8, "mode": "level"},
    "unpowered": {"h_m": 6000.0, "CL": 0.30, "mach_max": 0.8, "mode": "glide"},
}
# Aircraft whose envelope is not the class's (public data of the type).
ENVELOPE = {
    "Concorde": {"h_m": 16000.0, "mach": 2.0, "mode": "level",
                 "why": "supersonic cruise: Mach 2.02 at 15-18 km"},
    "F4N": {"h_m": 12000.0, "mach": 1.6, "mode": "level",
            "why": "supersonic: Mach 1.6 at 12 km (F-4: Mach 2.2 class)"},
    "OV10": {"h_m": 1500.0, "mach": 0.206, "mode": "glide",
             "why": "idle glide at 70 m/s, 1500 m (OV-10: turboprops modelled as turbines; in level flight "
                    "their thrust moment moved the C_m_alpha of a fit of the noise-free truth by +18 %)"},
}
ASYMMETRY_MAX = 0.002  # |CG y| / span; (Ixy, Iyz) / Ixx up to 5x this: the loading counts as symmetric
MAX_DURATION_S = 180.0
MAX_PITCH_FEEDBACK_S = 0.05  # elevator per pitch rate [rad per rad/s] beyond which pitch is closed-loop
MAX_GLIDE_DEG = 10.0   # a steeper glide changes q-bar too much over a manoeuvre

# Manoeuvre sizing (docs/jsbsim.md "Generated flight design")
ALPHA_STEP_DEG = 1.5     # steady alpha change the 3-2-1-1's surface step would give
BANK_STEP_DEG = 10.0     # bank change over the first half of the aileron doublet
BETA_STEP_DEG = 1.5      # steady sideslip of the rudder step
TRAVEL_FRACTION = 0.4    # no step beyond this fraction of the surface's travel
UNIT_OMEGA = 2.0         # 3-2-1-1 time unit = UNIT_OMEGA / omega_sp (c172x: 0.4 s at omega_sp ~ 5 rad/s);
                         # an overdamped short period: the slower real root instead of omega_sp
DAMPER_ITERATIONS = 8      # flown rudder doublets to size the step of a yaw-damped aircraft
DAMPER_TOLERANCE = 0.05    # ... until its peak sideslip is within this of the undamped doublet's
DOUBLET_OMEGA = 2.3      # doublet half-width = DOUBLET_OMEGA / omega_dr (Koehler's optimum)


class UnsupportedAircraft(ValueError):
    """A JSBSim aircraft aerosid cannot fly or take the truth from."""


@dataclass(frozen=True)
class FlightDesign:
    aircraft: str
    xml_path: Path
    propulsion: str
    engines: tuple[str, ...]
    controls: Controls
    trim: TrimPoint
    condition_note: str
    gains: dict            # d(surface)/d(command) at trim [rad per unit command]
    limits_rad: dict       # surface -> (min, max) [rad] over the full command range
    state: dict            # trim snapshot of the aero model's leaf properties and more
    derivatives: dict      # linear truth at trim about the CG (jsbsim_flight names)
    derivatives_rp: dict   # the same about the AERORP
    modes: dict            # omega_sp, omega_dr [rad/s], tau_roll [s]
    manoeuvre: dict        # jsbsim_flight._schedule keys
    duration_s: float
    notes: list = field(default_factory=list)
    feedback: dict = field(default_factory=dict)  # state_feedback: surface per body rate / angle at trim


# --------------------------------------------------------------------------------------
# the aircraft
# --------------------------------------------------------------------------------------

def aircraft_xml(jsbsim, aircraft: str) -> Path:
    path = Path(jsbsim.get_default_root_dir()) / "aircraft" / aircraft / f"{aircraft}.xml"
    if not path.is_file():
        names = sorted(p.name for p in (Path(jsbsim.get_default_root_dir()) / "aircraft").iterdir() if p.is_dir())
        raise UnsupportedAircraft(f"no JSBSim aircraft {aircraft!r}; the jsbsim package ships {', '.join(names)}")
    return path


def propulsion_class(jsbsim, xml_root: ET.Element, aircraft_dir: Path) -> tuple[str, tuple[str, ...]]:
    """("propeller" | "jet" | "unpowered", engine kinds) from the engine and thruster files."""
    root = Path(jsbsim.get_default_root_dir())

    def kind(name: str) -> str:
        for folder in (aircraft_dir / "Engines", aircraft_dir / "engine", root / "engine"):
            f = folder / f"{name}.xml"
            if f.is_file():
                return ET.parse(f).getroot().tag
        return "unknown"

    prop = xml_root.find("propulsion")
    engines, thrusters = [], []
    for eng in (prop.findall("engine") if prop is not None else []):
        engines.append(kind(eng.get("file")))
        th = eng.find("thruster")
        thrusters.append(kind(th.get("file")) if th is not None else "none")
    if any(t == "propeller" for t in thrusters):
        return "propeller", tuple(engines)
    if any(e == "turbine_engine" for e in engines):
        return "jet", tuple(engines)
    return "unpowered", tuple(engines)  # rocket (tanks empty as shipped) or no engine


def symmetric_loading(fdm, xml_root: ET.Element) -> list[float]:
    """A symmetric loading (aerosid's rigid-body model has Ixy = Iyz = 0): point masses
    that mirror each other across the symmetry plane both carry the larger of their two
    weights (pilot and flight-test engineer of equal weight), a point mass off the plane
    without a mirror image is left out; the rest as the XML has them.  Returns the
    weights [lbf] set, in the XML's order."""
    masses = []
    for pm in xml_root.iter("pointmass"):
        loc = pm.find("location")
        scale = 12.0 if (loc.get("unit", "IN").upper() in ("FT",)) else (39.37007874 if loc.get("unit", "IN").upper() == "M" else 1.0)
        w = pm.find("weight")
        wscale = 2.20462262 if (w.get("unit", "LBS").upper() == "KG") else 1.0
        masses.append((float(loc.findtext("x")) * scale, float(loc.findtext("y")) * scale,
                       float(loc.findtext("z")) * scale, float(w.text) * wscale))
    weights = [m[3] for m in masses]
    for i, (x, y, z, w) in enumerate(masses):
        if abs(y) < 0.5:
            continue
        mirror = [j for j, (x2, y2, z2, _) in enumerate(masses)
                  if j != i and abs(x2 - x) < 1.0 and abs(z2 - z) < 1.0 and abs(y2 + y) < 1.0]
        weights[i] = max(w, *(masses[j][3] for j in mirror)) if mirror else 0.0
    for i, w in enumerate(weights):
        fdm[f"inertia/pointmass-weight-lbs[{i}]"] = w
    return weights


def loaded_fdm(jsbsim, aircraft: str, xml_root: ET.Element, point: TrimPoint):
    """A fresh FDM of `aircraft` (JSBSim step DT_S) with the symmetric loading and its engines
    started at the trim point's height and speed (`initialise` then puts it at `point`)."""
    fdm = open_fdm(jsbsim, aircraft, DT_S)
    symmetric_loading(fdm, xml_root)
    start_engines(fdm, point.h_m, point.V_m_s)
    return fdm


def find_controls(tables: AeroTables, catalogue: set[str]) -> Controls:
    """The elevator, aileron and rudder variables of the aerodynamic model."""
    leaves = [p for p in tables.leaf_properties() if p.startswith("fcs/") and "mag-" not in p]

    siblings = []

    def pick(word: str, extra: tuple[str, ...] = ()) -> str:
        found = [p for p in leaves if word in p and (p.endswith("-pos-rad") or p in extra)]
        other = [p for p in leaves if word in p and p not in found]
        same = [p for p in other if len(found) == 1 and p.endswith(("-pos-norm", "-pos-deg"))
                and p.rsplit("-pos-", 1)[0] == found[0].rsplit("-pos-", 1)[0]]
        if len(found) != 1 or len(same) != len(other):
            raise UnsupportedAircraft(
                f"{tables.path}: its aerodynamics read the {word} as {found + other or 'nothing'}; aerosid needs "
                f"exactly one deflection in radians (fcs/...{word}...-pos-rad) and at most the same surface's "
                "-pos-norm or -pos-deg")
        siblings.extend((p, found[0]) for p in same)
        return found[0]

    roll = pick("aileron", ("fcs/effective-aileron-pos",))
    pitch, yaw = pick("elevator"), pick("rudder")
    left = "fcs/left-aileron-pos-rad" if "fcs/left-aileron-pos-rad" in catalogue else None
    right = "fcs/right-aileron-pos-rad" if "fcs/right-aileron-pos-rad" in catalogue else None
    return Controls(pitch=pitch, roll=roll, yaw=yaw, left_aileron=left, right_aileron=right,
                    siblings=tuple(siblings))


# --------------------------------------------------------------------------------------
# the trim condition
# --------------------------------------------------------------------------------------

def _air(fdm, h_m: float) -> tuple[float, float]:
    """(density [kg/m^3], speed of sound [m/s]) of JSBSim's atmosphere at h_m."""
    fdm["ic/h-sl-ft"] = h_m / FT
    fdm["ic/vt-fps"] = 300.0
    fdm.run_ic()
    return fdm["atmosphere/rho-slugs_ft3"] * SLUG_FT3, fdm["atmosphere/a-fps"] * FT


def trim_condition(fdm, aircraft: str, propulsion: str) -> tuple[float, float, str, str]:
    """(h_m, V_m_s, mode, why) of the trim from the envelope table or the class rule."""
    if aircraft in ENVELOPE:
        env = ENVELOPE[aircraft]
        _, a = _air(fdm, env["h_m"])
        return env["h_m"], env["mach"] * a, env["mode"], env["why"]
    rule = CLASS_CONDITION[propulsion]
    rho, a = _air(fdm, rule["h_m"])
    weight_n = fdm["inertia/weight-lbs"] * LBF
    area = fdm["metrics/Sw-sqft"] * FT**2
    V = math.sqrt(2.0 * weight_n / (rho * area * rule["CL"]))
    why = f"{propulsion} class: CL {rule['CL']} at {rule['h_m']:g} m"
    if V > rule["mach_max"] * a:
        V, why = rule["mach_max"] * a, why + f", capped at Mach {rule['mach_max']}"
    return rule["h_m"], round(V, 1), rule["mode"], why


def find_trim(fdm, aircraft: str, propulsion: str) -> tuple[TrimPoint, str]:
    h, V, mode, why = trim_condition(fdm, aircraft, propulsion)
    start_engines(fdm, h, V)
    point = trim(fdm, h, V, mode)
    if mode == "glide" and abs(point.gamma_deg) > MAX_GLIDE_DEG:
        raise TrimError(f"{aircraft} glides at {point.gamma_deg:.1f} deg at h {h:g} m, V {V:g} m/s: steeper than "
                        f"{MAX_GLIDE_DEG:g} deg, q-bar would change by "
                        f"{100 * (math.exp(-point.V_m_s * math.sin(math.radians(point.gamma_deg)) * 30 / 7000) - 1):.0f} "
                        "% over a 30 s manoeuvre (no steady test condition)")
    return point, why


# --------------------------------------------------------------------------------------
# the manoeuvre
# --------------------------------------------------------------------------------------

def _r(x: float) -> float:
    return round(float(x), 2)


def _travel(limits: dict, prop: str, value: float) -> float:
    lo, hi = limits[prop]
    return max(0.0, min(value - lo, hi - value))


def manoeuvre_design(d: dict, modes: dict, gains: dict, limits: dict, controls: Controls,
                     base: dict, closed: dict | None = None, feedback: dict | None = None,
                     rudder_peak: Callable[[float, float, float], float] | None = None) -> tuple[dict, float, list[str]]:
    """Input timing and amplitudes (the keys of jsbsim_flight._schedule), the flight's
    duration and notes on what limited them.  closed: :func:`closed_loop_derivatives`
    (default: the open loop's); the amplitudes are sized on the closed loop's steady
    response (a sideslip feedback that holds beta to a sixth of its open-loop value asks
    six times the rudder); feedback: :func:`state_feedback` and rudder_peak(step [rad], half [s],
    rise [s]) -> the peak |beta| [rad] of the rudder doublet flown with that surface step: with both, a yaw
    damper scales the rudder step (below); the timing comes from `modes` as given."""
    notes = []
    V = base["velocities/vt-fps"] * FT
    b = base["metrics/bw-ft"] * FT
    closed = {**{k: d[k] for k in CLOSED_LOOP}, **(closed or {})}
    for name in CLOSED_LOOP:
        if abs(closed[name] / d[name] - 1.0) > 0.05:
            notes.append(f"FCS feedback: the manoeuvre is sized on the closed loop's {name} "
                         f"{closed[name]:.4g} (open loop {d[name]:.4g})")
    w_sp, w_dr = modes["omega_pitch_design_rad_s"], modes["omega_dr_rad_s"]
    unit = _r(np.clip(UNIT_OMEGA / w_sp, 0.1, 1.0))
    half = _r(np.clip(DOUBLET_OMEGA / w_dr, 0.3, 2.0))

    def room_of(prop: str) -> float:
        """The largest step [rad] of surface `prop`: TRAVEL_FRACTION of the travel left at trim."""
        return TRAVEL_FRACTION * _travel(limits, prop, base[prop])

    def command(axis: str, prop: str, surface_rad: float, sign: float) -> tuple[float, float]:
        """The normalised command and the surface step [rad] it flies (capped by the travel)."""
        room = room_of(prop)
        if surface_rad > room:
            notes.append(f"{axis}: step {surface_rad / DEG:.2f} deg limited to {room / DEG:.2f} deg "
                         f"({TRAVEL_FRACTION:.0%} of the travel left at trim)")
            surface_rad = room
        gain = gains[axis]
        if abs(gain) < 1e-6:
            raise UnsupportedAircraft(f"the {axis} command does not move {prop} (static gain {gain:g})")
        return _r(sign * math.copysign(1.0, gain) * surface_rad / abs(gain) * 100.0) / 100.0 or 0.01, surface_rad

    # elevator: a step that would change alpha by ALPHA_STEP_DEG in steady state; the first
    # 3-2-1-1 starts nose-up (the surface moves the way that raises C_m).  The steady short
    # period turns at q = -Z_alpha alpha - Z_delta delta (alpha' = 0), so the pitch damping holds
    # alpha back too: 0 = C_m,alpha alpha + C_m,q c/(2V) q + C_m,delta delta.  With C_m,alpha alone
    # a heavily damped aircraft got 42 % of the step (c310: C_m,q c/(2V) Z_alpha 1.4 x C_m,alpha;
    # pa28 0.14 x); the elevator's own lift (Z_delta) moves the step by -6 % (pa28) to +11 % (c310)
    c = base["metrics/cbarw-ft"] * FT
    k_q = d["Cm_q"] * c / (2.0 * V)
    z_delta = modes["Z_alpha_s"] * d["CN_delta_p"] / d["CN_alpha"]
    stiffness = closed["Cm_alpha"] - k_q * modes["Z_alpha_s"]
    de = ALPHA_STEP_DEG * DEG * abs(stiffness / (d["Cm_delta_p"] - k_q * z_delta))
    a_e, de = command("pitch", controls.pitch, de, math.copysign(1.0, d["Cm_delta_p"]))
    # aileron: a bank change of BANK_STEP_DEG over the first half at the steady roll rate
    p_per_rad = abs(d["Cl_delta_r"] / closed["Cl_p"]) * 2.0 * V / b
    da = BANK_STEP_DEG * DEG / (half * p_per_rad)
    a_a, da = command("roll", controls.roll, da, math.copysign(1.0, d["Cl_delta_r"]))
    # rudder: a steady sideslip of BETA_STEP_DEG, nose left first
    rise_lat = _r(min(0.2, half / 4))
    dr = BETA_STEP_DEG * DEG * abs(closed["Cn_beta"] / d["Cn_delta_y"])
    # a yaw damper (r on the rudder) leaves the steady sideslip as it is but takes most of the
    # doublet's (A4, F4N, global5000, A320: 56-73 %): the rudder then follows r, and C_n,r is seen
    # only through the input's share.  The step is scaled until the doublet flown in JSBSim
    # reaches the peak sideslip the Dutch-roll approximation gives it without the damper (what
    # an undamped aircraft's doublet flies); flown, because a damper's authority limit (F4N:
    # 0.1 of the rudder) makes the response of a larger step more than proportional
    k_r = (feedback or {}).get("r", {}).get("yaw", 0.0)
    if abs(k_r) > 1e-3 and rudder_peak is not None:
        k_beta = feedback.get("beta", {}).get("yaw", 0.0)
        target = dr * doublet_sideslip_peak(d, base, half, rise_lat, 0.0, k_beta)
        room = room_of(controls.yaw)
        # the peak grows with the step, faster than in proportion once the damper saturates:
        # proportional steps kept inside a bracket, bisection when they leave it
        lo, hi = 0.0, room
        step = min(target / doublet_sideslip_peak(d, base, half, rise_lat, k_r, k_beta), room)
        flown = []
        for _ in range(DAMPER_ITERATIONS):
            peak = rudder_peak(step, half, rise_lat)
            flown.append((abs(peak / target - 1.0), step, peak))
            if flown[-1][0] < DAMPER_TOLERANCE or (step >= room and peak < target):
                break
            lo, hi = (step, hi) if peak < target else (lo, step)
            step = step * target / peak if lo < step * target / peak < hi else 0.5 * (lo + hi)
        _, step, peak = min(flown)
        cap = f", {TRAVEL_FRACTION:.0%} of the travel left at trim" if step >= room else ""
        notes.append(f"yaw damper ({k_r:.3g} rad per rad/s): rudder step {dr / DEG:.2f} -> {step / DEG:.2f} deg{cap}, "
                     f"so the doublet's peak sideslip is {peak / DEG:.2f} deg in JSBSim (undamped: {target / DEG:.2f})")
        dr = step
    a_r, dr = command("yaw", controls.yaw, dr, math.copysign(1.0, -d["Cn_delta_y"]) * -1.0)
    rise_e = _r(unit / 2)
    takeup = 0.2
    gap_lon = _r(max(3.0, 3 * 2 * math.pi / w_sp))
    gap_lat = _r(max(6.0, 3 * 2 * math.pi / w_dr))
    e_len = 7 * unit + rise_e + 2 * takeup
    t_e1 = 3.0
    t_e2 = _r(t_e1 + e_len + gap_lon)
    t_a = _r(t_e2 + e_len + gap_lon)
    t_r = _r(t_a + 2 * half + rise_lat + 2 * takeup + gap_lat)
    end = _r(t_r + 2 * half + rise_lat + 2 * takeup + max(8.0, 3 * 2 * math.pi / w_dr))
    m = {
        "elevator_starts_s": [t_e1, t_e2], "elevator_signs": [1, -1], "elevator_unit_s": unit,
        "elevator_units": [3, 2, 1, 1], "elevator_amplitudes_norm": [a_e, -a_e, a_e, -a_e], "elevator_rise_s": rise_e,
        "aileron_start_s": t_a, "aileron_half_s": half, "aileron_amplitude_norm": a_a, "aileron_rise_s": rise_lat,
        "rudder_start_s": t_r, "rudder_half_s": half, "rudder_amplitude_norm": a_r, "rudder_rise_s": rise_lat,
        "hysteresis_takeup_s": takeup,
        # the steps flown (after the travel caps): the generated model's 1 % rules compare to these
        "surface_steps_rad": {"elevator": de, "aileron": da, "rudder": dr},
    }
    return m, end, notes


# --------------------------------------------------------------------------------------

_DESIGNS: dict[str, FlightDesign] = {}


def flight_design(jsbsim, aircraft: str) -> FlightDesign:
    """The design of `aircraft`'s flight (cached per process: it is deterministic)."""
    if aircraft in _DESIGNS:
        return _DESIGNS[aircraft]
    try:
        design = _design(jsbsim, aircraft)
    except jsbsim.BaseError as exc:  # the model does not run on its own (a missing FlightGear property, ...)
        raise UnsupportedAircraft(f"JSBSim cannot run {aircraft} on its own: {str(exc).strip()}") from exc
    _DESIGNS[aircraft] = design
    return design


def in_catalogue(prop: str, catalogue: set[str]) -> bool:
    """Whether JSBSim defines prop.  Its catalogue lists the first of indexed properties without the
    index ('propulsion/engine/thrust-coefficient' for engine[0]); an aircraft may spell it either way
    (pc7 and J3Cub read 'propulsion/engine[0]/thrust-coefficient'), and JSBSim reads both."""
    return prop in catalogue or prop.replace("[0]", "") in catalogue


def _design(jsbsim, aircraft: str) -> FlightDesign:
    xml_path = aircraft_xml(jsbsim, aircraft)
    xml_root = ET.parse(xml_path).getroot()
    try:
        tables = AeroTables(xml_path)
    except (ValueError, NotImplementedError) as exc:
        raise UnsupportedAircraft(str(exc)) from exc
    propulsion, engines = propulsion_class(jsbsim, xml_root, xml_path.parent)
    fdm = open_fdm(jsbsim, aircraft, DT_S)
    loading = symmetric_loading(fdm, xml_root)
    catalogue = {p.split(" ")[0] for p in fdm.get_property_catalog()}
    controls = find_controls(tables, catalogue)
    missing = [p for p in tables.leaf_properties() if not in_catalogue(p, catalogue)]
    if missing:
        raise UnsupportedAircraft(f"{xml_path}: its aerodynamics read properties JSBSim does not define: {missing}")
    try:
        point, why = find_trim(fdm, aircraft, propulsion)
    except TrimError as exc:
        raise UnsupportedAircraft(str(exc)) from exc
    gains, limits = fcs_statics(fdm, point, controls)
    feedback = state_feedback(fdm, point, controls)
    base = snapshot(fdm, tables, controls)
    notes = []
    if abs(feedback["q"]["pitch"]) > MAX_PITCH_FEEDBACK_S:
        raise UnsupportedAircraft(f"{aircraft}: its FCS moves the elevator with pitch rate "
                                  f"({feedback['q']['pitch']:.3g} rad per rad/s: fly-by-wire or pitch augmentation); "
                                  "the open-loop manoeuvre design does not apply to closed-loop pitch control")
    for state, row in feedback.items():
        unit = "rad per rad" if state in ("alpha", "beta") else "rad per rad/s"
        for surface, k in row.items():
            if abs(k) > 1e-3:
                kind = "a yaw damper" if (state, surface) == ("r", "yaw") else "a stability augmentation"
                notes.append(f"FCS feedback: the {surface} surface moves with {state} ({k:.3g} {unit}; "
                             f"e.g. {kind}): its deflection is partly collinear with {state}")
    Ixx, Iyy, Izz = (base[f"inertia/i{k}-slugs_ft2"] for k in ("xx", "yy", "zz"))
    axis, excess = inertia_triangle_excess(Ixx, Iyy, Izz)
    inertias = (f"JSBSim's inertias Ixx {Ixx * SLUG_FT2:.6g}, Iyy {Iyy * SLUG_FT2:.6g}, Izz {Izz * SLUG_FT2:.6g} kg m^2 "
                f"violate the triangle inequality ({axis} exceeds the sum of the other two by {100 * excess:.2g} %")
    if excess > INERTIA_TRIANGLE_TOLERANCE:
        raise UnsupportedAircraft(f"{aircraft}: {inertias}; no rigid body has them, and aerosid's vehicle file "
                                  f"refuses more than {100 * INERTIA_TRIANGLE_TOLERANCE:g} %)")
    if excess > 0:
        notes.append(f"mass: {inertias}, within the {100 * INERTIA_TRIANGLE_TOLERANCE:g} % an estimate's error may "
                     "cross it by; JSBSim flies them as they are, and so does the vehicle file)")
    cg_y = base["inertia/cg-y-in"] / (base["metrics/bw-ft"] * 12.0)
    cross = max(abs(base["inertia/ixy-slugs_ft2"]), abs(base["inertia/iyz-slugs_ft2"])) / base["inertia/ixx-slugs_ft2"]
    text = (f"CG {base['inertia/cg-y-in']:.2f} in off the symmetry plane ({100 * cg_y:.2f} % of the span), "
            f"Ixy {base['inertia/ixy-slugs_ft2']:.4g}, Iyz {base['inertia/iyz-slugs_ft2']:.4g} slug ft^2 "
            f"({100 * cross:.2f} % of Ixx)")
    if abs(cg_y) > ASYMMETRY_MAX or cross > 5 * ASYMMETRY_MAX:
        raise UnsupportedAircraft(f"{aircraft}: its loading is asymmetric even with the symmetric point masses: "
                                  f"{text}; aerosid's rigid-body model has Ixy = Iyz = 0")
    if abs(cg_y) > 1e-6 or cross > 1e-6:
        notes.append(f"loading: {text}; the vehicle file leaves them out (aerosid's rigid body has Ixy = Iyz = 0)")
    d_cg, d_rp, lin = linear_truth(tables, base, controls, gains)
    # what the manoeuvre meets: the aircraft's derivatives with its FCS's static feedback
    closed = closed_loop_derivatives(d_cg, feedback, base["velocities/vt-fps"] * FT, base["metrics/bw-ft"] * FT)
    flown = {**d_cg, **closed}
    held = mode_frequencies(flown, base)
    unstable = [f"{k} = {flown[k]:+.4g}" for k, bad in (("Cm_alpha", flown["Cm_alpha"] >= 0 or held["M_alpha_s2"]
                                                          - held["Z_alpha_s"] * held["M_q_s"] >= 0),
                                                         ("Cn_beta", flown["Cn_beta"] <= 0),
                                                         ("Cl_p", flown["Cl_p"] >= 0)) if bad]
    if unstable:
        fcs = " with its FCS's static feedback" if any(closed[k] != d_cg[k] for k in CLOSED_LOOP) else ""
        raise UnsupportedAircraft(f"{aircraft} is statically unstable at its trim point (h {point.h_m:g} m, "
                                  f"V {point.V_m_s:g} m/s; {', '.join(unstable)} about the CG{fcs}): an open-loop "
                                  "manoeuvre would diverge")
    # the inputs' timing stays the open loop's: on A320 (seeds 0-4) timing the doublets on its
    # closed-loop Dutch roll (2.5 x faster) shortened them and cost C_n,beta's sigma 1.7 -> 4.6 %
    modes = mode_frequencies(d_cg, base)
    fresh = []  # a fresh FDM, opened on the first call: the probes above left the FCS in trim mode

    def rudder_peak(step_rad: float, half_s: float, rise_s: float) -> float:
        if not fresh:
            fresh.append(loaded_fdm(jsbsim, aircraft, xml_root, point))
        return flown_doublet_sideslip_peak(fresh[0], point, step_rad / abs(gains["yaw"]), half_s, rise_s, DT_S)

    m, duration, more = manoeuvre_design(d_cg, modes, gains, limits, controls, base, closed, feedback, rudder_peak)
    if duration > MAX_DURATION_S:
        raise UnsupportedAircraft(f"{aircraft}: the manoeuvre would last {duration:.0f} s (> {MAX_DURATION_S:g} s; "
                                  f"short period {modes['omega_sp_rad_s']:.3g} rad/s, Dutch roll "
                                  f"{modes['omega_dr_rad_s']:.3g} rad/s)")
    return FlightDesign(aircraft=aircraft, xml_path=xml_path, propulsion=propulsion, engines=engines,
                          controls=controls, trim=point, condition_note=why, gains=gains, limits_rad=limits,
                          state=base, derivatives=d_cg, derivatives_rp=d_rp, modes=modes, manoeuvre=m,
                          duration_s=duration, notes=notes + more, feedback=feedback)
