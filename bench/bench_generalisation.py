"""Generalisation bench (issue 16): the EBM pipeline with DEFAULT settings on vehicles the
project was not tuned on, N seeds each.

    python bench/bench_generalisation.py [--seeds 0-9] [--vehicles seed-rlv,c172x,pa28,...] [--jobs 1]
    -> bench/results/generalisation.md and bench/results/generalisation_runs.csv

Vehicles: seed-rlv (aerosid's own simulator), c172x (the hand-written JSBSim flight and
its shipped vehicle file) and the JSBSim aircraft flown with a GENERATED flight design
and vehicle file (aerosid.simulation.jsbsim_flight.GENERATED_AIRCRAFT: a light single,
a twin, a jet trainer, a jet attack aircraft and a Mach 2 airliner).  The 737 and the
787-8 are reserved for an independent check and never flown here.

Each run: simulate (noise and faults from the seed), then ``aerosid.ebm.process_telemetry``
with the vehicle file exactly as a user would have it (seed-rlv, c172x: the shipped files;
the generated aircraft: the vehicle.toml written beside the telemetry) and every other
setting at its default (including the Mach window of half-width 0.5).

Per vehicle and coefficient the table gives the truth, the mean and RMS error [% of
the truth] over the runs that completed, and the 95 % coverage: the fraction of runs
whose |estimate - truth| <= 1.96 x the reported (corrected) standard error.  Coefficients
(moments about the CG, SI per radian): Cm_alpha, Cm_delta (Cm_delta_p), damping =
Cm_q + Cm_alpha_dot (``LinearFit.combination``, sigma from the full covariance; Cm_q alone
where the model has no Cm_alpha_dot), CN_alpha, CN_delta (CN_delta_p), Cl_p, Cl_delta
(Cl_delta_r), Cn_beta, Cn_r, Cn_delta (Cn_delta_y).  "-" = not in the vehicle's default
model (seed-rlv's finned-class model has no rate terms).  seed-rlv's control derivatives
are per radian of delta/2 (its own convention); the aircraft's per radian of deflection.
The *oracle* column (aircraft) fits the same default model to the noise-free truth (the
aerodynamic plus propulsive coefficients the sensors feel, the true regressors): the part
of the error the model structure and the flight make, which no estimator removes.

A SILENT FAILURE is a run the pipeline reports as fine -- it returned an identification,
no smoothed segment is flagged diverged and the run has no finding (aerosid.estimation.findings:
a run with one is "ok with findings" and names the spans) -- in which some coefficient with a bar in issue
16 (Cm_alpha, Cm_delta, damping, CN_alpha, Cl_p, Cn_beta, Cn_r) is off the truth by more
than 5 reported sigma, or by more than 30 % while its 95 % interval excludes the truth --
unless the run printed that coefficient as NOT DETERMINED by the flight (its 95 % interval
holds 0: the coefficients table and the run's summary say so, 2026-11-26; before that F4N
seed 13's C_n,r, -0.024 +- 0.05 against -0.15, counted as silent).
A run that raises, or flags a segment as diverged, has announced itself and counts as a
failed run instead (and as a miss of every coverage).

A SECOND TRUTH for the JSBSim aircraft, beside the at-trim one (bench/generalisation_avg.py):
the flight-averaged derivative, per coefficient the mean over the flight's samples of the
central difference (h = 1e-4) of the same JSBSim model at each sample's own state.  JSBSim's
tables interpolate linearly, so the at-trim derivative is the slope of the one table segment
the trim point sits on (pa28's C_L(alpha): 5.743/rad below alpha = 0, 5.914 above, trim at
-0.48 deg, the flight crosses 0); by Stein's lemma, for jointly Gaussian excursions the
least-squares slope of a smooth f is E[f'(x)] over the excursions, which for piecewise-linear
tables is what a linear model identified from the flight estimates (the flight's excursions
are not Gaussian: the average is a physically motivated reference, not an identity).
seed-rlv's truth is analytic and linear: its averaged truth equals it.  Columns
NAME_truth_avg, NAME_err_pct_avg, NAME_z_avg, NAME_cover_avg, NAME_oracle_pct_avg,
silent_failure_avg; the report gives a second table per vehicle and the bars against both.
``--truth-only`` re-simulates every (vehicle, seed) of the runs CSV without the pipeline
(checking the at-trim truth against the CSV's) and merges the averaged truth into it.

The machine is shared: --jobs defaults to 1; each run takes ~0.5-1.5 min.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import tempfile
import time
import traceback
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
from bench_accuracy import parse_seeds  # noqa: E402  (the seed-range syntax of the benches)
from machine import loadavg, run_jobs, run_line  # noqa: E402  (bench/machine.py)
import generalisation_avg as averaged  # noqa: E402  (the flight-averaged truth)

COEFFICIENTS = {  # bench name -> truth / estimate name
    "Cm_alpha": "Cm_alpha", "Cm_delta": "Cm_delta_p", "damping": None, "CN_alpha": "CN_alpha",
    "CN_delta": "CN_delta_p", "Cl_p": "Cl_p", "Cl_delta": "Cl_delta_r", "Cn_beta": "Cn_beta", "Cn_r": "Cn_r",
    "Cn_delta": "Cn_delta_y",
}
BARRED = ("Cm_alpha", "Cm_delta", "damping", "CN_alpha", "Cl_p", "Cn_beta", "Cn_r")
SILENT_SIGMA = 5.0
SILENT_PCT = 30.0


def default_vehicles() -> list[str]:
    from aerosid.simulation.jsbsim_flight import GENERATED_AIRCRAFT

    return ["seed-rlv", "c172x", *GENERATED_AIRCRAFT]


def simulate(vehicle: str, seed: int, workdir: Path, turbulence: str = "none"):
    """(flight, Vehicle) as a user would have them; turbulence: a JSBSim flight's level
    (aerosid.simulation.jsbsim_turbulence.TURBULENCE_SEVERITY; seed-rlv flies in calm air only)."""
    from aerosid.vehicles.vehicle import load_vehicle

    if vehicle == "seed-rlv":
        from aerosid.simulation import load_case, simulate as sim

        if turbulence != "none":
            raise ValueError("seed-rlv's simulator flies in calm air only")
        case = load_case("seed-rlv")
        return sim(case, seed=seed), case.vehicle
    from aerosid.simulation.jsbsim_aircraft import RESERVED
    from aerosid.simulation.jsbsim_flight import simulate_jsbsim

    if vehicle in RESERVED:
        raise ValueError(f"{vehicle} is reserved for an independent check")
    flight = simulate_jsbsim(vehicle, "3211", seed, turbulence=turbulence)
    if "vehicle.toml" in flight.files:  # generated: written beside the telemetry, loaded from there
        paths = flight.write(workdir / f"{vehicle}-{seed}")
        return flight, load_vehicle(paths["vehicle"])
    return flight, load_vehicle(vehicle)


def truth_of(flight, name: str) -> float:
    c = flight.coefficients
    if name == "damping":
        if "Cm_q_plus_alpha_dot" in c:
            return float(c["Cm_q_plus_alpha_dot"])
        return float(c.get("Cm_q", math.nan) + c.get("Cm_alpha_dot", 0.0))
    return float(c.get(COEFFICIENTS[name], math.nan))


def estimate_of(ident, name: str) -> tuple[float, float]:
    """(estimate, corrected sigma) or (nan, nan) when the model lacks the term."""
    fit = ident.fits.get("Cm")
    if name == "damping":
        if fit is None or "Cm_q" not in fit.names:
            return math.nan, math.nan
        weights = {"Cm_q": 1.0, **({"Cm_alpha_dot": 1.0} if "Cm_alpha_dot" in fit.names else {})}
        est, se, *_ = fit.combination(weights)
        return est, se
    tab = ident.table().set_index("coefficient")
    key = COEFFICIENTS[name]
    if key not in tab.index:
        return math.nan, math.nan
    return float(tab.loc[key, "estimate"]), float(tab.loc[key, "std_error"])


#: The model signals of a JSBSim truth frame: signal name -> truth column (beta_dot_hat is zero).
TRUTH_SIGNALS = dict(alpha="alpha_rad", beta="beta_rad", mach="mach", V="V_m_s", qbar="qbar_pa",
                     delta_p="delta_p_rad", delta_r="delta_r_rad", delta_y="delta_y_rad", p="p_rad_s", q="q_rad_s",
                     r="r_rad_s", p_hat="p_hat", q_hat="q_hat", r_hat="r_hat", alpha_dot_hat="alpha_dot_hat",
                     t="t_s")


def truth_signals(T) -> dict[str, np.ndarray]:
    """The model signals (aerosid.modelling.models.SIGNALS names) of a JSBSim truth frame."""
    return {**{k: T[c].to_numpy() for k, c in TRUTH_SIGNALS.items()}, "beta_dot_hat": np.zeros(len(T))}


def oracle(flight, vehicle) -> dict[str, float]:
    """The vehicle's default models fitted to the noise-free truth (what the sensors see:
    aerodynamic + propulsive coefficients) with the true regressors (aircraft only)."""
    from aerosid.modelling.models import default_models

    T = flight.truth
    if vehicle.vehicle_class != "aircraft" or "q_hat" not in T:
        return {}
    sig = truth_signals(T)
    target = {"Cm": T["Cm"] + T["Cm_prop"], "CN": T["CN"] - T["CZ_prop"], "Cl": T["Cl"] + T["Cl_prop"],
              "Cn": T["Cn"] + T["Cn_prop"]}
    out = {}
    for ch, model in default_models(vehicle).items():
        if ch not in target:
            continue
        X = model.regressors(sig)
        sol = dict(zip(X.columns, np.linalg.lstsq(X.to_numpy(), target[ch].to_numpy(), rcond=None)[0]))
        for name, key in COEFFICIENTS.items():
            if key in sol:
                out[name] = sol[key]
        if ch == "Cm" and "Cm_q" in sol:
            out["damping"] = sol["Cm_q"] + sol.get("Cm_alpha_dot", 0.0)
    return out


def decimated(telemetry: pd.DataFrame, factor: int) -> pd.DataFrame:
    """Every factor-th sample of the telemetry's sample grid (by time, so the rows a dropout
    removed stay removed): the same flight logged at 1/factor of the rate, each sensor read
    at its instant (no anti-alias filter: the sensors' white noise keeps its per-sample sigma)."""
    if factor <= 1:
        return telemetry
    t = telemetry["t_s"].to_numpy(float)
    dt = float(np.nanmedian(np.diff(t)))
    k = np.rint((t - np.nanmin(t)) / dt).astype(np.int64)
    return telemetry.loc[k % factor == 0].reset_index(drop=True)


def one(job: tuple) -> dict:
    vehicle_name, seed, *rest = job
    factor = int(rest[0]) if rest else 1
    from aerosid.ebm import process_telemetry

    row = {"vehicle": vehicle_name, "seed": seed, "failed": "", "diverged": False}
    with tempfile.TemporaryDirectory() as tmp:
        try:
            flight, vehicle = simulate(vehicle_name, seed, Path(tmp))
        except Exception as exc:  # the flight itself: recorded, not the pipeline's fault
            row["failed"] = f"simulation: {type(exc).__name__}: {exc}"
            return row
    orc = oracle(flight, vehicle)
    if factor > 1:
        row["decimate"] = factor
        flight = dataclasses.replace(flight, telemetry=decimated(flight.telemetry, factor))
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            run = process_telemetry(flight.telemetry, vehicle)
    except Exception as exc:
        row["failed"] = f"{type(exc).__name__}: {exc}"
        row["traceback"] = traceback.format_exc(limit=3)
        return row
    row["time_s"] = time.perf_counter() - t0
    row["diverged"] = any(bool(getattr(s.result, "diverged", False)) for s in run.smoothed)
    found = list(getattr(run, "findings", []))
    row["findings"] = "; ".join(f"{f['kind']} {f['channel']} {f['t0_s']:.1f}-{f['t1_s']:.1f} s".replace("  ", " ")
                                for f in found)
    row["band_hz"] = float(run.flight_data["band_hz"].median()) if "band_hz" in run.flight_data else math.nan
    for name in COEFFICIENTS:
        truth = truth_of(flight, name)
        est, se = estimate_of(run.identification, name)
        row[f"{name}_truth"], row[f"{name}_est"], row[f"{name}_se"] = truth, est, se
        if math.isfinite(est) and math.isfinite(truth) and truth != 0:
            row[f"{name}_err_pct"] = 100.0 * (est / truth - 1.0)
            row[f"{name}_z"] = (est - truth) / se if se > 0 else math.inf
            row[f"{name}_cover"] = bool(abs(est - truth) <= 1.96 * se)
        if name in orc and math.isfinite(truth) and truth != 0:
            row[f"{name}_oracle_pct"] = 100.0 * (orc[name] / truth - 1.0)
    # a run with findings said so ("ok with findings"): averaged.silent leaves it out
    row["silent_failure"] = averaged.silent(row, BARRED, SILENT_SIGMA, SILENT_PCT)
    averaged.add_columns(row, flight, COEFFICIENTS, COEFFICIENTS, truth_of, BARRED, SILENT_SIGMA, SILENT_PCT)
    return row


def report(df: pd.DataFrame, seeds: list[int], label: str, load: tuple[str, str], jobs: int, wall_s: float) -> str:
    lines = [f"# Generalisation bench ({label}): {len(seeds)} seed(s) per vehicle, default settings", "",
             run_line(load, jobs, wall_s) + f"; seeds {seeds[0]}..{seeds[-1]}.", "",
             "Flights and definitions: bench/bench_generalisation.py (docstring).  Errors in % of the truth "
             "(mean / RMS / worst over the completed runs); coverage = share of ALL runs whose 95 % interval (1.96 "
             "reported sigma) holds the truth; oracle = the default model fitted to the noise-free truth (the best "
             "the model structure can give on this flight); coverage of the oracle = the same share against it.  "
             "Truth = the at-trim truth (central differences of the model at the trim point); 'vs the flight-averaged "
             "truth' = the same columns against the mean over the flight's samples of the central difference at each "
             "sample's state (bench/generalisation_avg.py: by Stein's lemma what a linear fit estimates for Gaussian "
             "excursions; seed-rlv: analytic and linear, the same truth).", ""]
    if label == "smoke":
        lines += [f"**Smoke run** (fewer than 10 seeds: {len(seeds)}): not the bench result; the "
                  "full bench is `python bench/bench_generalisation.py --seeds 0-9`.", ""]
    lines += ["| vehicle | runs | failed (announced) | with findings | silent failures | band edge [Hz] | "
              "pipeline time per run [s] |", "|---|---|---|---|---|---|---|"]
    for v, g in df.groupby("vehicle", sort=False):
        ok = g[g["failed"] == ""]
        failed = len(g) - len(ok) + int(ok["diverged"].sum())
        silent = int((ok["silent_failure"].fillna("") != "").sum()) if len(ok) else 0
        t = f"{ok['time_s'].mean():.0f}" if len(ok) else "-"
        flagged = int((ok["findings"].fillna("") != "").sum()) if "findings" in ok and len(ok) else 0
        band = f"{ok['band_hz'].median():.2f}" if "band_hz" in ok and len(ok) else "-"
        lines.append(f"| {v} | {len(g)} | {failed} | {flagged} | {silent} | {band} | {t} |")
    for v, g in df.groupby("vehicle", sort=False):
        ok = g[(g["failed"] == "") & ~g["diverged"].astype(bool)]
        lines += ["", f"## {v}", "", "| coefficient | truth | mean error % | RMS error % | worst error % | "
                  "95 % coverage | mean sigma % | oracle % | coverage of the oracle |", "|---|---|---|---|---|---|---|---|---|"]
        for name in COEFFICIENTS:
            col = f"{name}_err_pct"
            if col not in g or g[col].notna().sum() == 0:
                lines.append(f"| {name} | {g.get(f'{name}_truth', pd.Series([math.nan])).iloc[0]:.4g} | - | - | - | - | - | "
                             "- | - |")
                continue
            e = ok[col].dropna()
            cover = ok[f"{name}_cover"].fillna(False).astype(bool).sum() / len(g)
            sig = (100 * ok[f"{name}_se"] / ok[f"{name}_truth"].abs()).mean()
            orc = ok.get(f"{name}_oracle_pct")
            orc_txt = f"{orc.mean():+.1f}" if orc is not None and orc.notna().any() else "-"
            orc_cover = "-"
            if orc is not None and orc.notna().any():  # the interval against what the model CAN give
                best = ok[f"{name}_truth"] * (1 + orc / 100)
                orc_cover = f"{((ok[f'{name}_est'] - best).abs() <= 1.96 * ok[f'{name}_se']).sum() / len(g):.0%}"
            lines.append(f"| {name} | {ok[f'{name}_truth'].iloc[0]:.4g} | {e.mean():+.1f} | "
                         f"{np.sqrt((e ** 2).mean()):.1f} | {e.abs().max():.1f} | {cover:.0%} | {sig:.1f} | {orc_txt} | "
                         f"{orc_cover} |")
        lines += averaged.vehicle_table(g, ok, list(COEFFICIENTS))
        for _, r in g.iterrows():
            if r["failed"]:
                lines.append(f"\nseed {r['seed']}: failed: {r['failed']}")
            elif r["diverged"]:
                lines.append(f"\nseed {r['seed']}: a smoothed segment is flagged diverged")
            elif r.get("silent_failure"):
                lines.append(f"\nseed {r['seed']}: SILENT FAILURE: {r['silent_failure']}")
    lines += ["", "## Issue 16's bars", "", "Against the at-trim truth:", "", bars(df)]
    if any(c.endswith(averaged.SUFFIX) for c in df.columns):
        lines += ["", "Against the flight-averaged truth (seed-rlv: the same truth):", "", bars(df, averaged.SUFFIX)]
    return "\n".join(lines) + "\n"


#: issue 16's done-when bars: name -> (|mean| and RMS error limit [%], coverage floor or None)
BARS = {"Cm_alpha": (3.0, 0.85), "Cm_delta": (3.0, 0.85), "damping": (10.0, 0.85), "CN_alpha": (5.0, 0.85),
        "Cl_p": (10.0, None), "Cn_beta": (10.0, None), "Cn_r": (10.0, None)}


def bars(df: pd.DataFrame, suffix: str = "") -> str:
    """One line per vehicle: every bar of issue 16 it misses (|mean| error and RMS against the
    limit -- Cm_alpha and Cm_delta: mean <= 3 %, RMS <= 5 % --, coverage against 85 %;
    seed-rlv: |error| <= 5 % on every seed and coverage >= 90 % for Cm_alpha and Cm_delta).
    suffix "_avg": against the flight-averaged truth (generalisation_avg)."""
    out = []
    for v, g in df.groupby("vehicle", sort=False):
        if suffix:  # the rows that have that truth
            g = averaged.with_average(g)
            if g.empty:
                out.append(f"- {v}: not computed")
                continue
        ok = g[(g["failed"] == "") & ~g["diverged"].astype(bool)]
        if ok.empty:  # nothing to measure: not "every bar met"
            first = str(g["failed"].iloc[0]) if len(g) and str(g["failed"].iloc[0]) else "diverged"
            out.append(f"- {v}: no completed run ({len(g)} failed; first: {first[:160]})")
            continue
        miss = []
        for name, (limit, floor) in BARS.items():
            col = f"{name}_err_pct{suffix}"
            if col not in ok or ok[col].notna().sum() == 0:
                continue
            e = ok[col].dropna()
            rms_limit = 5.0 if name in ("Cm_alpha", "Cm_delta") else limit
            if abs(e.mean()) > limit:
                miss.append(f"{name} mean {e.mean():+.1f} % (bar {limit:g})")
            if np.sqrt((e ** 2).mean()) > rms_limit:
                miss.append(f"{name} RMS {np.sqrt((e ** 2).mean()):.1f} % (bar {rms_limit:g})")
            cover = ok[f"{name}_cover{suffix}"].fillna(False).astype(bool).sum() / len(g)
            if v == "seed-rlv" and name in ("Cm_alpha", "Cm_delta"):
                floor = 0.90
                if e.abs().max() > 5.0:
                    miss.append(f"{name} worst seed {e.abs().max():.1f} % (bar 5)")
            if floor is not None and cover < floor:
                miss.append(f"{name} coverage {cover:.0%} (bar {floor:.0%})")
        silent = int((ok[f"silent_failure{suffix}"].fillna("") != "").sum())
        if silent:
            miss.append(f"{silent} silent failure(s)")
        out.append(f"- {v}: " + ("every bar met" if not miss else "misses " + "; ".join(miss)))
    return "\n".join(out)


TEXT_COLUMNS = ("failed", "findings", "silent_failure", "silent_failure_avg")


def read_runs(path) -> pd.DataFrame:
    df = pd.read_csv(path, dtype={c: str for c in TEXT_COLUMNS})
    for c in TEXT_COLUMNS:
        if c in df:
            df[c] = df[c].fillna("")
    # the silent-failure rule is applied again (it has changed since some CSVs were written)
    rows = df.to_dict("records")
    df["silent_failure"] = [averaged.silent(r, BARRED, SILENT_SIGMA, SILENT_PCT) for r in rows]
    if "silent_failure_avg" in df:
        df["silent_failure_avg"] = [averaged.silent(r, BARRED, SILENT_SIGMA, SILENT_PCT, averaged.SUFFIX) for r in rows]
    return df


def truth_only(args) -> None:
    """--truth-only: the flight-averaged truth merged into the runs CSV (no pipeline run)."""
    path = Path(args.from_csv) if args.from_csv else Path(__file__).parent / "results" / "generalisation_runs.csv"
    df = read_runs(path)
    vehicles = args.vehicles.split(",") if args.vehicles else list(dict.fromkeys(df["vehicle"]))
    seeds = set(parse_seeds(args.seeds))
    jobs = [(v, int(s)) for v, s in zip(df["vehicle"], df["seed"]) if v in vehicles and int(s) in seeds]
    t0 = time.perf_counter()
    results = run_jobs(averaged.truth_only_job, jobs, args.jobs)
    merged, bad = averaged.merge(df, results, list(COEFFICIENTS), BARRED, SILENT_SIGMA, SILENT_PCT)
    if bad:
        raise SystemExit("the at-trim truth recomputed differs from the CSV's (not the same simulation):\n"
                         + "\n".join(bad))
    merged.to_csv(path, index=False, float_format="%.6g")
    n_sim = sum(not r["analytic"] for r in results)
    print(f"{n_sim} JSBSim run(s) re-simulated in {time.perf_counter() - t0:.0f} s (seed-rlv: analytic, not "
          f"simulated); at-trim truth identical to the CSV's in every run; flight-averaged truth merged into {path}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--vehicles", default=None, help="comma-separated (default: seed-rlv, c172x and the generated set)")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--label", default=None, help="'smoke' or 'full' (default: full with >= 10 seeds)")
    ap.add_argument("--from-csv", default=None, help="rewrite the report from a runs CSV of this bench")
    ap.add_argument("--decimate", type=int, default=1,
                    help="log every K-th sample only (100/K Hz for the JSBSim flights): a flight the rate of the "
                         "bench's never saw")
    ap.add_argument("--stem", default="generalisation",
                    help="results file stem: bench/results/STEM.md and STEM_runs.csv")
    ap.add_argument("--truth-only", action="store_true",
                    help="simulate the runs CSV's (vehicle, seed) pairs again without the pipeline and merge the "
                         "flight-averaged truth into it (generalisation_avg)")
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    if args.truth_only:
        truth_only(args)
        return
    if args.from_csv:
        df = read_runs(args.from_csv)
        text = report(df, sorted(df["seed"].unique().tolist()), args.label or "full", ("-", "-"), args.jobs, math.nan)
        print(text)
        return
    vehicles = args.vehicles.split(",") if args.vehicles else default_vehicles()
    label = args.label or ("full" if len(seeds) >= 10 else "smoke")
    jobs = [(v, s, args.decimate) for v in vehicles for s in seeds]
    load0, t0 = loadavg(), time.perf_counter()
    rows = run_jobs(one, jobs, args.jobs)
    wall = time.perf_counter() - t0
    df = pd.DataFrame(rows)
    out = Path(__file__).parent / "results"
    df.drop(columns=["traceback"], errors="ignore").to_csv(out / f"{args.stem}_runs.csv", index=False,
                                                           float_format="%.6g")
    text = report(df, seeds, label, (load0, loadavg()), args.jobs, wall)
    (out / f"{args.stem}.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
