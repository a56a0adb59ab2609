"""Efficiency bench (issue 20): how close the estimates come to the Cramér–Rao bound, and
whether the reported sigma tells their scatter.

    python bench/bench_efficiency.py [--seeds 0-29] [--vehicles seed-rlv,c172x] [--workers 2]
    python bench/bench_efficiency.py --report-only      # the tables again from the CSV
    -> bench/results/efficiency_runs.csv and bench/results/efficiency.md
    python bench/bench_efficiency.py --variant exact-inputs --seeds 0-14   # regressors' noise x0.01
    python bench/bench_efficiency.py --variant exact-inputs-no-faults --seeds 0-9  # and no dropouts/outliers
    python bench/bench_efficiency.py --variant estimator --seeds 0-5       # + the estimator's own std
    -> bench/results/efficiency_<variant>_runs.csv and efficiency_<variant>.md

The variants take the default flights apart: ``exact-inputs`` scales the noise of every
regressor's source by 0.01 (seed-rlv: the accelerometers alpha and beta are inverted from;
c172x: vanes, surfaces, V) and keeps the gyros' (errors in variables removed, except the
rates' own noise where they are regressors); ``exact-inputs-no-faults`` also leaves out the
dropouts, outliers and sync gap (the samples used are then the same in every run, so model
error cannot move the estimates from seed to seed); ``estimator`` adds, per run, the std of the
regression's estimates when only the sensors' white noise at the run's R goes through the
band-limited equation-error estimator with exact regressors (``estimator_noise_std``).

Each run: the flight of bench_generalisation.simulate (seed-rlv: aerosid's simulator with
Table 2 noise; c172x: the JSBSim 3-2-1-1 flight with its shipped vehicle file), then
``aerosid.ebm.process_telemetry`` at default settings; per coefficient the estimate, the
reported (coloured-residual corrected) sigma, the plain OLS sigma and ``crb_std``
(aerosid.identification.crb: output-error information of the gyros and accelerometers
under the run's R, inputs taken as measured).

Per coefficient over the runs:
* efficiency = Monte-Carlo std of the estimates / RMS of the CRB (1 = efficient; the CRB
  changes little between seeds, the RMS is the right mean for a variance bound);
* honesty of sigma = Monte-Carlo std / mean reported sigma (1 = honest, < 1 conservative);
* bias = mean error / Monte-Carlo std (how much of the error the scatter does not explain).
Each ratio of stds carries the sampling error of a std from n runs: a 95 % band
sqrt(chi2(0.025, n-1)/(n-1)) .. sqrt(chi2(0.975, n-1)/(n-1)) (0.80-1.26 for n = 30).
The CSV is written after every run (a stopped bench keeps what it measured).
"""
from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import tempfile
import time
import traceback
import warnings
from concurrent.futures import ProcessPoolExecutor, as_completed
from datetime import date
from pathlib import Path

import numpy as np
import pandas as pd
import scipy.stats

sys.path.insert(0, str(Path(__file__).parent))
from bench_accuracy import parse_seeds  # noqa: E402
from bench_generalisation import simulate  # noqa: E402
from machine import cpu_model, loadavg  # noqa: E402

OUT = Path(__file__).parent / "results"
CSV = OUT / "efficiency_runs.csv"
MD = OUT / "efficiency.md"
#: A coefficient whose Monte-Carlo std exceeds this many CRB is named and explained.
INEFFICIENT = 1.5
TABLES, TABLES_END = "<!-- tables: bench/bench_efficiency.py -->", "<!-- end of tables -->"


#: --variant exact-inputs: the noise of every regressor's source scaled by this factor
EXACT = 0.01


