"""The vanes' delay behind the IMU (aerosid.identification.vanes) on flights with known truth.

    python bench/bench_airdata_timing.py --vehicles pa28,OV10,T37,F4N,c172p --seeds 0-3 --jobs 2

Per (vehicle, seed), three runs of the default pipeline (``process_telemetry``):

* ``as flown``: the JSBSim telemetry as simulated (vanes = the true alpha, beta + bias + noise):
  the estimate on a flight whose vanes have no delay, and whether it is (falsely) reported;
* ``delayed``: the same telemetry with both vanes read DELAY_S later (linear interpolation), no
  correction: the estimate (truth: its ``as flown`` value + DELAY_S) and the coefficients' errors;
* ``corrected``: the delayed telemetry with the vehicle file's ``[air_data] delay_s`` set to the
  ``delayed`` run's estimate (what the finding tells the engineer to do).

Errors in % of the at-trim truth (bench/bench_generalisation.py's definitions and coefficients).
Writes bench/results/airdata_timing.md and airdata_timing_runs.csv (with --label L:
airdata_timing_L.md, airdata_timing_L_runs.csv).
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import platform
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
from bench_accuracy import parse_seeds  # noqa: E402
from bench_generalisation import estimate_of, simulate, truth_of  # noqa: E402
from machine import cpu_model, loadavg  # noqa: E402

DELAY_S = 0.025
COEFS = ("Cm_alpha", "Cm_delta", "damping", "CN_alpha", "CN_delta")
RESULTS = ROOT / "bench" / "results"


def delayed(telemetry: pd.DataFrame, vehicle, delay_s: float) -> pd.DataFrame:
    """The vanes read delay_s later: x_new(t) = x(t - delay_s)."""
    from aerosid.identification.vanes import advance

    out = telemetry.copy()
    t = out["t_s"].to_numpy(float)
    for c in (vehicle.alpha_column, vehicle.beta_column):
        out[c] = advance(t, out[c].to_numpy(float), -delay_s)
    return out


def run_arm(flight, telemetry, vehicle, arm: str) -> dict:
    import aerosid.identification.flight_data as fdmod
    from aerosid.ebm import process_telemetry

    seen = []
    original = fdmod.vane_delay

    def spy(*a, **k):
        vd = original(*a, **k)
        seen.append(vd)
        return vd

    fdmod.vane_delay = spy
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            run = process_telemetry(telemetry, vehicle)
    finally:
        fdmod.vane_delay = original
    row = {"arm": arm, "applied_s": vehicle.vane_delay_s}
    vds = [v for v in seen if v is not None]
    if vds:  # the longest segment's estimate
        vd = max(vds, key=lambda v: v.n)
        row.update(delay_ms=1e3 * vd.delay_s, sigma_ms=1e3 * vd.sigma_s, gain=vd.gain, p=vd.p_value,
                   detected=vd.detected, sample_ms=1e3 * vd.sample_s)
    row["reported"] = any(f["kind"] == "airdata_delay" for f in getattr(run, "findings", []))
    for name in COEFS:
        truth = truth_of(flight, name)
        est, se = estimate_of(run.identification, name)
        if math.isfinite(est) and truth:
            row[f"{name}_err_pct"] = 100.0 * (est / truth - 1.0)
            row[f"{name}_cover"] = bool(abs(est - truth) <= 1.96 * se)
    return row


def one(job) -> list[dict]:
    vehicle_name, seed = job
    base = {"vehicle": vehicle_name, "seed": seed}
    with tempfile.TemporaryDirectory() as tmp:
        try:
            flight, vehicle = simulate(vehicle_name, seed, Path(tmp))
        except Exception as exc:
            return [{**base, "failed": f"simulation: {exc}"}]
    rows = []
    try:
        rows.append({**base, **run_arm(flight, flight.telemetry, vehicle, "as flown")})
        late = delayed(flight.telemetry, vehicle, DELAY_S)
        d = run_arm(flight, late, vehicle, "delayed")
        rows.append({**base, **d})
        fix = d.get("delay_ms", math.nan) / 1e3
        if math.isfinite(fix):
            rows.append({**base, **run_arm(flight, late, dataclasses.replace(vehicle, vane_delay_s=round(fix, 3)),
                                           "corrected")})
    except Exception as exc:
        rows.append({**base, "failed": f"{type(exc).__name__}: {exc}"})
    return rows


def report(df: pd.DataFrame, args, wall_s: float, load) -> str:
    lines = [
        "# The vanes' delay behind the IMU: estimate, report, correction (JSBSim flights with known truth)", "",
        f"{date.today().isoformat()}, `python bench/bench_airdata_timing.py --vehicles {args.vehicles} --seeds "
        f"{args.seeds} --jobs {args.jobs}" + (f" --label {args.label}" if args.label else "") + "`,"
        f" Python {platform.python_version()}, {cpu_model()}, load {load[0]} (start) / "
        f"{load[1]} (end), wall {wall_s / 60:.1f} min.", "",
        f"Definitions: bench/bench_airdata_timing.py (docstring). Added delay {DELAY_S * 1e3:.0f} ms. "
        "*reported*: the run has an `airdata_delay` finding (p < 0.001 and at least one sample interval). "
        "Errors: mean / RMS over the seeds, % of the at-trim truth; coverage of the 95 % interval.", "",
        "| vehicle | runs | as flown: estimate [ms] (mean, range) | reported | delayed: estimate - as flown [ms] (mean, range) | reported |",
        "|---|---|---|---|---|---|"]
    for v, g in df.groupby("vehicle", sort=False):
        a = g[g.arm == "as flown"].set_index("seed")
        d = g[g.arm == "delayed"].set_index("seed")
        diff = (d["delay_ms"] - a["delay_ms"]).dropna()
        lines.append(f"| {v} | {len(a)} | {a.delay_ms.mean():+.1f} ({a.delay_ms.min():+.1f}..{a.delay_ms.max():+.1f}), "
                     f"sigma {a.sigma_ms.mean():.1f} | {int(a.reported.sum())}/{len(a)} | {diff.mean():+.1f} "
                     f"({diff.min():+.1f}..{diff.max():+.1f}) | {int(d.reported.sum())}/{len(d)} |")
    lines += ["", "| vehicle | coefficient | as flown | delayed | corrected | coverage: as flown / delayed / corrected |",
              "|---|---|---|---|---|---|"]
    for v, g in df.groupby("vehicle", sort=False):
        for c in COEFS:
            cells, cov = [], []
            for arm in ("as flown", "delayed", "corrected"):
                e = g.loc[g.arm == arm, f"{c}_err_pct"].dropna() if f"{c}_err_pct" in g else pd.Series(dtype=float)
                cells.append(f"{e.mean():+.1f} / {math.sqrt((e ** 2).mean()):.1f}" if len(e) else "-")
                k = g.loc[g.arm == arm, f"{c}_cover"].dropna() if f"{c}_cover" in g else pd.Series(dtype=float)
                cov.append(f"{100 * k.astype(bool).mean():.0f} %" if len(k) else "-")
            lines.append(f"| {v} | {c} | {' | '.join(cells)} | {' / '.join(cov)} |")
    lines += ["", "Per-run rows: `bench/results/airdata_timing_runs.csv`.", ""]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", default="pa28,OV10,T37,F4N,c172p")
    ap.add_argument("--seeds", default="0-3")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--label", default=None, help="suffix of the result files")
    args = ap.parse_args()
    jobs = [(v, s) for v in args.vehicles.split(",") for s in parse_seeds(args.seeds)]
    load0, t0 = loadavg(), time.perf_counter()
    rows = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for part in pool.map(one, jobs):
            rows.extend(part)
            print(part[-1].get("vehicle"), part[-1].get("seed"), [(r.get("arm"), round(r.get("delay_ms", np.nan), 1))
                                                                   for r in part], flush=True)
    df = pd.DataFrame(rows)
    RESULTS.mkdir(exist_ok=True)
    name = "airdata_timing" + (f"_{args.label}" if args.label else "")
    df.to_csv(RESULTS / f"{name}_runs.csv", index=False)
    (RESULTS / f"{name}.md").write_text(report(df, args, time.perf_counter() - t0, (load0, loadavg()))
                                        .replace("airdata_timing_runs.csv", f"{name}_runs.csv"))
    print((RESULTS / f"{name}.md").read_text())


if __name__ == "__main__":
    main()
