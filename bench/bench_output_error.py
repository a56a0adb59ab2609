"""Output-error refinement (aerosid refine) against the equation-error estimates, on flights with known truth.

    python bench/bench_output_error.py --vehicles c172x,sgs126 --seeds 0-2 --jobs 2 [--label NAME]
    -> bench/results/output_error[_NAME].md, bench/results/output_error[_NAME]_runs.csv

Each run: the generalisation bench's flight (bench_generalisation.simulate: the same
telemetry, vehicle file and truth), the default pipeline (process_telemetry: the equation-error
estimates, with their reported sigma), then the longitudinal output-error fit
(aerosid.identification.output_error.output_error_fit) started from them on the same flight:
inputs and outputs as ``aerosid refine`` takes them (the fins and, without vanes, the inverted
alpha and beta before the band's low-pass; the other outputs from the preprocessed telemetry),
the telemetry's INS attitude (phi_rad, theta_rad: 0.1 deg of noise; before 2026-11-27 the
simulators wrote none and this bench read the truth's), the identity channels of a vehicle
without vanes (C_N, C_Y) at the preflight database's values as in ``aerosid refine`` (before
2026-11-27: at 0), the rows in the Mach window.  Errors in % of the at-trim truth (bench_generalisation.truth_of); coverage: the truth
inside estimate +- 1.96 sigma.  Not a default and not tuned here: the bench measures it.
"""
from __future__ import annotations

import argparse
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

sys.path.insert(0, str(Path(__file__).parent))
from bench_accuracy import parse_seeds  # noqa: E402
from bench_generalisation import estimate_of, simulate, truth_of  # noqa: E402
from machine import cpu_model, loadavg  # noqa: E402

NAMES = {"Cm_alpha": "Cm_alpha", "Cm_delta": "Cm_delta_p", "damping": None, "CN_alpha": "CN_alpha",
         "CN_delta": "CN_delta_p"}


def one(job: tuple[str, int]) -> dict:
    from aerosid.ebm import process_telemetry
    from aerosid.identification.identified import IdentifiedModel, with_preflight_identities
    from aerosid.identification.identify import mach_window_mask
    from aerosid.identification.output_error import output_error_fit
    from aerosid.identification.output_prediction import prediction_inputs
    from aerosid.identification.validate import attitude_on, measured_outputs, spans_of
    from aerosid.modelling.models import default_models

    vname, seed = job
    row = {"vehicle": vname, "seed": seed, "failed": ""}
    try:
        with tempfile.TemporaryDirectory() as tmp:
            flight, veh = simulate(vname, seed, Path(tmp))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            run = process_telemetry(flight.telemetry, veh)
        fd = run.flight_data.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
        tab = run.identification.table()
        model = IdentifiedModel(default_models(veh), dict(zip(tab["coefficient"], tab["estimate"])), "equation error")
        model, _ = with_preflight_identities(model, veh)
        span = spans_of(fd, mach_window_mask(fd["mach"].to_numpy(), veh.mach_reference, 0.5))
        att = attitude_on(flight.telemetry, fd["t_s"].to_numpy(float), "telemetry")
        inputs = prediction_inputs(fd, veh, att[0], att[1], span, wideband_controls=True)
        meas, _ = measured_outputs(run.preprocessed.frame, fd, veh, wideband=True)
        t0 = time.perf_counter()
        oe = output_error_fit(model, inputs, meas, veh, "lon")
    except Exception as exc:  # recorded, not hidden
        row["failed"] = f"{type(exc).__name__}: {exc}"
        print(vname, seed, "FAILED", row["failed"], flush=True)
        return row
    row.update(oe_s=time.perf_counter() - t0, n=oe.n_samples, converged=oe.converged, nfev=oe.nfev)
    row.update({f"tic_{o}_{w}": getattr(oe, f"tic_{w}")[o] for o in oe.tic_end for w in ("start", "end")})
    for name, key in NAMES.items():
        truth = truth_of(flight, name)
        ee, ee_se = estimate_of(run.identification, name)
        if name == "damping":
            w = {"Cm_q": 1.0, **({"Cm_alpha_dot": 1.0} if "Cm_alpha_dot" in oe.names else {})}
            o, o_se = oe.combination(w) if "Cm_q" in oe.names else (math.nan, math.nan)
        else:
            o, o_se = (oe.estimate[key], oe.sigma[key]) if key in oe.names else (math.nan, math.nan)
        row.update({f"{name}_truth": truth, f"{name}_ee": ee, f"{name}_ee_se": ee_se, f"{name}_oe": o,
                    f"{name}_oe_se": o_se})
        for m, est, se in (("ee", ee, ee_se), ("oe", o, o_se)):
            if math.isfinite(est) and math.isfinite(truth) and truth != 0:
                row[f"{name}_{m}_pct"] = 100 * (est / truth - 1)
                row[f"{name}_{m}_sig_pct"] = 100 * se / abs(truth)
                row[f"{name}_{m}_cover"] = bool(abs(est - truth) <= 1.96 * se)
    print(vname, seed, f"{row['oe_s']:.0f} s", " ".join(
        f"{n} EE {row.get(n + '_ee_pct', math.nan):+.1f} OE {row.get(n + '_oe_pct', math.nan):+.1f}" for n in NAMES),
        flush=True)
    return row