def simulate_variant(vehicle_name: str, seed: int, workdir: Path, variant: str):
    """bench_generalisation.simulate, or with the regressors' noise sources x EXACT
    (variant "exact-inputs"): seed-rlv the accelerometers (alpha, beta are inverted from
    them); c172x the vanes, the surfaces and V (and the vehicle's vane noise for SIMEX).
    The gyros keep their noise: what is left between the scatter and the gyros-only bound is
    the estimator's own (equation error on the band-limited derivative)."""
    if variant in ("default", "estimator"):
        return simulate(vehicle_name, seed, workdir)
    if variant not in ("exact-inputs", "exact-inputs-no-faults"):
        raise ValueError(f"unknown variant {variant!r}")
    from dataclasses import replace

    faults = variant == "exact-inputs"
    if vehicle_name == "seed-rlv":
        from aerosid.simulation import load_case, simulate as sim

        case = load_case("seed-rlv")
        sens = replace(case.sensors, accel_noise_m_s2=tuple(EXACT * v for v in case.sensors.accel_noise_m_s2))
        case = replace(case, sensors=sens, **({} if faults else {"faults": case.faults.without_faults()}))
        return sim(case, seed=seed), case.vehicle
    if vehicle_name != "c172x":
        raise ValueError("the exact-inputs variant is defined for seed-rlv and c172x")
    import copy

    import aerosid.simulation.jsbsim_flight as jf
    from aerosid.vehicles.vehicle import load_vehicle

    original = jf.load_jsbsim_config

    def quiet(aircraft="c172x"):
        sim_cfg, veh_cfg = original(aircraft)
        sim_cfg = copy.deepcopy(sim_cfg)
        for key in ("vane_noise_deg", "surface_noise_deg", "V_noise_m_s"):
            sim_cfg["sensors"][key] *= EXACT
        return sim_cfg, veh_cfg

    jf.load_jsbsim_config = quiet
    try:
        flight = jf.simulate_jsbsim("c172x", "3211", seed, faults=faults)
    finally:
        jf.load_jsbsim_config = original
    vehicle = load_vehicle("c172x")
    return flight, replace(vehicle, vane_noise_rad=EXACT * vehicle.vane_noise_rad)


def gyro_bounds(run, vehicle) -> dict:
    """crb_std from the gyros alone (the accelerometers' lever-arm information left out)."""
    from aerosid.identification.crb import identification_bounds
    from aerosid.identification.identify import mach_window_mask

    ident = run.identification
    fd = run.flight_data.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    fd = fd.loc[mach_window_mask(fd["mach"].to_numpy(), vehicle.mach_reference, 0.5)].reset_index(drop=True)
    return identification_bounds(fd, vehicle, ident.models, ident.fits, ident.identities, ("p", "q", "r")).std


