"""Trimming any JSBSim aircraft in steady, straight, wings-level-ish flight.

JSBSim's own trim (``simulation/do_simple_trim``) balances u-dot with the throttle,
so it cannot trim a glide with the engines at idle or off (an X-15 after burn-out, a
glider) and it fails on some models whose control laws read their own outputs.
:func:`trim` solves the six steady-flight equations u̇ = v̇ = ẇ = ṗ = q̇ = ṙ = 0
itself, by Newton's method on JSBSim's own accelerations: at each trial point the
initial condition is set (speed, height, α, γ, φ, β = 0, zero rates), the pilot
commands and throttles are set, and JSBSim is initialised with its FCS in trim mode
(actuators pass their input straight through, as during JSBSim's trim) and the
engines run to their steady state; the accelerations JSBSim then computes are the
residuals.  Unknowns: α, the elevator, aileron and rudder commands, the bank angle φ
(β stays 0), and either the flight-path angle γ (``mode="glide"``: throttle fixed) or
the throttle (``mode="level"``: γ fixed).
"""
from __future__ import annotations

import atexit
import functools
import math
import multiprocessing.util
import os
import shutil
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

FT = 0.3048
RESIDUALS = ("accelerations/udot-ft_sec2", "accelerations/vdot-ft_sec2", "accelerations/wdot-ft_sec2",
             "accelerations/pdot-rad_sec2", "accelerations/qdot-rad_sec2", "accelerations/rdot-rad_sec2")
COMMANDS = ("fcs/elevator-cmd-norm", "fcs/aileron-cmd-norm", "fcs/rudder-cmd-norm")
# converged when |u,v,w-dot| < 1e-3 ft/s^2 and |p,q,r-dot| < 1e-5 rad/s^2
TOLERANCE = np.array([1e-3, 1e-3, 1e-3, 1e-5, 1e-5, 1e-5])
MODES = ("glide", "level")


class TrimError(RuntimeError):
    """The aircraft does not trim at the requested condition."""


@dataclass(frozen=True)
class TrimPoint:
    """A steady flight condition found by :func:`trim` (angles in degrees, commands
    normalised as JSBSim's pilot inputs)."""

    h_m: float
    V_m_s: float
    mode: str
    alpha_deg: float
    gamma_deg: float
    phi_deg: float
    elevator_cmd: float
    aileron_cmd: float
    rudder_cmd: float
    throttle: float
    max_residual: tuple[float, float]  # (max |u,v,w-dot| [ft/s^2], max |p,q,r-dot| [rad/s^2])
    iterations: int

    def as_dict(self) -> dict:
        return asdict(self)


@functools.cache
def _scratch_dir(pid: int) -> str:
    """A folder for process `pid`'s JSBSim output files, removed when it exits: at interpreter
    exit, or, for a forked pool worker (which ends with os._exit and skips atexit), by
    multiprocessing's finaliser; cached per pid so a forked child does not share its parent's."""
    folder = tempfile.mkdtemp(prefix="aerosid-jsbsim-")
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    multiprocessing.util.Finalize(None, shutil.rmtree, args=(folder,), kwargs={"ignore_errors": True},
                                  exitpriority=0)
    return folder


def new_fdm(jsbsim):
    """A quiet JSBSim executive whose output files go to a throwaway folder.  An aircraft's
    XML may ask for output files (c172x: 0.8 MB of CSV per flight; B17, global5000, pogo),
    which JSBSim opens even after disable_output(), in its own package folder by default:
    an installation folder (on a read-only one, an error line per initialisation)."""
    fdm = jsbsim.FGFDMExec(jsbsim.get_default_root_dir())
    fdm.set_debug_level(0)
    fdm.set_output_path(_scratch_dir(os.getpid()))
    return fdm


