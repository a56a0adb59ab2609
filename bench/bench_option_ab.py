"""A default changed, flight by flight: the generalisation bench's flights run with the shipped
smoother defaults (B) and with one or more options set back (A), and what moved.

For every (vehicle, seed): both runs' estimates of the bench's coefficients (bench_generalisation
COEFFICIENTS) and their error against the truth; whether the two runs are identical; the
largest shift of a barred coefficient in the A run's sigma; the findings each run reports;
a failed run's message.  Per vehicle: flights that differ, mean |error| of each barred
coefficient under A and B, failures and findings.

    python bench/bench_option_ab.py --set gyro_gate_hold_s=null --vehicles c172x,pa28 --seeds 0-1 --jobs 2 \\
        --out gate_hold_ab

--set NAME=JSON (repeatable): the A run's smoothing options (aerosid.estimation.pipeline.EBMOptions),
e.g. gyro_gate_hold_s=null; the B run takes the defaults.  Writes bench/results/NAME.md and NAME_runs.csv.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
import warnings
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
from bench_accuracy import parse_seeds  # noqa: E402
from bench_generalisation import BARRED, COEFFICIENTS, estimate_of, simulate, truth_of  # noqa: E402
from machine import loadavg, run_jobs, run_line  # noqa: E402


def _run(telemetry, vehicle, options: dict):
    from aerosid.ebm import process_telemetry

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return process_telemetry(telemetry, vehicle, smoothing_options=options or None), ""
        except Exception as exc:  # a failed run is a result of the comparison
            return None, f"{type(exc).__name__}: {str(exc)[:300]}"


def _findings(run) -> str:
    return "; ".join(f"{f['kind']} {f['channel']} {f['t0_s']:.1f}-{f['t1_s']:.1f} s" for f in run.findings)


def one(job: tuple) -> dict:
    vehicle_name, seed, options = job
    with tempfile.TemporaryDirectory() as tmp:
        flight, vehicle = simulate(vehicle_name, seed, Path(tmp))
    row = {"vehicle": vehicle_name, "seed": seed}
    runs = {}
    for arm, opts in (("A", options), ("B", {})):
        start = time.perf_counter()
        run, failed = _run(flight.telemetry, vehicle, opts)
        row[f"{arm}_time_s"] = time.perf_counter() - start
        row[f"{arm}_failed"] = failed
        row[f"{arm}_findings"] = _findings(run) if run is not None else ""
        runs[arm] = run
        for name in COEFFICIENTS:
            est, se = estimate_of(run.identification, name) if run is not None else (math.nan, math.nan)
            truth = truth_of(flight, name)
            row[f"{name}_{arm}"], row[f"{name}_{arm}_se"] = est, se
            if math.isfinite(truth) and truth != 0 and math.isfinite(est):
                row[f"{name}_{arm}_err_pct"] = 100.0 * (est / truth - 1.0)
    shifts = [abs(row[f"{n}_B"] - row[f"{n}_A"]) / row[f"{n}_A_se"] for n in BARRED
              if math.isfinite(row[f"{n}_A"]) and math.isfinite(row[f"{n}_B"]) and row[f"{n}_A_se"] > 0]
    row["max_shift_sigma"] = max(shifts) if shifts else math.nan
    a, b = runs["A"], runs["B"]
    row["identical"] = (a is None and b is None) or bool(a is not None and b is not None
                                                         and a.flight_data.equals(b.flight_data))
    return row


def report(df: pd.DataFrame, args, load, wall_s: float) -> str:
    lines = [f"# A default changed, flight by flight ({args.out})", "",
             run_line(load, args.jobs, wall_s) + ".", "",
             f"`python bench/bench_option_ab.py {' '.join(sys.argv[1:])}`", "",
             f"A: the smoothing options {', '.join(args.set)}; B: the shipped defaults. Shift: |B - A| / sigma(A) "
             "of a barred coefficient. Error columns: mean |error| [%] over the vehicle's flights that both runs "
             "estimate.", ""]
    head = "| vehicle | flights | differ | failed A | failed B | largest shift [sigma] |"
    head += "".join(f" {n} A | {n} B |" for n in BARRED)
    lines += [head, "|" + "---|" * (6 + 2 * len(BARRED))]
    for veh, g in df.groupby("vehicle", sort=False):
        cells = [veh, str(len(g)), str(int((~g["identical"]).sum())), str(int((g["A_failed"] != "").sum())),
                 str(int((g["B_failed"] != "").sum())), f"{g['max_shift_sigma'].max():.2f}"]
        for n in BARRED:
            both = g[[f"{n}_A_err_pct", f"{n}_B_err_pct"]].dropna() if f"{n}_A_err_pct" in g and f"{n}_B_err_pct" in g \
                else pd.DataFrame()
            cells += ([f"{both[f'{n}_A_err_pct'].abs().mean():.1f}", f"{both[f'{n}_B_err_pct'].abs().mean():.1f}"]
                      if len(both) else ["-", "-"])
        lines.append("| " + " | ".join(cells) + " |")
    diff = df[~df["identical"]]
    if len(diff):
        lines += ["", "Flights that differ (findings A / B, failures):", ""]
        for _, r in diff.iterrows():
            lines.append(f"- {r['vehicle']} seed {r['seed']}: shift {r['max_shift_sigma']:.2f} sigma; "
                         f"A: {r['A_failed'] or r['A_findings'] or 'no finding'}; "
                         f"B: {r['B_failed'] or r['B_findings'] or 'no finding'}")
    lines += ["", f"Per-run rows: `bench/results/{args.out}_runs.csv`."]
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", action="append", required=True, help="NAME=JSON: an A-run smoothing option")
    ap.add_argument("--vehicles", required=True)
    ap.add_argument("--seeds", default="0-1")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    options = {}
    for item in args.set:
        name, _, value = item.partition("=")
        options[name] = json.loads(value)
    jobs = [(v, s, options) for v in args.vehicles.split(",") for s in parse_seeds(args.seeds)]
    load0, start = loadavg(), time.perf_counter()
    df = pd.DataFrame(run_jobs(one, jobs, args.jobs))
    wall = time.perf_counter() - start
    out = Path(__file__).parent / "results"
    df.to_csv(out / f"{args.out}_runs.csv", index=False)
    (out / f"{args.out}.md").write_text(report(df, args, (load0, loadavg()), wall))
    print((out / f"{args.out}.md").read_text())


if __name__ == "__main__":
    main()
