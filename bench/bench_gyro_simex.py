"""The gyro part of the SIMEX correction (aerosid.identification.eiv, issue 16) on cached flights.

    python bench/bench_gyro_simex.py [--vehicles F4N,OV10,pa28] [--seeds 0-9]
        [--cache-dir /tmp/aerosid-attrib-ab2] [--out gyro_simex]
    -> bench/results/<out>.md and bench/results/<out>_runs.csv

Per (vehicle, seed) the cached flight (bench/attribution_cache.py: the simulated flight, its
preprocessed and smoothed frames) is turned into flight data by the CURRENT code
(aerosid.identification.flight_data.build_flight_data_segments: it carries the gyro noise
eiv_sigma_p/q/r_rad_s) and identified with identify()'s defaults, in these variants:

  off            identify(gyro_eiv=False): the angles' SIMEX only (the code before this change)
  on             identify(gyro_eiv=True): angles' and gyros' noise in the same SIMEX draws in
                 every channel (the default is "auto": only the channels without alpha_dot_hat)
  rates true     p, q, r replaced by the band-limited truth (the same low-pass and runs the
                 flight data went through), gyro_eiv=False: what a perfect gyro correction
                 would give on top of the angles' SIMEX
  angles true    alpha, beta replaced by the band-limited truth (eiv_sigma_alpha/beta = 0),
    off / on     without / with the gyro SIMEX: the gyro part alone, with no angle error left
  angles+rates   both true, no SIMEX: what "angles true, on" aims at
    true

Errors are % of the linear truth; coverage = share of runs whose 1.96 sigma interval holds the
truth; damping = C_m_q + C_m_alpha_dot (sigma of the sum from the fit's covariance).
"""
from __future__ import annotations

import argparse
import math
import platform
import sys
import time
import warnings
from datetime import date
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
import attribution_cache  # noqa: E402
from bench_accuracy import parse_seeds  # noqa: E402
from bench_attribution import band_limited_truth  # noqa: E402
from bench_generalisation import estimate_of, truth_of  # noqa: E402

NAMES = ("Cm_alpha", "Cm_delta", "damping", "CN_alpha", "Cl_p", "Cn_beta", "Cn_r")
VARIANTS = ("off", "on", "rates true", "angles true, off", "angles true, on", "angles+rates true")


def variants(data: dict) -> dict[str, tuple[pd.DataFrame, bool]]:
    """Variant name -> (flight data, gyro_eiv)."""
    from aerosid.identification.flight_data import build_flight_data_segments, load_database
    from aerosid.identification.inversion import total_angles

    veh = data["vehicle_obj"]
    fd = build_flight_data_segments(data["preprocessed"], data["smoothed"], veh, load_database(veh), "flight")
    T = data["truth"]
    lp = band_limited_truth({**data, "flight_data": fd},
                            {k: T[c] for k, c in (("alpha", "alpha_rad"), ("beta", "beta_rad"), ("p", "p_rad_s"),
                                                  ("q", "q_rad_s"), ("r", "r_rad_s"))})

    def rates_true(f: pd.DataFrame) -> pd.DataFrame:
        f = f.copy()
        f["p_rad_s"], f["q_rad_s"], f["r_rad_s"] = lp["p"], lp["q"], lp["r"]
        return f

    def angles_true(f: pd.DataFrame) -> pd.DataFrame:
        f = f.copy()
        f["alpha_rad"], f["beta_rad"] = lp["alpha"], lp["beta"]
        f["alpha_r_rad"], f["phi_r_rad"] = total_angles(lp["alpha"], lp["beta"])
        f["eiv_sigma_alpha_rad"] = f["eiv_sigma_beta_rad"] = 0.0
        return f

    return {"off": (fd, False), "on": (fd, True), "rates true": (rates_true(fd), False),
            "angles true, off": (angles_true(fd), False), "angles true, on": (angles_true(fd), True),
            "angles+rates true": (rates_true(angles_true(fd)), False)}


def run(vehicles: list[str], seeds: list[int], cache_dir: Path) -> pd.DataFrame:
    from aerosid.identification.identify import identify

    rows = []
    for v in vehicles:
        for s in seeds:
            data = attribution_cache.load(v, s, cache_dir)
            flight = SimpleNamespace(coefficients=data["coefficients"])
            t_run = time.perf_counter()
            for name, (fd, gyro) in variants(data).items():
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    ident = identify(fd, data["vehicle_obj"], gyro_eiv=gyro, bias_pairs=0,
                                     control_eiv=False)  # as recorded (before the controls' part)
                row = {"vehicle": v, "seed": s, "variant": name, "identify_s": time.perf_counter() - t0}
                for c in NAMES:
                    truth = truth_of(flight, c)
                    est, se = estimate_of(ident, c)
                    row[f"{c}_err_pct"] = 100 * (est / truth - 1)
                    row[f"{c}_sigma_pct"] = 100 * abs(se / truth)
                    row[f"{c}_cover"] = bool(abs(est - truth) <= 1.96 * se)
                rows.append(row)
            print(f"{v} seed {s}: {time.perf_counter() - t_run:.0f} s", flush=True)
    return pd.DataFrame(rows)


def report(df: pd.DataFrame, seeds: list[int], cache_dir: Path) -> str:
    lines = [f"# The gyro part of SIMEX on cached flights ({len(seeds)} seeds per vehicle)", "",
             f"{date.today()}, Python {platform.python_version()}; flights {cache_dir} (bench/attribution_cache.py), "
             "flight data rebuilt by the current code; bench/bench_gyro_simex.py (docstring: the variants).  "
             "Cells: mean error % / RMS error % / 95 % coverage over the seeds.", ""]
    for v, g in df.groupby("vehicle", sort=False):
        lines += [f"## {v}", "", "| variant | " + " | ".join(NAMES) + " | identify s |",
                  "|---|" + "---|" * (len(NAMES) + 1)]
        for name, h in g.groupby("variant", sort=False):
            cells = []
            for c in NAMES:
                e = h[f"{c}_err_pct"].dropna()
                cells.append(f"{e.mean():+.1f} / {np.sqrt((e ** 2).mean()):.1f} / {h[f'{c}_cover'].mean():.0%}"
                             if len(e) else "-")
            lines.append(f"| {name} | " + " | ".join(cells) + f" | {h['identify_s'].mean():.1f} |")
        lines.append("")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", default="F4N,OV10,pa28")
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--cache-dir", default="/tmp/aerosid-attrib-ab2")
    ap.add_argument("--out", default="gyro_simex")
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    t0 = time.perf_counter()
    df = run(args.vehicles.split(","), seeds, Path(args.cache_dir))
    out = Path(__file__).parent / "results"
    df.to_csv(out / f"{args.out}_runs.csv", index=False, float_format="%.5g")
    text = report(df, seeds, Path(args.cache_dir)) + f"\nwall {time.perf_counter() - t0:.0f} s\n"
    (out / f"{args.out}.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
