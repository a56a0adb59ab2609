"""The band order of non-linear terms (aerosid.identification.band_order), before and after,
on an aircraft nobody here modelled: JSBSim's DHC-6, whose C_l is even in beta.

Each seed: ``aerosid simulate --jsbsim DHC6`` and the estimation chain (cached in --cache), then
with the old order (every column f(LP(x))), the new one without its pre-filter (LP(f(x_wide)),
"unfiltered") and the new one (LP(f(LP_3(x_wide))), the wide-band signal first low-passed at
WIDE_BAND_FACTOR x the band):

* diagnose the default models and take the C_l localisation's first significant suggestion, as a
  user pasting the printed lines would;
* fit the default models plus that term and read C_l,p, C_l,delta_r (the ailerons), the term's
  coefficient and their sigmas against the truth (truth.json: JSBSim's own tables at the trim);
* re-diagnose with the term in and record the C_l localisation's significant findings (an
  ``abs(r_hat)`` there was the old order's artefact).

    python bench/bench_band_order.py --seeds 0-4 --jobs 2
    -> bench/results/band_order_runs.csv and bench/results/band_order.md
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from datetime import date
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from machine import cpu_model, loadavg  # noqa: E402

AIRCRAFT = "DHC6"
COEFS = ("Cl_p", "Cl_delta_r", "Cl_beta", "Cl_r")


def _run(seed: int, cache: Path) -> Path:
    out = cache / f"{AIRCRAFT}_s{seed}"
    if not (out / "run" / "flight_data.parquet").exists():
        exe = Path(sys.executable).parent / "aerosid"
        subprocess.run([str(exe), "simulate", "--jsbsim", AIRCRAFT, "--seed", str(seed), "--out", str(out)],
                       check=True, capture_output=True)
        subprocess.run([str(exe), "run", str(out / "telemetry.parquet"), "--vehicle", str(out / "vehicle.toml"),
                        "--out", str(out / "run")], check=True, capture_output=True)
    return out


def one(job: tuple) -> list[dict]:
    import aerosid.identification.band_order as band_order
    from aerosid.diagnosis import diagnose
    from aerosid.identification.identify import identify
    from aerosid.modelling.models import default_models, parse_term
    from aerosid.vehicles.vehicle import load_vehicle

    seed, cache = job
    out = _run(seed, Path(cache))
    truth = json.loads((out / "truth.json").read_text())["coefficients"]
    vehicle = load_vehicle(out / "vehicle.toml")
    fd = pd.read_parquet(out / "run" / "flight_data.parquet").sort_values(["flight", "t_s"]).reset_index(drop=True)
    rows = []
    for order, enabled, factor in (("old", False, band_order.WIDE_BAND_FACTOR), ("unfiltered", True, None),
                                   ("new", True, band_order.WIDE_BAND_FACTOR)):
        t0 = time.perf_counter()
        band_order.ENABLED, band_order.WIDE_BAND_FACTOR = enabled, factor
        d = diagnose(fd, vehicle)
        sig = [f for f in d.localisation.get("Cl", ()) if f.significant]
        row = {"seed": seed, "order": order, "suggested": sig[0].suggested_expression if sig else ""}
        models = dict(default_models(vehicle))
        if sig:
            models["Cl"] = models["Cl"].with_term(parse_term(f"{sig[0].suggested_coefficient} = "
                                                             f"{sig[0].suggested_expression}", "Cl"))
        fit = identify(fd, vehicle, models).fits["Cl"]
        est, se = dict(zip(fit.names, fit.estimate)), dict(zip(fit.names, fit.std_error))
        row["r2"] = fit.r2
        for c in COEFS:
            row[c], row[f"{c}_sigma"], row[f"{c}_truth"] = est[c], se[c], truth[c]
        if sig:
            row["term"], row["term_sigma"] = est[sig[0].suggested_coefficient], se[sig[0].suggested_coefficient]
            d2 = diagnose(fd, vehicle, models)
            row["after"] = "; ".join(f.suggested_expression for f in d2.localisation.get("Cl", ()) if f.significant)
        row["seconds"] = time.perf_counter() - t0
        rows.append(row)
    return rows


def _report(df: pd.DataFrame, wall_s: float, seeds: list[int]) -> str:
    lines = [f"# The band order of non-linear terms, before and after: JSBSim {AIRCRAFT}, seeds "
             f"{seeds[0]}-{seeds[-1]}", "",
             f"{date.today().isoformat()}, {cpu_model()}, load {loadavg()}; wall {wall_s / 60:.1f} min. "
             f"`python bench/bench_band_order.py --seeds {seeds[0]}-{seeds[-1]}`.", "",
             "Per seed: the default models plus the C_l localisation's first significant suggestion (as a user "
             "would paste it), fitted with the old order (f(LP(x))), the new one without its pre-filter "
             "(unfiltered: LP(f(x_wide))) and the new one (LP(f(LP_3(x_wide))), WIDE_BAND_FACTOR = 3). Error = "
             "estimate - truth (JSBSim's tables at the trim, truth.json), in % and in the estimate's sigma.", "",
             "| seed | order | suggested | R^2 | C_l,p (err %, sigma) | C_l,delta_a (err %, sigma) | term | "
             "C_l findings after adding it |", "|---|---|---|---|---|---|---|---|"]
    for _, r in df.iterrows():
        def cell(c):
            e = r[c] - r[f"{c}_truth"]
            return f"{r[c]:.3f} ({100 * e / abs(r[f'{c}_truth']):+.0f} %, {e / r[f'{c}_sigma']:+.1f} sigma)"
        term = f"{r['term']:.3f} +- {r['term_sigma']:.3f}" if isinstance(r.get("suggested"), str) and r["suggested"] \
            else "-"
        lines.append(f"| {r['seed']} | {r['order']} | `{r['suggested']}` | {r['r2']:.3f} | {cell('Cl_p')} | "
                     f"{cell('Cl_delta_r')} | {term} | {r.get('after') if isinstance(r.get('after'), str) else ''} |")
    lines += ["", "| order | C_l,p mean error | C_l,p RMS error | within 2 sigma | C_l,delta_a mean error |",
              "|---|---|---|---|---|"]
    for order, g in df.groupby("order", sort=False):
        e = (g["Cl_p"] - g["Cl_p_truth"]) / g["Cl_p_truth"].abs()
        z = (g["Cl_p"] - g["Cl_p_truth"]) / g["Cl_p_sigma"]
        ea = (g["Cl_delta_r"] - g["Cl_delta_r_truth"]) / g["Cl_delta_r_truth"].abs()
        lines.append(f"| {order} | {100 * e.mean():+.1f} % | {100 * np.sqrt((e ** 2).mean()):.1f} % | "
                     f"{int((z.abs() <= 2).sum())}/{len(g)} | {100 * ea.mean():+.1f} % |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-4")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--cache", default="/tmp/aerosid_bench_band_order")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    a = ap.parse_args()
    lo, _, hi = a.seeds.partition("-")
    seeds = list(range(int(lo), int(hi or lo) + 1))
    Path(a.cache).mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with ProcessPoolExecutor(a.jobs) as ex:
        rows = [r for rs in ex.map(one, [(s, a.cache) for s in seeds]) for r in rs]
    df = pd.DataFrame(rows)
    out = Path(a.out)
    df.to_csv(out / "band_order_runs.csv", index=False)
    (out / "band_order.md").write_text(_report(df, time.perf_counter() - t0, seeds))
    print((out / "band_order.md").read_text())


if __name__ == "__main__":
    main()
