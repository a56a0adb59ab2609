"""Accuracy of the EBM pipeline on the JSBSim-flown c172x validation flight, seeds 0-9.

    python bench/bench_jsbsim.py [--seeds 0-9]

Each seed: ``simulate_jsbsim("c172x", "3211", seed)`` (noise and faults), then the
in-memory pipeline ``process_telemetry`` with the vehicle file's defaults
(``aerosid/data/c172x/vehicle.toml``: [estimation], [air_data], [models]) and no Mach
window.  Errors are against JSBSim's linear truth at the trim point, about the CG
(``flight.coefficients``).  ``damping`` is the combined pitch damping
Cm_q + Cm_alpha_dot (``LinearFit.combination``, sigma from the full covariance), the
quantity a short-period manoeuvre determines; Cm_q and Cm_alpha_dot are listed alone
too.  The "oracle" column fits the same model to the noise-free truth (aero +
propeller pitching moment, true regressors): the part of the error that no
estimator can remove with this model.  Writes bench/results/jsbsim.md.
One process (the machine is shared).
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time
import warnings
from datetime import date
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from machine import cpu_model, loadavg  # noqa: E402  (bench/machine.py)

BARS = {"Cm_alpha": 5.0, "Cm_delta_p": 5.0, "damping": 10.0}
OTHER = ("Cm_q", "Cm_alpha_dot", "CN_alpha", "Cl_beta", "Cl_p", "Cl_delta_r", "Cn_beta", "Cn_r", "Cn_delta_y")
TRUTH_NAME = {"damping": "Cm_q_plus_alpha_dot"}


def parse_seeds(text: str) -> list[int]:
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(s) for s in text.split(",")]


def oracle(flight) -> dict[str, float]:
    """The Cm model fitted by least squares to the noise-free truth (what the sensors
    see: aerodynamic + propeller moment) with the true regressors."""
    T = flight.truth
    X = np.column_stack([np.ones(len(T)), T["alpha_rad"], T["delta_p_rad"], T["q_hat"], T["alpha_dot_hat"],
                         np.abs(T["beta_rad"])])
    y = (T["Cm"] + T["Cm_prop"]).to_numpy()
    sol = np.linalg.lstsq(X, y, rcond=None)[0]
    return {"Cm_alpha": sol[1], "Cm_delta_p": sol[2], "damping": sol[3] + sol[4]}


def one(seed: int) -> dict:
    from aerosid.ebm import process_telemetry
    from aerosid.simulation.jsbsim_flight import simulate_jsbsim
    from aerosid.vehicles.vehicle import load_vehicle

    flight = simulate_jsbsim("c172x", "3211", seed=seed)
    truth = {k: flight.coefficients[TRUTH_NAME.get(k, k)] for k in (*BARS, *OTHER)}
    row = {"seed": seed, "failed": ""}
    orc = oracle(flight)
    for k, v in orc.items():
        row[f"{k}_oracle_pct"] = 100.0 * (v / truth[k] - 1.0)
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            run = process_telemetry(flight.telemetry, load_vehicle("c172x"), mach_half_width=None)
    except Exception as exc:  # a failed run counts as a miss of every bar
        row["failed"] = f"{type(exc).__name__}: {exc}"
        return row
    row["time_s"] = time.perf_counter() - t0
    tab = run.identification.table().set_index("coefficient")
    est_se = {k: (float(tab.loc[k, "estimate"]), float(tab.loc[k, "std_error"])) for k in (*BARS, *OTHER) if k in tab.index}
    est_se["damping"] = run.identification.fits["Cm"].combination({"Cm_q": 1.0, "Cm_alpha_dot": 1.0})[:2]
    for k in (*BARS, *OTHER):
        est, se = est_se[k]
        row[f"{k}_err_pct"] = 100.0 * (est / truth[k] - 1.0)
        row[f"{k}_cover"] = bool(abs(est - truth[k]) <= 1.96 * se)
        row[f"{k}_se_pct"] = 100.0 * se / abs(truth[k])
    fr = run.smoothed[0].frame
    idx = np.rint(fr["t_s"].to_numpy() * 100.0).astype(int)
    row["rms_q_dot_err"] = float(np.sqrt(np.nanmean((fr["q_dot_rad_s2"].to_numpy()
                                                     - flight.truth["q_dot_rad_s2"].to_numpy()[idx]) ** 2)))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-9")
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    load0 = loadavg()
    rows = [one(s) for s in seeds]
    load1 = loadavg()
    ok = [r for r in rows if not r["failed"]]
    failed = [r for r in rows if r["failed"]]
    n = len(rows)
    lines = [f"# EBM accuracy on the JSBSim c172x validation flight, {n} seeds", "",
             f"{date.today()}, Python {platform.python_version()}, machine: {cpu_model()}, {os.cpu_count()} cores, "
             f"load average {load0} (start) / {load1} (end); one process.", "",
             "Flight: `simulate_jsbsim(\"c172x\", \"3211\", seed)` (aerosid/data/c172x/simulation.toml: a -6 deg "
             "glide near zero thrust, two mirrored elevator 3-2-1-1s, aileron and rudder doublets, noise and faults); pipeline: `process_telemetry` with "
             "the vehicle file's defaults, no Mach window.  Truth: JSBSim's linear truth at trim about the CG; "
             "`damping` = C_m_q + C_m_alpha_dot (sum of the two estimates, sigma from their covariance).  Errors in % of the truth; a failed run counts "
             "as a miss.  *oracle*: the same Cm model fitted to the noise-free truth (aero + propeller moment, "
             "true regressors) - the part of the error the model itself makes.", "",
             f"Runs completed: {len(ok)} of {n}" + (f"; failed seeds: {', '.join(str(r['seed']) for r in failed)} "
                                                     f"({failed[0]['failed']})" if failed else "") + ".", "",
             "| coefficient | bar | mean error % | RMS error % | max abs error % | seeds within bar | "
             "95 % interval coverage | mean std error % | oracle mean % |",
             "|---|---|---|---|---|---|---|---|---|"]
    for k in (*BARS, *OTHER):
        if not ok:
            break
        e = np.array([r[f"{k}_err_pct"] for r in ok])
        cov = np.mean([r[f"{k}_cover"] for r in ok])
        se = np.mean([r[f"{k}_se_pct"] for r in ok])
        bar = BARS.get(k)
        within = f"{int(np.sum(np.abs(e) <= bar))} / {n}" if bar else "-"
        orc = f"{np.mean([r[f'{k}_oracle_pct'] for r in rows]):+.1f}" if k in BARS else "-"
        lines.append(f"| {k} | {f'{bar:g} %' if bar else '-'} | {e.mean():+.1f} | {np.sqrt(np.mean(e ** 2)):.1f} | "
                     f"{np.abs(e).max():.1f} | {within} | {cov:.0%} | {se:.1f} | {orc} |")
    if ok:
        lines += ["", f"Smoothed q_dot RMS error: mean {np.mean([r['rms_q_dot_err'] for r in ok]):.4f} rad/s^2; "
                      f"pipeline time per flight {np.mean([r['time_s'] for r in ok]):.1f} s.", "",
                  "Per seed (error %):", "", "| seed | " + " | ".join(BARS) + " |", "|---|" + "---|" * len(BARS)]
    for r in rows:
        cells = ["failed"] * len(BARS) if r["failed"] else [f"{r[f'{k}_err_pct']:+.1f}" for k in BARS]
        lines.append(f"| {r['seed']} | " + " | ".join(cells) + " |")
    out = Path(__file__).parent / "results" / "jsbsim.md"
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