def report(df: pd.DataFrame, cmd: str, load: tuple[str, str], wall_s: float) -> str:
    lines = ["# Output-error refinement against equation error, on flights with known truth", "",
             f"{date.today()}, `{cmd}`, Python {platform.python_version()}, {cpu_model()}, load {load[0]} (start) / "
             f"{load[1]} (end), wall {wall_s / 60:.1f} min.", "",
             "Definitions: bench/bench_output_error.py (docstring). Per vehicle and coefficient: mean / RMS error "
             "[% of the at-trim truth], mean sigma [%], 95 % coverage, for the default pipeline (EE) and the "
             "output-error refinement started from it (OE).", "",
             "| vehicle | runs (failed) | OE time per run [s] | coefficient | EE mean / RMS | EE sigma | EE coverage "
             "| OE mean / RMS | OE sigma | OE coverage |", "|---|---|---|---|---|---|---|---|---|---|"]
    for v, g in df.groupby("vehicle", sort=False):
        ok = g[g["failed"].fillna("") == ""]
        for k, name in enumerate(NAMES):
            cells = []
            for m in ("ee", "oe"):
                e = ok.get(f"{name}_{m}_pct", pd.Series(dtype=float)).dropna()
                s = ok.get(f"{name}_{m}_sig_pct", pd.Series(dtype=float)).dropna()
                c = ok.get(f"{name}_{m}_cover", pd.Series(dtype=float)).dropna()
                cells += [f"{e.mean():+.1f} / {np.sqrt((e ** 2).mean()):.1f}" if len(e) else "-",
                          f"{s.mean():.1f}" if len(s) else "-", f"{100 * c.astype(bool).mean():.0f} %" if len(c) else "-"]
            head = (f"| {v} | {len(g)} ({len(g) - len(ok)}) | {ok['oe_s'].mean():.0f} |" if k == 0
                    else "| | | |")
            lines.append(f"{head} {name} | " + " | ".join(cells) + " |")
    fails = df[df["failed"].fillna("") != ""]
    lines += ["", *(f"- {r.vehicle} seed {r.seed}: {r.failed}" for r in fails.itertuples())]
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--vehicles", default="c172x")
    ap.add_argument("--seeds", default="0-2")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--label", default="")
    args = ap.parse_args()
    jobs = [(v, s) for v in args.vehicles.split(",") for s in parse_seeds(args.seeds)]
    load0, t0 = loadavg(), time.time()
    with ProcessPoolExecutor(args.jobs) as ex:
        rows = list(ex.map(one, jobs))
    df = pd.DataFrame(rows)
    out = Path(__file__).parent / "results" / f"output_error{'_' + args.label if args.label else ''}"
    df.to_csv(f"{out}_runs.csv", index=False)
    cmd = "python bench/bench_output_error.py " + " ".join(sys.argv[1:])
    text = report(df, cmd, (load0, loadavg()), time.time() - t0)
    Path(f"{out}.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
