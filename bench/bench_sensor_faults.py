"""Sensor faults on aircraft the findings were not tuned on (issue 16, "failures announce
themselves, and cost only what they touch").

    python bench/bench_sensor_faults.py [--vehicles c172x,pa28,J3Cub,c182] [--seeds 0-1] [--jobs 2]
        [--out sensor_faults] [--decimate K]
    -> bench/results/<out>.md and bench/results/<out>_runs.csv

The findings' own tests inject faults into seed-rlv's flight.  Here each flight of the
generalisation bench (bench_generalisation.simulate: the vehicle file as a user has it, every
setting at its default) is run clean and then once per fault, each fault a bias jump of one
sensor for FAULT_S seconds centred on the pitch manoeuvre's largest pitch rate (the moment a
cut costs most):

* ``az``: +AZ_JUMP_M_S2 on the normal accelerometer (with vanes it feeds only C_N);
* ``ax``: +AX_JUMP_M_S2 on the axial accelerometer (feeds only C_A, which no default model fits);
* ``q``: +Q_JUMP_RAD_S on the pitch gyro (feeds every channel).

Per faulted run: *announced* -- a finding on the faulted sensor (gated, a departure of the
matching smoothed signal, or a kinematic_mismatch, whose channel ``q/az/alpha`` names it)
overlapping the fault or within 0.5 s of it; *status* -- the run has findings (it does not
print "ok"); *rows lost* -- flight-data rows against the clean run's; and per coefficient the
shift from the clean run's estimate in the clean run's sigma.  A *silent* faulted run: nothing
announced on that sensor and some barred coefficient moved by more than SILENT_SHIFT clean sigma.
--decimate K: the flights logged at 100/K Hz (every K-th sample), the faults injected after.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
from bench_accuracy import parse_seeds  # noqa: E402
from bench_generalisation import BARRED, COEFFICIENTS, decimated, estimate_of, simulate, truth_of  # noqa: E402
from machine import loadavg, run_jobs, run_line  # noqa: E402

FAULT_S = 1.5
AZ_JUMP_M_S2 = 2.0
AX_JUMP_M_S2 = 1.0
Q_JUMP_RAD_S = 0.03
FAULTS = {"az": ("az_m_s2", AZ_JUMP_M_S2, ("Z1_m_s2",)), "ax": ("ax_m_s2", AX_JUMP_M_S2, ("X1_m_s2",)),
          "q": ("q_rad_s", Q_JUMP_RAD_S, ("q_rad_s",))}
SILENT_SHIFT = 2.0
DEFAULT_VEHICLES = "c172x,pa28,J3Cub,c182"


def fault_span(telemetry: pd.DataFrame) -> tuple[float, float]:
    """FAULT_S seconds centred on the largest |q - median q| (q through a 9-sample running median
    first, so a single noisy sample cannot place it)."""
    t = telemetry["t_s"].to_numpy(float)
    q = pd.Series(telemetry["q_rad_s"].to_numpy(float)).rolling(9, center=True, min_periods=1).median().to_numpy()
    k = int(np.nanargmax(np.abs(q - np.nanmedian(q))))
    return float(t[k] - FAULT_S / 2), float(t[k] + FAULT_S / 2)


def _estimates(run) -> dict:
    return {name: estimate_of(run.identification, name) for name in COEFFICIENTS}


def _run(telemetry, vehicle):
    from aerosid.ebm import process_telemetry

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return process_telemetry(telemetry, vehicle)


def one(job: tuple) -> list[dict]:
    vehicle_name, seed, faults, factor = job
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        flight, vehicle = simulate(vehicle_name, seed, Path(tmp))
    if factor > 1:  # logged at 1/factor of the rate (bench_generalisation.decimated), faulted after
        flight = dataclasses.replace(flight, telemetry=decimated(flight.telemetry, factor))
    clean = _run(flight.telemetry, vehicle)
    base = _estimates(clean)
    t0, t1 = fault_span(flight.telemetry)
    n_clean = len(clean.flight_data)
    clean_found = "; ".join(f"{f['kind']} {f['channel']} {f['t0_s']:.1f}-{f['t1_s']:.1f} s" for f in clean.findings)
    for fault in faults:
        column, jump, smoothed_cols = FAULTS[fault]
        tel = flight.telemetry.copy()
        t = tel["t_s"].to_numpy(float)
        tel.loc[(t >= t0) & (t <= t1), column] += jump
        row = {"vehicle": vehicle_name, "seed": seed, "fault": fault, "t0_s": t0, "t1_s": t1,
               "air_data": vehicle.air_data_source, "clean_findings": clean_found}
        start = time.perf_counter()
        try:
            run = _run(tel, vehicle)
        except Exception as exc:  # announced: the run refused
            row.update(failed=f"{type(exc).__name__}: {exc}", announced=True, status_findings=True)
            rows.append(row)
            continue
        row["time_s"] = time.perf_counter() - start
        found = list(run.findings)
        on_sensor = [f for f in found if (f["channel"] == fault or f["channel"] in smoothed_cols
                                          or fault in f["channel"].split("/"))
                     and f["t1_s"] >= t0 - 0.5 and f["t0_s"] <= t1 + 0.5]
        row["announced"] = bool(on_sensor)
        row["announced_as"] = "; ".join(f"{f['kind']} {f['channel']} {f['t0_s']:.1f}-{f['t1_s']:.1f} s "
                                        f"({'cut' if f['cut'] else 'kept'})" for f in on_sensor)
        row["status_findings"] = bool(found)
        row["rows_lost"] = n_clean - len(run.flight_data)
        shifts = []
        for name, (est, se) in _estimates(run).items():
            b_est, b_se = base[name]
            truth = truth_of(flight, name)
            row[f"{name}_clean"], row[f"{name}_est"] = b_est, est
            if math.isfinite(est) and math.isfinite(b_est) and b_se > 0:
                row[f"{name}_shift_sigma"] = (est - b_est) / b_se
                if name in BARRED:
                    shifts.append(abs(row[f"{name}_shift_sigma"]))
            if math.isfinite(truth) and truth != 0 and math.isfinite(est):
                row[f"{name}_err_pct"] = 100.0 * (est / truth - 1.0)
                row[f"{name}_clean_err_pct"] = 100.0 * (b_est / truth - 1.0)
        row["max_shift_sigma"] = max(shifts) if shifts else math.nan
        row["silent"] = (not row["announced"]) and row["max_shift_sigma"] > SILENT_SHIFT
        rows.append(row)
    return rows


def report(df: pd.DataFrame, args, load, wall_s: float) -> str:
    lines = [f"# Sensor faults on the generalisation bench's aircraft ({args.out})", "",
             run_line(load, args.jobs, wall_s) + ".", "",
             f"`python bench/bench_sensor_faults.py --vehicles {args.vehicles} --seeds {args.seeds} "
             f"--faults {args.faults} --jobs {args.jobs} --out {args.out}"
             + (f" --decimate {args.decimate}" if args.decimate > 1 else "") + "`", "",
             f"Definitions: bench/bench_sensor_faults.py (docstring). Faults: a bias jump for {FAULT_S:g} s centred on "
             f"the largest pitch rate: a_z +{AZ_JUMP_M_S2:g} m/s^2, a_x +{AX_JUMP_M_S2:g} m/s^2, q "
             f"+{Q_JUMP_RAD_S:g} rad/s. Shift: (faulted - clean estimate) / clean sigma.", "",
             "| vehicle | air data | fault | runs | announced on the sensor | with findings | silent | rows lost "
             "(median) | largest barred shift [sigma] (median, max) | coefficient moved most (max) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for (veh, fault), g in df.groupby(["vehicle", "fault"], sort=False):
        shift_cols = [f"{n}_shift_sigma" for n in BARRED if f"{n}_shift_sigma" in g]
        worst = g[shift_cols].abs().max().idxmax().removesuffix("_shift_sigma") if shift_cols else "-"
        lines.append(f"| {veh} | {g['air_data'].iloc[0]} | {fault} | {len(g)} | {int(g['announced'].sum())} | "
                     f"{int(g['status_findings'].sum())} | {int(g.get('silent', pd.Series(False)).sum())} | "
                     f"{g['rows_lost'].median():.0f} | {g['max_shift_sigma'].median():.2f}, "
                     f"{g['max_shift_sigma'].max():.2f} | {worst} |")
    lines += ["", "Per-run rows (estimates, shifts, findings on the sensor): "
              f"`bench/results/{args.out}_runs.csv`."]
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", default=DEFAULT_VEHICLES)
    ap.add_argument("--seeds", default="0-1")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--faults", default=",".join(FAULTS), help=f"comma-separated of {', '.join(FAULTS)}")
    ap.add_argument("--out", default="sensor_faults")
    ap.add_argument("--decimate", type=int, default=1, help="log every K-th sample (100 Hz / K)")
    args = ap.parse_args()
    faults = tuple(args.faults.split(","))
    unknown = [f for f in faults if f not in FAULTS]
    if unknown:
        ap.error(f"--faults: unknown {unknown}; choose from {', '.join(FAULTS)}")
    jobs = [(v, s, faults, args.decimate) for v in args.vehicles.split(",") for s in parse_seeds(args.seeds)]
    load0, start = loadavg(), time.perf_counter()
    results = run_jobs(one, jobs, args.jobs)
    df = pd.DataFrame([r for rows in results for r in rows])
    out = Path(__file__).parent / "results"
    df.to_csv(out / f"{args.out}_runs.csv", index=False)
    (out / f"{args.out}.md").write_text(report(df, args, (load0, loadavg()), time.perf_counter() - start))
    print((out / f"{args.out}.md").read_text())


if __name__ == "__main__":
    main()
