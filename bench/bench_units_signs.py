"""Benchmark: the unit and sign check (aerosid/plausibility) on flights nobody tuned it on.

Run:  python bench/bench_units_signs.py [--seeds 0 1] [--aircraft c172p c182 ...] [--sidpac DIR]
                                        [--out bench/results/units_signs.md]

Every JSBSim aircraft of the list (``aerosid simulate --jsbsim``'s flight, its generated
vehicle file) and NASA's Twin Otter as ``aerosid import sidpac`` writes it: the recorded
flight must raise nothing (a false alarm refuses a good flight), and each mistake below,
made on one channel at a time, must be named -- the right column first (a pair where the
kinematics cannot tell which: counted apart), never another one.  The measured air data's
mistakes are made on the flight with a density, dynamic and static pressure and total temperature added where it
has none (the Twin Otter keeps its own); the vane-noise rows change the vehicle file's
[air_data] noise_rad, and "named" means the finding names that key.  The calibrated-airspeed
rows replace V_m_s by the calibrated airspeed at the flight's altitude (US-1976), counted by
the flight's median altitude: below about 3 km a calibrated airspeed is within 12 % of the
true one and the kinematics are not expected to tell.  The impact-pressure rows replace the
measured qbar_pa by the impact pressure of the same day, counted by the flight's median Mach
(below 0.6 q_c is within 9 % of q-bar and not told apart).  The 737 and 787-8 stay out
(reserved for independent checks).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import math
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from machine import cpu_model as _cpu_model, loadavg as _loadavg  # noqa: E402  (bench/machine.py)

AIRCRAFT = ["c172x", "c172p", "c172r", "c182", "c310", "pa28", "J3Cub", "OV10", "T37", "F4N", "A4", "f15",
            "p51d", "sgs126", "minisgs", "sgs233", "t6texan2", "C130", "Boeing314", "DHC6", "B747", "F80C", "A320",
            "global5000", "pogo-jsbsim"]
DEG = 180.0 / math.pi
#: label -> (column, factor, the column the finding must name)
MISTAKES = {
    "a_z with z up": ("az_m_s2", -1.0, "az_m_s2"),
    "q flipped": ("q_rad_s", -1.0, "q_rad_s"),
    "alpha vane flipped": ("alpha_vane_rad", -1.0, "alpha_vane_rad"),
    "theta flipped": ("theta_rad", -1.0, "theta_rad"),
    "p flipped": ("p_rad_s", -1.0, "p_rad_s"),
    "phi flipped": ("phi_rad", -1.0, "phi_rad"),
    "r flipped": ("r_rad_s", -1.0, "r_rad_s"),
    "beta vane flipped": ("beta_vane_rad", -1.0, "beta_vane_rad"),
    "a_y flipped": ("ay_m_s2", -1.0, "ay_m_s2"),
    "alpha vane in deg": ("alpha_vane_rad", DEG, "alpha_vane_rad"),
    "beta vane in deg": ("beta_vane_rad", DEG, "beta_vane_rad"),
    "theta in deg": ("theta_rad", DEG, "theta_rad"),
    "V in kt": ("V_m_s", 1 / 0.514444, "V_m_s"),
    "V in ft/s": ("V_m_s", 1 / 0.3048, "V_m_s"),
    # measured air data (each flight given a density, dynamic and static pressure and total temperature
    # where it has none: aerosid.simulation.sensors.with_measured_air_data), written in another unit
    "qbar in psf": ("qbar_pa", 1 / 47.880259, "qbar_pa"),
    "qbar in kPa": ("qbar_pa", 1e-3, "qbar_pa"),
    "rho in slug/ft^3": ("rho_kg_m3", 1 / 515.378818, "rho_kg_m3"),
    "p_static in hPa": ("p_static_pa", 1e-2, "p_static_pa"),
    "p_static in inHg": ("p_static_pa", 1 / 3386.389, "p_static_pa"),
    "T_total in degR": ("T_total_K", 1.8, "T_total_K"),
}
AIR_COLUMNS = ("rho_kg_m3", "qbar_pa", "p_static_pa", "T_total_K")
#: label -> factor on the vehicle file's [air_data] noise_rad (the finding must name that key)
SETTINGS = {"vane noise_rad in deg": 1 / DEG, "vane noise_rad x10": 10.0, "vane noise_rad x0.1": 0.1}
#: label -> the median altitude band [m] of the flights counted in it (V_m_s a calibrated airspeed)
AIRSPEED_BANDS = {"V_m_s a calibrated airspeed, h >= 4 km": (4000.0, math.inf),
                  "V_m_s a calibrated airspeed, h < 4 km": (-math.inf, 4000.0)}
#: label -> the median Mach band of the flights counted in it (qbar_pa an impact pressure)
IMPACT_BANDS = {"qbar_pa an impact pressure, Mach >= 0.6": (0.6, math.inf),
                "qbar_pa an impact pressure, Mach < 0.6": (-math.inf, 0.6)}


def with_impact_pressure(measured):
    """qbar_pa replaced by the impact pressure of the same day (the measured static pressure and
    total temperature); (frame, median Mach)."""
    import numpy as np

    from aerosid.vehicles.airspeed import _qc_over_p
    from aerosid.vehicles.atmosphere import CP_AIR_J_KG_K, GAMMA_AIR, R_AIR_J_KG_K

    V = measured["V_m_s"].to_numpy(float)
    T = measured["T_total_K"].to_numpy(float) - V**2 / (2.0 * CP_AIR_J_KG_K)
    mach = V / np.sqrt(GAMMA_AIR * R_AIR_J_KG_K * T)
    return measured.assign(qbar_pa=measured["p_static_pa"] * _qc_over_p(mach)), float(np.nanmedian(mach))


def as_calibrated(frame):
    """V_m_s replaced by the calibrated airspeed of the same flight (US-1976 at h_m)."""
    from aerosid.vehicles.airspeed import calibrated_from_true_m_s

    out = frame.copy()
    ok = out["V_m_s"].notna() & out["h_m"].notna()
    out.loc[ok, "V_m_s"] = calibrated_from_true_m_s(out.loc[ok, "V_m_s"].to_numpy(), out.loc[ok, "h_m"].to_numpy())
    return out


TURBULENT = ["c182", "c310", "pa28", "J3Cub", "A4", "f15"]


def turbulent_flights(aircraft: list[str], work: Path):
    """(label, telemetry, vehicle): seed 0 in light and in moderate turbulence (the vane reads
    the air's angles, the kinematics the body's: the fits the signs are read from suffer)."""
    from aerosid.simulation.jsbsim_aircraft import simulate_aircraft
    from aerosid.vehicles.vehicle import load_vehicle

    for name in aircraft:
        for level in ("light", "moderate"):
            fl = simulate_aircraft(name, 0, turbulence=level)
            path = work / f"{name}_{level}.toml"
            path.write_text(fl.files["vehicle.toml"])
            yield f"{name} {level} turbulence", fl.telemetry, load_vehicle(path)


def flights(aircraft: list[str], seeds: list[int], sidpac: Path | None, work: Path):
    """(label, telemetry, vehicle) for every flight."""
    from aerosid.simulation.jsbsim_aircraft import simulate_aircraft
    from aerosid.simulation.jsbsim_flight import simulate_jsbsim
    from aerosid.vehicles.vehicle import load_vehicle

    for name in aircraft:
        for seed in seeds:
            if name == "c172x":  # the built-in vehicle and its own flight
                yield f"{name} seed {seed}", simulate_jsbsim(name, "3211", seed=seed).telemetry, load_vehicle(name)
                continue
            fl = simulate_aircraft(name, seed)
            path = work / f"{name}_{seed}.toml"
            path.write_text(fl.files["vehicle.toml"])
            yield f"{name} seed {seed}", fl.telemetry, load_vehicle(path)
    if sidpac is not None:
        from aerosid.vehicles.sidpac import import_sidpac

        for mat in sorted(sidpac.glob("lon_*.mat")):
            imported = import_sidpac(mat)
            path = work / f"{mat.stem}.toml"
            path.write_text(imported.vehicle_toml)
            yield f"Twin Otter {mat.stem} (real)", imported.telemetry, load_vehicle(path)


def tally(cases) -> dict:
    """Per mistake: named (the column alone), pair, wrong (another column), missed, n; and the
    false alarms and wrong columns by flight."""
    from aerosid.plausibility.units import unit_findings
    from aerosid.simulation.sensors import with_measured_air_data

    import dataclasses

    counts = {m: {"named": 0, "pair": 0, "wrong": 0, "missed": 0, "n": 0}
              for m in (*MISTAKES, *SETTINGS, *AIRSPEED_BANDS, *IMPACT_BANDS)}
    false, wrong, n = [], [], 0
    for label, frame, veh in cases:
        n += 1
        measured = with_measured_air_data(frame)
        for which, f in (("", frame), (" (with measured air data)", measured)):
            clean = unit_findings(f, veh)
            if clean:
                false.append(f"{label}{which}: {clean[0].message()[:160]}")
        for m, (col, factor, want) in MISTAKES.items():
            base = measured if col in AIR_COLUMNS else frame
            if col not in base.columns:
                continue
            found = unit_findings(base.assign(**{col: base[col] * factor}), veh)
            c = counts[m]
            c["n"] += 1
            if not found:
                c["missed"] += 1
            elif found[0].columns == (want,):
                c["named"] += 1
            elif want in found[0].columns:
                c["pair"] += 1
            else:
                c["wrong"] += 1
                wrong.append(f"{label}, {m}: named {found[0].columns}")
        def count_kind(m: str, found: list, kind: str) -> None:
            """A mistake whose finding is named by its kind (a vehicle-file setting, the airspeed's)."""
            c = counts[m]
            c["n"] += 1
            if not found:
                c["missed"] += 1
            elif found[0].kind == kind:
                c["named"] += 1
            else:
                c["wrong"] += 1
                wrong.append(f"{label}, {m}: named {found[0].columns}")

        for m, factor in SETTINGS.items():
            if veh.air_data_source == "vanes" and veh.vane_noise_rad > 0:
                count_kind(m, unit_findings(frame, dataclasses.replace(veh, vane_noise_rad=veh.vane_noise_rad * factor)),
                           "setting")
        h = float(frame["h_m"].median())
        band = next(b for b, (lo, hi) in AIRSPEED_BANDS.items() if lo <= h < hi)
        count_kind(band, unit_findings(as_calibrated(frame), veh), "airspeed")
        impact, mach = with_impact_pressure(measured)
        count_kind(next(b for b, (lo, hi) in IMPACT_BANDS.items() if lo <= mach < hi), unit_findings(impact, veh),
                   "pressure")
    return {"counts": counts, "false": false, "wrong": wrong, "n": n}


def table(result: dict, title: str) -> list[str]:
    lines = [f"## {title}", "", f"Flights: {result['n']}. False alarms on the recorded flights (each also checked with measured air "
             f"data added, a cold high-pressure day: 4 % above US-1976's pressure, 12 K below its temperature): "
             f"**{len(result['false'])}**.", "",
             "| mistake | flights | named (the column alone) | a pair holding it | another column | missed |",
             "|---|---|---|---|---|---|"]
    for m, c in result["counts"].items():
        lines.append(f"| {m} | {c['n']} | {c['named']} | {c['pair']} | {c['wrong']} | {c['missed']} |")
    if result["false"]:
        lines += ["", "False alarms:", *[f"- {f}" for f in result["false"]]]
    if result["wrong"]:
        lines += ["", "Another column named:", *[f"- {w}" for w in result["wrong"]]]
    return lines + [""]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--aircraft", nargs="+", default=AIRCRAFT)
    ap.add_argument("--sidpac", type=Path, default=Path(__file__).parents[1] / "tests" / "data" / "sidpac-twin-otter")
    ap.add_argument("--turbulent", nargs="*", default=TURBULENT, help="aircraft also flown in turbulence")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "units_signs.md")
    args = ap.parse_args()
    t0 = time.time()
    with tempfile.TemporaryDirectory() as tmp:
        calm = tally(flights(args.aircraft, args.seeds, args.sidpac if args.sidpac.is_dir() else None, Path(tmp)))
        rough = tally(turbulent_flights(args.turbulent, Path(tmp)))
    lines = [
        "# The unit and sign check on flights it was not tuned on",
        "",
        f"{_dt.date.today()}, {_cpu_model()}, load {_loadavg()}; wall {time.time() - t0:.0f} s. "
        f"`python bench/bench_units_signs.py --seeds {' '.join(map(str, args.seeds))}`.",
        "",
        __doc__.split("\n\n", 2)[2].strip(),
        "",
        *table(calm, "Calm air: the JSBSim aircraft and the real Twin Otter"),
        *table(rough, "Turbulence (seed 0, light and moderate; the vehicle files do not declare it)"),
    ]
    args.out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