def open_fdm(jsbsim, model: str, dt: float):
    """A JSBSim instance of `model` in the clean configuration (a retractable gear, flaps
    and speed brakes retracted), no output files, fuel consumption frozen (the mass and
    CG stay those of the trim; some models' engines feed from small collector tanks
    that only FlightGear's transfer scripts refill: Concorde's flame out after ~10 s)."""
    fdm = new_fdm(jsbsim)
    if not fdm.load_model(model):
        raise TrimError(f"JSBSim could not load the aircraft {model!r}")
    fdm.disable_output()
    fdm.disable_input()  # 737.xml asks for TCP and UDP input ports: no socket is opened, at any initialisation
    fdm.set_dt(dt)
    catalogue = {p.split(" ")[0] for p in fdm.get_property_catalog()}
    if "propulsion/fuel_freeze" in catalogue:
        fdm["propulsion/fuel_freeze"] = 1
    xml = Path(jsbsim.get_default_root_dir()) / "aircraft" / model / f"{model}.xml"
    retractable = xml.is_file() and any((el.text or "").strip() == "1" for el in ET.parse(xml).getroot().iter("retractable"))
    # a fixed gear stays down: its drag is part of the aircraft (pa28's CDgear reads gear/gear-pos-norm)
    for prop in (("gear/gear-cmd-norm", "gear/gear-pos-norm") if retractable else ()) + (
            "fcs/flap-cmd-norm", "fcs/speedbrake-cmd-norm", "fcs/spoiler-cmd-norm"):
        if prop in catalogue:
            fdm[prop] = 0.0
    return fdm


def n_engines(fdm) -> int:
    return int(fdm.get_propulsion().get_num_engines())


def start_engines(fdm, h_m: float, V_m_s: float) -> None:
    """Initialise once at the condition, then set every engine running (a piston
    engine set running before the first initialisation stays off)."""
    fdm["ic/h-sl-ft"] = h_m / FT
    fdm["ic/vt-fps"] = V_m_s / FT
    fdm.run_ic()
    if n_engines(fdm):
        fdm["propulsion/set-running"] = -1


def apply(fdm, h_m: float, V_m_s: float, alpha_deg: float, gamma_deg: float, phi_deg: float,
          commands: tuple[float, float, float], throttle: float,
          rates: tuple[float, float, float] = (0.0, 0.0, 0.0), beta_deg: float = 0.0) -> np.ndarray:
    """Initialise JSBSim at this point (body rates `rates` [rad/s], else zero; sideslip
    `beta_deg`, else zero) with the FCS in trim mode; the six accelerations (RESIDUALS) it
    computes there."""
    fdm["ic/h-sl-ft"] = h_m / FT
    fdm["ic/vt-fps"] = V_m_s / FT
    fdm["ic/gamma-deg"] = gamma_deg
    fdm["ic/alpha-deg"] = alpha_deg
    fdm["ic/beta-deg"] = beta_deg
    fdm["ic/phi-deg"] = phi_deg
    fdm["ic/psi-true-deg"] = 0.0
    for axis, rate in zip("pqr", rates):
        fdm[f"ic/{axis}-rad_sec"] = rate
    for prop, value in zip(COMMANDS, commands):
        fdm[prop] = value
    for i in range(n_engines(fdm)):
        fdm[f"fcs/throttle-cmd-norm[{i}]"] = throttle
    fdm.set_trim_status(True)
    try:
        fdm.run_ic()
        if n_engines(fdm):
            fdm.get_propulsion().get_steady_state()
        # a few passes: control laws that read their own outputs (X15's scheduled
        # elevator gain) settle only over several frames
        for _ in range(3):
            fdm.run_ic()
    finally:
        fdm.set_trim_status(False)
    return np.array([fdm[p] for p in RESIDUALS])


