"""Monte-Carlo error of the SIMEX correction (aerosid.identification.eiv): how much the corrected
estimates depend on the seed of SIMEX's own draws, for three ways of drawing them.

    python bench/bench_simex_mc.py [--vehicles F4N,OV10,pa28,seed-rlv,T37,c172x] [--seeds 0-2] [--jobs 2]
    -> bench/results/simex_mc.md and bench/results/simex_mc_runs.csv

  seq   the scheme before 2026-11-28: the angles' draws fresh at every lambda from one
        generator; the rates' draws common random numbers (replicate b, scaled by sqrt(lambda))
  crn   common random numbers for the angles too (replicate b's draw at every lambda)
  anti  what identify does (eiv.simex_frames): common random numbers in antithetic pairs,
        pair k adds +sqrt(lambda) and -sqrt(lambda) times one draw

Each (vehicle, seed) flight is simulated and estimated once (bench/attribution_cache.py, cached
under /tmp/aerosid-attrib), then identified (identify(bias_pairs=0): SIMEX alone) with each
scheme and three seeds of the draws (eiv.SEED, 11, 12).  MC-sd: the spread (1 sd, in % of the
truth) of a flight's estimate over the three draw seeds, averaged over the flights; mean / RMS /
sigma / coverage over every (flight, draw seed).  Coefficients and truth as
bench/bench_generalisation.py."""
from __future__ import annotations

import argparse
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
from bench_generalisation import COEFFICIENTS, estimate_of, truth_of  # noqa: E402

MODES = ("seq", "crn", "anti")
MASTERS_EXTRA = (11, 12)
RESULTS = Path(__file__).parent / "results"


def legacy_simex(mode: str, master: int):
    """identify's simex_estimates with the draws of `mode` (seq or crn) seeded by `master`."""
    import aerosid.identification.eiv as eiv

    def simex(fd, y_by_channel, design, sigma_rad, cutoff_hz, rate_sigma=None, rate_cutoff_hz=None,
              lambdas=eiv.LAMBDAS, control_sigma=None, control_cutoff_hz=None):
        if control_sigma is not None:
            raise ValueError("the legacy schemes have no controls' part: identify(control_eiv=False)")
        rng = np.random.default_rng(master)
        groups = eiv.segment_keys(fd)
        t = fd["t_s"].to_numpy(float)

        def fit_all(frame):
            X = design(frame)
            return {ch: np.linalg.lstsq(X[ch], y, rcond=None)[0] for ch, y in y_by_channel.items()}

        naive = fit_all(fd)
        curves = {ch: [b] for ch, b in naive.items()}
        angles, rates = {}, {}
        for lam in lambdas:
            acc = {ch: np.zeros_like(b) for ch, b in naive.items()}
            for b in range(eiv.REPLICATES):
                f = fd
                if sigma_rad is not None:
                    if mode == "seq":
                        scaled = (tuple(np.asarray(x) * np.sqrt(lam) for x in sigma_rad)
                                  if isinstance(sigma_rad, tuple) else sigma_rad * np.sqrt(lam))
                        f = eiv.with_angle_noise(f, rng, groups, scaled, cutoff_hz)
                    else:
                        if b not in angles:
                            angles[b] = eiv.angle_noise(np.random.default_rng([master, b]), groups, t, sigma_rad,
                                                        cutoff_hz)
                        f = eiv.with_angles_moved(f, np.sqrt(lam) * angles[b][0], np.sqrt(lam) * angles[b][1])
                if rate_sigma is not None:
                    if b not in rates:
                        rates[b] = eiv.column_noise(np.random.default_rng([master + 1, b]), groups, t, rate_sigma,
                                                    rate_cutoff_hz)
                    f = eiv.with_column_noise(f, np.sqrt(lam) * rates[b], copy=f is fd)
                for ch, est in fit_all(f).items():
                    acc[ch] += est / eiv.REPLICATES
            for ch in curves:
                curves[ch].append(acc[ch])
        lams = np.array((0.0, *lambdas))
        return {ch: eiv.SimexResult.from_curve(lams, np.array(rows)) for ch, rows in curves.items()}
    return simex


