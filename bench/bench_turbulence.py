"""Least squares against instrumental variables on flights in JSBSim's turbulence.

    python bench/bench_turbulence.py [--vehicles c172x,pa28,OV10] [--seeds 0-3]
                                     [--levels none,light] [--jobs 2]

Each (vehicle, seed, level): ``simulate_jsbsim(vehicle, "3211", seed, turbulence=level)`` (JSBSim's
MIL-F-8785C model in its Tustin form, rotational gusts included: aerosid.simulation.jsbsim_turbulence.
TURBULENCE_SEVERITY), the pipeline in memory (``process_telemetry``, default settings), then
``identify`` twice on the same flight data: least squares + SIMEX (the default) and the
instrumental-variable fit (``instrumental=True``, what ``[estimation] turbulent_air = true`` selects;
aerosid.identification.instrumental).  Both with the default estimator-bias check.  Errors in % of
the at-trim truth, coverage = |estimate - truth| <= 1.96 sigma; the coefficients and truth of
bench/bench_generalisation.py.  The vehicles are flown with the generated flight design and
vehicle file (c172x: its hand-written ones).

Writes bench/results/turbulence.md and bench/results/turbulence_runs.csv.
"""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from datetime import date
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).parent))
from machine import cpu_model, loadavg  # noqa: E402  (bench/machine.py)

NAMES = ("Cm_alpha", "Cm_delta", "damping", "CN_alpha", "Cl_p", "Cl_delta", "Cn_beta", "Cn_r", "Cn_delta")


def one(job: tuple[str, int, str]) -> list[dict]:
    import bench_generalisation as G
    from aerosid.ebm import process_telemetry
    from aerosid.identification.identify import identify

    vehicle_name, seed, level = job
    base = {"vehicle": vehicle_name, "seed": seed, "turbulence": level}
    with tempfile.TemporaryDirectory() as tmp:
        flight, vehicle = G.simulate(vehicle_name, seed, Path(tmp), turbulence=level)
    T = flight.truth
    V = T["V_m_s"].to_numpy()
    base["alpha_gust_deg"] = math.nan
    base["p_gust_rad_s"] = float(np.std(T["p_rad_s"].to_numpy() - T["p_hat"].to_numpy() * 2 * V / vehicle.span_m))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            run = process_telemetry(flight.telemetry, vehicle)
    except Exception as exc:  # recorded, not hidden
        return [{**base, "estimator": "-", "failed": f"{type(exc).__name__}: {exc}"}]
    rows = []
    for estimator, iv in (("least squares", False), ("instrumental", True)):
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ident = identify(run.flight_data, vehicle, instrumental=iv)
        row = {**base, "estimator": estimator, "failed": "", "identify_s": time.perf_counter() - t0}
        for name in NAMES:
            truth = G.truth_of(flight, name)
            est, se = G.estimate_of(ident, name)
            row[f"{name}_err_pct"] = 100 * (est / truth - 1) if math.isfinite(est) and truth else math.nan
            row[f"{name}_sigma_pct"] = 100 * se / abs(truth) if math.isfinite(se) and truth else math.nan
            row[f"{name}_cover"] = bool(abs(est - truth) <= 1.96 * se) if math.isfinite(est) else False
        rows.append(row)
    return rows


def table(df: pd.DataFrame) -> list[str]:
    lines = ["| vehicle | air | estimator | " + " | ".join(NAMES) + " |",
             "|---|---|---|" + "---|" * len(NAMES)]
    for (veh, level, est), g in df.groupby(["vehicle", "turbulence", "estimator"], sort=False):
        cells = []
        for n in NAMES:
            e = g[f"{n}_err_pct"].dropna()
            if e.empty:
                cells.append("-")
                continue
            cells.append(f"{e.mean():+.1f} / {np.sqrt((e ** 2).mean()):.1f} / {100 * g[f'{n}_cover'].mean():.0f} % "
                         f"(σ {g[f'{n}_sigma_pct'].mean():.1f})")
        lines.append(f"| {veh} | {level} | {est} | " + " | ".join(cells) + " |")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--vehicles", default="c172x,pa28,OV10")
    ap.add_argument("--seeds", default="0-3")
    ap.add_argument("--levels", default="none,light")
    ap.add_argument("--jobs", type=int, default=1)
    args = ap.parse_args()
    a, _, b = args.seeds.partition("-")
    seeds = list(range(int(a), int(b or a) + 1))
    jobs = [(v, s, lev) for v in args.vehicles.split(",") for lev in args.levels.split(",") for s in seeds]
    load0, t0 = loadavg(), time.perf_counter()
    rows = []

    def done(job, rs) -> None:  # progress on stdout, a line per flight
        rows.extend(rs)
        print(f"[{time.perf_counter() - t0:6.0f} s] {job}: " + "; ".join(
            f"{r['estimator']} C_l,p {r.get('Cl_p_err_pct', math.nan):+.0f} %" for r in rs), flush=True)

    if args.jobs > 1:
        with ProcessPoolExecutor(args.jobs) as ex:
            for job, rs in zip(jobs, ex.map(one, jobs)):
                done(job, rs)
    else:
        for job in jobs:
            done(job, one(job))
    wall = time.perf_counter() - t0
    df = pd.DataFrame(rows)
    out = ROOT / "bench" / "results"
    df.to_csv(out / "turbulence_runs.csv", index=False)
    head = [f"# Least squares against instrumental variables in JSBSim's turbulence ({len(seeds)} seeds)", "",
            f"{date.today().isoformat()}, `python bench/bench_turbulence.py --vehicles {args.vehicles} --seeds "
            f"{args.seeds} --levels {args.levels} --jobs {args.jobs}`; {cpu_model()}, load {load0} (start) / "
            f"{loadavg()} (end); wall {wall / 60:.1f} min.  Definitions: the script's docstring.", "",
            "Cells: mean / RMS error % / 95 % coverage (mean reported σ %), over the seeds.", ""]
    failed = df[df["failed"].fillna("") != ""]
    tail = [f"\nFailed runs: {len(failed)}"] + [f"- {r.vehicle} seed {r.seed} {r.turbulence}: {r.failed}"
                                                 for r in failed.itertuples()]
    gust = df.groupby(["vehicle", "turbulence"])["p_gust_rad_s"].mean()
    tail += ["", "Rolling gust (std of p - p_air over the flight, rad/s): "
             + ", ".join(f"{v} {lev} {x:.3f}" for (v, lev), x in gust.items())]
    (out / "turbulence.md").write_text("\n".join(head + table(df[df["failed"].fillna("") == ""]) + tail) + "\n")
    print("\n".join(head + table(df[df["failed"].fillna("") == ""]) + tail))


if __name__ == "__main__":
    main()
