"""A simulation case: trajectory, manoeuvre plan, flight deviations, sensors, faults."""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

from aerosid.vehicles.vehicle import DATA_DIR, Vehicle, load_vehicle


#: Default 1-sigma white noise of the INS's roll and pitch attitude [deg] (a navigation-grade
#: system's attitude output is good to 0.05-0.1 deg); [sensors] attitude_noise_deg overrides it.
ATTITUDE_NOISE_DEG = 0.1


@dataclass(frozen=True)
class SensorSpec:
    """1-sigma noise: accelerometers [m/s^2], gyros [rad/s], fins [rad], V [m/s], h [m],
    the INS's roll and pitch attitude [rad]."""

    accel_noise_m_s2: tuple[float, float, float] = (0.8, 1.0, 2.0)
    gyro_noise_rad_s: tuple[float, float, float] = (0.06981317, 0.03490659, 0.01745329)
    fin_noise_rad: float = 3.5e-4
    V_noise_m_s: float = 0.3
    h_noise_m: float = 3.0
    attitude_noise_rad: float = math.radians(ATTITUDE_NOISE_DEG)

    def scaled(self, factor: float) -> "SensorSpec":
        """Every sensor's 1-sigma noise multiplied by `factor` [-] (a sensitivity study)."""
        return SensorSpec(**{f.name: (tuple(factor * v for v in getattr(self, f.name))
                                      if isinstance(getattr(self, f.name), tuple) else factor * getattr(self, f.name))
                             for f in fields(self)})


@dataclass(frozen=True)
class FaultSpec:
    """Telemetry faults: dropout bursts (all channels), outlier spikes, one sync gap."""

    dropout_rate_per_s: float = 0.15
    dropout_length_s: tuple[float, float] = (0.02, 0.3)
    dropout_nan_fraction: float = 0.4
    outlier_probability: float = 0.001
    outlier_size_sigma: tuple[float, float] = (6.0, 40.0)
    sync_gap_at: float = 0.45
    sync_gap_s: float = 2.0

    def without_faults(self) -> "FaultSpec":
        return replace(self, dropout_rate_per_s=0.0, outlier_probability=0.0, sync_gap_s=0.0)


@dataclass(frozen=True)
class SimulationCase:
    """Everything the simulator needs besides the seed and the hidden effects."""

    name: str
    vehicle: Vehicle
    duration_s: float
    sample_rate_hz: float
    h0_m: float
    V0_m_s: float
    gamma0_rad: float
    heading0_rad: float
    deviations: dict = field(default_factory=dict)
    autopilot: dict = field(default_factory=dict)
    period_s: float = 78.0
    ramp_s: float = 0.3
    pitch_plan: tuple = ()  # (start_s, duration_s, delta_p/2 [rad])
    roll_plan: tuple = ()  # (start_s, duration_s, phi_cmd [rad])
    yaw_plan: tuple = ()  # (start_s, duration_s, delta_y/2 [rad])
    sensors: SensorSpec = SensorSpec()
    faults: FaultSpec = FaultSpec()
    #: designed input time histories replacing the plans (aerosid.design.io.INPUT_COLUMNS):
    #: column -> (t_s, values) arrays, e.g. "delta_p_cmd_rad" replaces pitch_plan
    inputs: dict = field(default_factory=dict)


def _is_jsbsim(path: Path) -> bool:
    return "jsbsim" in tomllib.loads(path.read_text())


def builtin_cases() -> list[str]:
    """Cases of the built-in simulator (JSBSim-flown ones, e.g. c172x, use --jsbsim)."""
    return sorted(p.parent.name for p in DATA_DIR.glob("*/simulation.toml") if not _is_jsbsim(p))


def load_case(name: str = "seed-rlv", **overrides) -> SimulationCase:
    """Load a built-in case (``aerosid/data/<name>/simulation.toml``); keyword
    overrides replace fields (e.g. duration_s=600, sample_rate_hz=200)."""
    path = DATA_DIR / name / "simulation.toml"
    if not path.is_file():
        raise KeyError(f"unknown simulation case {name!r}; built-in: {', '.join(builtin_cases())}")
    doc = tomllib.loads(path.read_text())
    if "jsbsim" in doc:
        raise KeyError(f"case {name!r} is flown by JSBSim: aerosid simulate --jsbsim {name} --manoeuvre 3211")
    import math

    deg = math.pi / 180.0
    s, f = doc["sensors"], doc["faults"]
    m = doc["manoeuvres"]
    case = SimulationCase(
        name=name,
        vehicle=load_vehicle(name),
        duration_s=float(doc["flight"]["duration_s"]),
        sample_rate_hz=float(doc["flight"]["sample_rate_hz"]),
        h0_m=float(doc["trajectory"]["h0_m"]),
        V0_m_s=float(doc["trajectory"]["V0_m_s"]),
        gamma0_rad=float(doc["trajectory"]["gamma0_deg"]) * deg,
        heading0_rad=float(doc["trajectory"]["heading0_deg"]) * deg,
        deviations=dict(doc.get("deviations", {})),
        autopilot={**doc["autopilot"], "gamma_floor_rad": doc["autopilot"]["gamma_floor_deg"] * deg,
                   "gamma_rate_rad_s": doc["autopilot"]["gamma_rate_deg_s"] * deg},
        period_s=float(m["period_s"]),
        ramp_s=float(m["ramp_s"]),
        pitch_plan=tuple((a, b, c * deg) for a, b, c in m["pitch"]),
        roll_plan=tuple((a, b, c * deg) for a, b, c in m["roll"]),
        yaw_plan=tuple((a, b, c * deg) for a, b, c in m["yaw"]),
        sensors=SensorSpec(
            accel_noise_m_s2=tuple(s["accel_noise_m_s2"]),
            gyro_noise_rad_s=tuple(v * deg for v in s["gyro_noise_deg_s"]),
            fin_noise_rad=s["fin_noise_deg"] * deg,
            V_noise_m_s=s["V_noise_m_s"],
            h_noise_m=s["h_noise_m"],
            attitude_noise_rad=s.get("attitude_noise_deg", ATTITUDE_NOISE_DEG) * deg,
        ),
        faults=FaultSpec(
            dropout_rate_per_s=f["dropout_rate_per_s"],
            dropout_length_s=tuple(f["dropout_length_s"]),
            dropout_nan_fraction=f["dropout_nan_fraction"],
            outlier_probability=f["outlier_probability"],
            outlier_size_sigma=tuple(f["outlier_size_sigma"]),
            sync_gap_at=f["sync_gap_at"],
            sync_gap_s=f["sync_gap_s"],
        ),
    )
    return replace(case, **overrides) if overrides else case


def case_source(name: str) -> Path:
    return DATA_DIR / name / "simulation.toml"