def estimator_noise_std(run, vehicle, replicates: int = 200, seed: int = 0) -> dict:
    """Std of the regression's estimates when only the gyros' and accelerometers' white noise
    (at the run's R) goes through the estimator: every regressor exact, the noise low-passed
    and differentiated as aerosid.identification.band does (linear part: B^-1 w_dot for the
    moments, a - w_dot x r for the forces), scaled to coefficients and fitted by OLS on the
    run's own design matrices.  The equation-error estimator's own loss against the bound."""
    from aerosid.identification.band import low_pass_runs
    from aerosid.identification.crb import R_COLUMNS, rate_coupling_matrix, runs_of
    from aerosid.identification.identify import mach_window_mask
    from aerosid.modelling.models import vehicle_signals

    ident = run.identification
    fd = run.flight_data.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    fd = fd.loc[mach_window_mask(fd["mach"].to_numpy(), vehicle.mach_reference, 0.5)].reset_index(drop=True)
    t = fd["t_s"].to_numpy(float)
    runs = runs_of(t, (fd["flight"].astype(str) + "/" + fd["segment"].astype(str)).to_numpy())
    fs = 1.0 / float(np.median(np.diff(t)))
    band = float(fd["band_hz"].median())
    sigma = fd[list(R_COLUMNS)].to_numpy(float)
    qs = fd["qbar_pa"].to_numpy(float) * vehicle.S_m2
    Binv = np.linalg.inv(rate_coupling_matrix((vehicle.Ixx_kg_m2, vehicle.Iyy_kg_m2, vehicle.Izz_kg_m2,
                                               vehicle.Ixz_kg_m2)))
    scale = {"CN": -vehicle.mass_kg / qs, "CY": vehicle.mass_kg / qs,
             "Cl": vehicle.Ixx_kg_m2 / (qs * vehicle.length_lateral_m), "Cm": vehicle.Iyy_kg_m2 / (qs * vehicle.length_pitch_m),
             "Cn": vehicle.Izz_kg_m2 / (qs * vehicle.length_lateral_m)}
    signals = vehicle_signals(fd, vehicle)
    designs = {ch: m.design(signals)[0].to_numpy(float)[:, np.asarray(ident.fits[ch].identifiable)]
               for ch, m in ident.models.items() if ch in scale and ch not in ident.identities}
    rng = np.random.default_rng(seed)
    est = {ch: [] for ch in designs}
    r_off = np.asarray(vehicle.accel_offset_m, float)
    # the pipeline filters whole segments and drops their edges: the noise of a run here is
    # filtered with PAD band periods of context on both sides, then cropped to the run
    pad = int(np.ceil(2.0 * fs / band))
    for _ in range(replicates):
        f = np.full(sigma.shape, np.nan)
        wdot = np.full((len(t), 3), np.nan)
        for r in runs:
            n = r.stop - r.start
            if n < 2:
                continue
            sig = np.vstack([np.repeat(sigma[r][:1], pad, 0), sigma[r], np.repeat(sigma[r][-1:], pad, 0)])
            x = low_pass_runs(rng.standard_normal(sig.shape) * sig, fs, band, [slice(0, n + 2 * pad)])
            f[r] = x[pad:pad + n]
            wdot[r] = np.gradient(x[:, 3:], 1.0 / fs, axis=0)[pad:pad + n]
        ang = wdot @ Binv.T
        acc = f[:, :3] - np.cross(wdot, r_off)
        coef = {"CN": acc[:, 2], "CY": acc[:, 1], "Cl": ang[:, 0], "Cm": ang[:, 1], "Cn": ang[:, 2]}
        for ch, X in designs.items():
            y = scale[ch] * coef[ch]
            ok = np.isfinite(y) & np.all(np.isfinite(X), axis=1)
            est[ch].append(np.linalg.lstsq(X[ok], y[ok], rcond=None)[0])
    out = {}
    for ch, rows in est.items():
        names = [n for n, u in zip(ident.models[ch].names, ident.fits[ch].identifiable) if u]
        out.update(dict(zip(names, np.std(np.array(rows), axis=0, ddof=1))))
    return out


def one(job: tuple[str, int, str]) -> list[dict]:
    vehicle_name, seed, variant = job
    from aerosid.ebm import process_telemetry

    base = {"vehicle": vehicle_name, "seed": seed, "variant": variant}
    try:
        with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            flight, vehicle = simulate_variant(vehicle_name, seed, Path(tmp), variant)
            t0 = time.perf_counter()
            run = process_telemetry(flight.telemetry, vehicle)
    except Exception as exc:
        return [{**base, "failed": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc(limit=3)}]
    found = [f"{f['kind']} {f['channel']}" for f in run.findings]
    tab = run.identification.table()
    gyro = gyro_bounds(run, vehicle)
    own = estimator_noise_std(run, vehicle) if variant == "estimator" else {}
    rows = []
    for _, r in tab.iterrows():
        rows.append({**base, "failed": "", "time_s": time.perf_counter() - t0, "findings": "; ".join(found),
                     "channel": r["channel"], "coefficient": r["coefficient"],
                     "truth": float(flight.coefficients.get(r["coefficient"], math.nan)),
                     "estimate": r["estimate"], "std_error": r["std_error"], "std_error_ols": r["std_error_ols"],
                     "crb_std": r["crb_std"], "crb_gyro_std": gyro.get(r["coefficient"], math.nan),
                     "estimator_noise_std": own.get(r["coefficient"], math.nan),
                     "condition_number": r["condition_number"], "n_eff": r["n_eff"],
                     "n_obs": r["n_obs"], "band_hz": float(run.flight_data["band_hz"].median())})
    return rows