def trim(fdm, h_m: float, V_m_s: float, mode: str = "glide", *, gamma_deg: float = 0.0, throttle: float = 0.0,
         max_iterations: int = 40) -> TrimPoint:
    """Solve for steady straight flight at `h_m`, `V_m_s` (true airspeed); see the module
    docstring.  Leaves `fdm` initialised at the trimmed point, ready to run."""
    if mode not in MODES:
        raise ValueError(f"unknown trim mode {mode!r}; choices: {', '.join(MODES)}")
    glide = mode == "glide"
    # x = [alpha_deg, gamma_deg or throttle, elevator, aileron, rudder, phi_deg]
    x = np.array([2.0, -3.0 if glide else 0.5, 0.0, 0.0, 0.0, 0.0])
    steps = np.array([0.01, 0.01 if glide else 0.001, 0.001, 0.001, 0.001, 0.01])
    max_step = np.array([2.0, 2.0 if glide else 0.1, 0.1, 0.1, 0.1, 2.0])

    def residual(v):
        g, thr = (v[1], throttle) if glide else (gamma_deg, v[1])
        return apply(fdm, h_m, V_m_s, v[0], g, v[5], (v[2], v[3], v[4]), thr)

    r = residual(x)
    it = 0
    for it in range(1, max_iterations + 1):
        if np.all(np.abs(r) < TOLERANCE) or not np.all(np.isfinite(r)):
            break
        J = np.empty((6, 6))
        for j in range(6):
            xp = x.copy()
            xp[j] += steps[j]
            J[:, j] = (residual(xp) - r) / steps[j]
        dx = np.linalg.lstsq(J / TOLERANCE[:, None], -r / TOLERANCE, rcond=None)[0]
        x = x + dx * min(1.0, float(np.min(max_step / np.maximum(np.abs(dx), 1e-300))))
        r = residual(x)
    where = f"h {h_m:g} m, V {V_m_s:g} m/s, {mode}"
    if not (np.all(np.isfinite(r)) and np.all(np.abs(r) < TOLERANCE)):
        raise TrimError(f"{fdm.get_model_name()} does not trim at {where}: residual accelerations "
                        f"{np.array2string(r, precision=3)} after {it} iterations "
                        f"(alpha {x[0]:.2f} deg, {'gamma' if glide else 'throttle'} {x[1]:.3g}, "
                        f"commands {np.array2string(x[2:5], precision=3)})")
    if np.any(np.abs(x[2:5]) > 1.0) or not glide and not 0.0 <= x[1] <= 1.0:
        raise TrimError(f"{fdm.get_model_name()} trims at {where} only with a command outside its range "
                        f"(elevator, aileron, rudder {np.array2string(x[2:5], precision=3)}"
                        + ("" if glide else f", throttle {x[1]:.3f}") + ")")
    g, thr = (float(x[1]), throttle) if glide else (gamma_deg, float(x[1]))
    return TrimPoint(h_m=h_m, V_m_s=V_m_s, mode=mode, alpha_deg=float(x[0]), gamma_deg=g, phi_deg=float(x[5]),
                     elevator_cmd=float(x[2]), aileron_cmd=float(x[3]), rudder_cmd=float(x[4]), throttle=thr,
                     max_residual=(float(np.max(np.abs(r[:3]))), float(np.max(np.abs(r[3:])))), iterations=it)


def initialise(fdm, point: TrimPoint, commands: tuple[float, float, float] | None = None,
               rates: tuple[float, float, float] = (0.0, 0.0, 0.0), *, alpha_offset_deg: float = 0.0,
               beta_deg: float = 0.0) -> np.ndarray:
    """Initialise `fdm` at `point` (optionally with other pilot commands, body rates, an
    angle of attack offset from the trim's or a sideslip: a static probe of the FCS); the
    accelerations there."""
    cmd = commands if commands is not None else (point.elevator_cmd, point.aileron_cmd, point.rudder_cmd)
    return apply(fdm, point.h_m, point.V_m_s, point.alpha_deg + alpha_offset_deg, point.gamma_deg, point.phi_deg, cmd,
                 point.throttle, rates, beta_deg)


def sink_rate(point: TrimPoint) -> float:
    """Rate of descent of the trimmed flight [m/s] (positive down)."""
    return -point.V_m_s * math.sin(math.radians(point.gamma_deg))