def shipped_simex(master: int):
    """identify's own simex_estimates (antithetic common random numbers) with the draws seeded by `master`."""
    import aerosid.identification.eiv as eiv

    def simex(*args, **kwargs):
        return eiv.simex_estimates(*args, **kwargs, seed=master)
    return simex


def one(job: tuple[str, int]) -> list[dict]:
    """The rows of one cached flight: every scheme with every draw seed."""
    import aerosid.identification.eiv as eiv
    import aerosid.identification.eiv_fit as eiv_fit
    import aerosid.identification.identify as idm

    v, s = job
    data = attribution_cache.load(v, s)
    veh, fd = data["vehicle_obj"], data["flight_data"]
    flight = SimpleNamespace(coefficients=data["coefficients"])
    original = eiv_fit.simex_estimates
    rows = []
    try:
        for mode in MODES:
            for master in (eiv.SEED, *MASTERS_EXTRA):
                eiv_fit.simex_estimates = shipped_simex(master) if mode == "anti" else legacy_simex(mode, master)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    ident = idm.identify(fd, veh, bias_pairs=0, control_eiv=False)  # the angles' (and rates') draws
                row = {"vehicle": v, "seed": s, "mode": mode, "master": master}
                for c in COEFFICIENTS:
                    tr = truth_of(flight, c)
                    est, se = estimate_of(ident, c)
                    row[c] = 100 * (est / tr - 1)
                    row[c + "_sig"] = 100 * abs(se / tr)
                    row[c + "_cov"] = bool(abs(est - tr) <= 1.96 * se)
                rows.append(row)
    finally:
        eiv_fit.simex_estimates = original
    print(v, s, flush=True)
    return rows


def run(vehicles: list[str], seeds: list[int], jobs: int = 1) -> pd.DataFrame:
    todo = [(v, s) for v in vehicles for s in seeds]
    for job in todo:  # build the missing caches first, one at a time
        if not attribution_cache.cache_path(*job).exists():
            attribution_cache.build(*job)
    if jobs > 1:
        from multiprocessing import Pool

        with Pool(jobs) as pool:
            parts = pool.map(one, todo)
    else:
        parts = [one(job) for job in todo]
    return pd.DataFrame([row for part in parts for row in part])


def report(df: pd.DataFrame, seeds: list[int], wall_s: float) -> str:
    out = ["# Monte-Carlo error of the SIMEX correction: three ways of drawing its noise", "",
           f"{date.today().isoformat()}, Python {platform.python_version()}, {platform.processor() or platform.machine()}; "
           f"seeds {seeds[0]}..{seeds[-1]} per vehicle; wall {wall_s / 60:.1f} min.  "
           "`python bench/bench_simex_mc.py` (docstring: the schemes and the columns).", "",
           "Per coefficient: mean / RMS error % of the truth, mean sigma %, 95 % coverage, and MC-sd: how much a "
           "flight's estimate moves with the seed of SIMEX's draws (1 sd over 3 draw seeds, %, averaged).", ""]
    for v, gv in df.groupby("vehicle", sort=False):
        out += [f"## {v}", "", "| coefficient | " + " | ".join(f"{m}: mean / RMS / sigma / cov / MC-sd" for m in MODES) + " |",
                "|---|" + "---|" * len(MODES)]
        for c in COEFFICIENTS:
            if gv[c].isna().all():
                continue
            cells = []
            for m in MODES:
                g = gv[gv["mode"] == m]
                mc = g.groupby("seed")[c].std().mean()
                cells.append(f"{g[c].mean():+.1f} / {np.sqrt((g[c] ** 2).mean()):.1f} / {g[c + '_sig'].mean():.1f} / "
                             f"{g[c + '_cov'].mean():.0%} / **{mc:.2f}**")
            out.append(f"| {c} | " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", default="F4N,OV10,pa28,seed-rlv,T37,c172x")
    ap.add_argument("--seeds", default="0-2")
    ap.add_argument("--out", default="simex_mc")
    ap.add_argument("--jobs", type=int, default=1)
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    t0 = time.perf_counter()
    df = run(args.vehicles.split(","), seeds, args.jobs)
    df.to_csv(RESULTS / f"{args.out}_runs.csv", index=False)
    (RESULTS / f"{args.out}.md").write_text(report(df, seeds, time.perf_counter() - t0) + "\n")


if __name__ == "__main__":
    main()