def chi2_band(n: int) -> tuple[float, float]:
    """95 % band of (sample std / true std) from n independent normal draws."""
    if n < 2:
        return math.nan, math.nan
    return (math.sqrt(scipy.stats.chi2.ppf(0.025, n - 1) / (n - 1)),
            math.sqrt(scipy.stats.chi2.ppf(0.975, n - 1) / (n - 1)))


def summarise(df: pd.DataFrame) -> pd.DataFrame:
    ok = df[(df["failed"].astype(object).fillna("") == "") & np.isfinite(df["estimate"].astype(float))]
    out = []
    for (veh, ch, coef), g in ok.groupby(["vehicle", "channel", "coefficient"], sort=False):
        n = len(g)
        est = g["estimate"].to_numpy(float)
        sd = float(np.std(est, ddof=1)) if n > 1 else math.nan
        crb = float(np.sqrt(np.mean(g["crb_std"].to_numpy(float) ** 2)))
        sig = float(np.mean(g["std_error"]))
        truth = float(g["truth"].iloc[0])
        err = est - truth
        out.append({"vehicle": veh, "channel": ch, "coefficient": coef, "n": n, "truth": truth,
                    "mean_estimate": float(est.mean()), "mc_std": sd, "crb_rms": crb,
                    "mean_sigma": sig, "mean_sigma_ols": float(np.mean(g["std_error_ols"])),
                    "efficiency": sd / crb if crb > 0 else math.nan, "honesty": sd / sig if sig > 0 else math.nan,
                    "sigma_over_crb": sig / crb if crb > 0 else math.nan,
                    "bias_over_std": float(err.mean()) / sd if sd > 0 and math.isfinite(truth) else math.nan,
                    "rms_err_over_crb": float(np.sqrt(np.mean(err ** 2))) / crb if crb > 0 and math.isfinite(truth)
                    else math.nan,
                    "condition_number": float(g["condition_number"].median()), "n_eff": float(g["n_eff"].median())})
        if "crb_gyro_std" in g:
            cg = float(np.sqrt(np.mean(g["crb_gyro_std"].to_numpy(float) ** 2)))
            out[-1].update(crb_gyro_rms=cg, efficiency_gyro=sd / cg if cg > 0 else math.nan)
        if "estimator_noise_std" in g and g["estimator_noise_std"].notna().any():
            own = float(np.sqrt(np.mean(g["estimator_noise_std"].to_numpy(float) ** 2)))
            out[-1].update(estimator_over_crb=own / crb if crb > 0 else math.nan)
    return pd.DataFrame(out)


def report(df: pd.DataFrame, head: str) -> str:
    s = summarise(df)
    lines = [*([head, ""] if head else []),
             "Definitions: bench/bench_efficiency.py (docstring).  efficiency = Monte-Carlo std / RMS CRB; "
             "honesty = Monte-Carlo std / mean reported sigma; bias = mean error / Monte-Carlo std.  "
             f"Coefficients with efficiency > {INEFFICIENT} are marked **bold**.", ""]
    for veh, g in s.groupby("vehicle", sort=False):
        n = int(g["n"].max())
        lo, hi = chi2_band(n)
        failed = df[(df["vehicle"] == veh) & (df["failed"].astype(object).fillna("") != "")]["seed"].nunique()
        gyro = "efficiency_gyro" in g and g["efficiency_gyro"].notna().any()
        own = "estimator_over_crb" in g and g["estimator_over_crb"].notna().any()
        lines += [f"## {veh}: {n} runs ({failed} failed); a std ratio's 95 % sampling band {lo:.2f}..{hi:.2f}", "",
                  "| coefficient | truth | mean estimate | MC std | CRB | mean sigma | sigma OLS | std/CRB | "
                  "std/sigma | sigma/CRB | bias/std | cond. | N_eff |" + (" std/CRB gyros only |" if gyro else "")
                  + (" estimator's own std/CRB |" if own else ""),
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|" + ("---|" if gyro else "") + ("---|" if own else "")]
        for _, r in g.iterrows():
            name = f"**{r['coefficient']}**" if r["efficiency"] > INEFFICIENT else r["coefficient"]
            lines.append(f"| {name} | {r['truth']:.4g} | {r['mean_estimate']:.4g} | {r['mc_std']:.3g} | "
                         f"{r['crb_rms']:.3g} | {r['mean_sigma']:.3g} | {r['mean_sigma_ols']:.3g} | "
                         f"{r['efficiency']:.2f} | {r['honesty']:.2f} | {r['sigma_over_crb']:.2f} | "
                         f"{r['bias_over_std']:+.2f} | {r['condition_number']:.1f} | {r['n_eff']:.0f} |"
                         + (f" {r['efficiency_gyro']:.2f} |" if gyro else "")
                         + (f" {r['estimator_over_crb']:.2f} |" if own else ""))
        lines.append("")
    return "\n".join(lines) + "\n"


def write_md(df: pd.DataFrame, head: str | None) -> None:
    """efficiency.md: head (None: keep the file's), the tables from df, and the file's
    hand-written analysis (everything after TABLES_END) kept as it was."""
    old = MD.read_text() if MD.exists() else ""
    if head is None:
        head = old.split(TABLES, 1)[0].rstrip() if TABLES in old else "# Efficiency bench"
    analysis = old.split(TABLES_END, 1)[1] if TABLES_END in old else "\n"
    MD.write_text(f"{head}\n\n{TABLES}\n{report(df, '').lstrip()}{TABLES_END}{analysis}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-29")
    ap.add_argument("--vehicles", default="seed-rlv,c172x")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--report-only", action="store_true", help="rewrite efficiency.md from the CSV")
    ap.add_argument("--csv", default=None)
    ap.add_argument("--variant", default="default", choices=("default", "exact-inputs", "exact-inputs-no-faults", "estimator"),
                    help="exact-inputs: the regressors' noise sources x0.01 (see simulate_variant); estimator: "
                         "default flights, plus the estimator's own noise std (estimator_noise_std)")
    args = ap.parse_args()
    global MD
    if args.variant != "default":
        MD = OUT / f"efficiency_{args.variant}.md"
    csv = Path(args.csv) if args.csv else (CSV if args.variant == "default" else OUT / f"efficiency_{args.variant}_runs.csv")
    if args.report_only:
        write_md(pd.read_csv(csv), None)
        print(MD.read_text())
        return
    seeds = parse_seeds(args.seeds)
    jobs = [(v, s, args.variant) for s in seeds for v in args.vehicles.split(",")]
    load0, t0 = loadavg(), time.perf_counter()
    rows: list[dict] = []
    with ProcessPoolExecutor(args.workers) as pool:
        futures = [pool.submit(one, j) for j in jobs]
        for fut in as_completed(futures):
            rows += fut.result()
            pd.DataFrame(rows).drop(columns=["traceback"], errors="ignore").to_csv(csv, index=False,
                                                                                   float_format="%.8g")
            print(f"{len({(r['vehicle'], r['seed']) for r in rows})}/{len(jobs)} runs, "
                  f"{(time.perf_counter() - t0) / 60:.1f} min", flush=True)
    what = {"default": "", "exact-inputs": f", variant exact-inputs: the regressors' noise x{EXACT}",
            "exact-inputs-no-faults": f", variant exact-inputs-no-faults: the regressors' noise x{EXACT}, no faults",
            "estimator": ", variant estimator: default flights + the estimator's own noise std"}[args.variant]
    head = (f"# Efficiency of the estimates against the Cramér–Rao bound ({len(seeds)} seeds per vehicle{what})\n\n"
            f"{date.today()}, Python {platform.python_version()}, machine: {cpu_model()}, {os.cpu_count()} cores, "
            f"load average {load0} (start) / {loadavg()} (end); {args.workers} worker(s), wall time "
            f"{(time.perf_counter() - t0) / 60:.1f} min; seeds {seeds[0]}..{seeds[-1]}; default settings, "
            "Mach window half-width 0.5.")
    write_md(pd.DataFrame(rows), head)
    print(MD.read_text())

if __name__ == "__main__":
    main()
