"""Issue 18 bench: look-alikes resolved and the error against its floor, on the real pipeline.

Each run simulates seed-rlv with one hidden catalogue effect (scale 1, Table 2 noise), runs
the estimation chain (preprocess -> EKF/MBF -> band-path flight data) and `diagnose`s the
default models.  Recorded per run:

* ``recommended`` (diagnosis.json `recommended`) and the look-alike verdict;
* for control_alpha / alpha_nonlinearity: the *wrong* look-alike is added to the model and
  the flight re-diagnosed; ``closed_on_wrong`` = that re-diagnosis ends the loop
  ("nothing missing": `loop_closed`), which must never happen;
* the floor of the effect's channel (RMS of the sigma column) against RMS(measured -
  LP(true)) (the band path's own error: the regressors are low-passed alike) and against
  RMS(measured - true) (modelling_loop.md's "floor" column);
* the excess over the floor before and after adding the true effect (identify), and its drop.

    python bench/bench_lookalikes.py --seeds 0-9 --jobs 2 [--seeds-other 0-4] [--cache DIR]
    -> bench/results/lookalikes.md, bench/results/lookalikes_runs.csv
"""
from __future__ import annotations

import argparse
import os
import platform
import time
from concurrent.futures import ProcessPoolExecutor
from datetime import date
from pathlib import Path

import numpy as np
import pandas as pd

WRONG = {"control_alpha": "alpha_nonlinearity", "alpha_nonlinearity": "control_alpha"}
EFFECTS = ("control_alpha", "alpha_nonlinearity", "mach_cm_alpha", "roll_orientation", "fin_misalignment",
           "pitch_damping")


def _rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def _flight(name: str, seed: int, cache: str | None):
    """(flight data, truth on the flight-data rows): simulated and estimated, or read from
    `cache` (files {name}_{seed}_fd.parquet / _truth.parquet written by an earlier run of this
    bench with the same code: the estimation chain is deterministic given the seed)."""
    from aerosid.ebm import estimate_flight_data
    from aerosid.modelling.effects import CATALOGUE
    from aerosid.simulation import load_case, simulate

    if cache:
        f_fd, f_tr = Path(cache) / f"{name}_{seed}_fd.parquet", Path(cache) / f"{name}_{seed}_truth.parquet"
        if f_fd.is_file() and f_tr.is_file():
            return pd.read_parquet(f_fd), pd.read_parquet(f_tr)
    case = load_case("seed-rlv")
    flight = simulate(case, () if name == "none" else ((CATALOGUE[name], 1.0),), seed=seed)
    fd = estimate_flight_data(flight.telemetry, case.vehicle, flight="flight").flight_data
    fd = fd.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    truth = flight.truth.set_index(np.round(flight.truth["t_s"], 6)).loc[np.round(fd["t_s"], 6)].reset_index(drop=True)
    if cache:
        Path(cache).mkdir(parents=True, exist_ok=True)
        tmp = Path(cache) / f"{name}_{seed}_fd.tmp"
        truth.to_parquet(Path(cache) / f"{name}_{seed}_truth.parquet")
        fd.to_parquet(tmp)
        tmp.rename(Path(cache) / f"{name}_{seed}_fd.parquet")
    return fd, truth


def one(job: tuple) -> dict:
    from aerosid.diagnosis import diagnose
    from aerosid.diagnosis.floor import excess
    from aerosid.modelling.effects import CATALOGUE
    from aerosid.identification.band import low_pass_runs
    from aerosid.identification.identify import identify, mach_window_mask
    from aerosid.modelling.models import default_models, parse_term
    from aerosid.simulation import load_case

    name, seed, cache = job
    t0 = time.perf_counter()
    vehicle = load_case("seed-rlv").vehicle
    fd, truth = _flight(name, seed, cache)
    d = diagnose(fd, vehicle)
    top_look = next((c for c in d.lookalikes if c.in_model is None), None)
    row = {"effect": name, "seed": seed, "top": d.top.name, "top_significant": bool(d.top.significant),
           "recommended": d.recommended or "", "loop_closed": bool(d.loop_closed),
           "lookalike_verdict": top_look.verdict if top_look else "",
           "lookalike_names": " ".join(top_look.names) if top_look else "",
           "lookalike_delta": max(top_look.delta.values()) if top_look else np.nan}
    if name == "none":
        row["seconds"] = time.perf_counter() - t0
        return row
    eff = CATALOGUE[name]
    ch = eff.channel
    e = d.effect(name)
    row.update(channel=ch, significant=bool(e.significant), rank=d.rank_of(name),
               detectable_size=e.detectable_size, truth=eff.value,
               above_floor=bool(abs(eff.value) > e.detectable_size))
    # the floor against the truth
    t = fd["t_s"].to_numpy(float)
    seg = fd["segment"].astype(str).to_numpy()
    brk = np.nonzero((np.diff(t) > 0.015) | (seg[1:] != seg[:-1]))[0] + 1
    edges = np.concatenate([[0], brk, [t.size]])
    runs = [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:]) if b - a > 30]
    fs = 1.0 / float(np.median(np.diff(t)))
    lp = low_pass_runs(truth[ch].to_numpy(float), fs, float(fd["band_hz"].iloc[0]), runs)
    m = mach_window_mask(fd["mach"].to_numpy(float), vehicle.mach_reference, 0.5) & np.isfinite(lp)
    meas = fd[ch].to_numpy(float)
    row["floor_sigma"] = d.floor[ch].floor_rms
    row["err_vs_lp_truth"] = _rms((meas - lp)[m])
    row["err_vs_truth"] = _rms((meas - truth[ch].to_numpy(float))[m])
    # the excess over the floor before and after adding the true effect
    base = identify(fd, vehicle, default_models(vehicle), bias_pairs=0)  # as recorded
    models = dict(default_models(vehicle))
    models[ch] = models[ch].with_term(parse_term(name, ch))
    aug = identify(fd, vehicle, models, bias_pairs=0)  # as recorded
    fl = d.floor[ch].floor_rms
    row["resid_before"], row["resid_after"] = base.fits[ch].rms_residual, aug.fits[ch].rms_residual
    row["excess_before"], row["excess_after"] = excess(row["resid_before"], fl), excess(row["resid_after"], fl)
    row["excess_drop"] = 1 - row["excess_after"] / row["excess_before"] if row["excess_before"] > 0 else np.nan
    row["resid_drop"] = 1 - row["resid_after"] / row["resid_before"]
    if name in WRONG:
        wrong = dict(default_models(vehicle))
        wrong[ch] = wrong[ch].with_term(parse_term(WRONG[name], ch))
        d2 = diagnose(fd, vehicle, wrong)
        look = next((c for c in d2.lookalikes if c.in_model == WRONG[name]), None)
        row.update(after_wrong_recommended=d2.recommended or "", closed_on_wrong=bool(d2.loop_closed),
                   after_wrong_verdict=look.verdict if look else "",
                   after_wrong_true_significant=bool(any(x.name == name and x.significant for x in d2.effects)),
                   after_wrong_message=d2.message[:400])
        # held-out: does the true term still improve the prediction once the wrong one is in?
        if look is not None:
            row["after_wrong_heldout_true"] = look.alternative(name).heldout_rms
            row["after_wrong_heldout_wrong"] = look.alternative(WRONG[name]).heldout_rms
    row["seconds"] = time.perf_counter() - t0
    return row


def _seeds(text: str) -> list[int]:
    a, _, b = text.partition("-")
    return list(range(int(a), int(b) + 1)) if b else [int(a)]


def _report(df: pd.DataFrame, seeds: list[int], wall_s: float, other_txt: str | None = None) -> str:
    from machine import cpu_model, loadavg

    n = len(seeds)
    L = [f"# Look-alikes and the floor on the real pipeline (issue 18), {n} seeds per look-alike effect", "",
         f"{date.today()}, {cpu_model()}, {os.cpu_count()} cores, load {loadavg()}; wall {wall_s / 60:.1f} min. "
         f"`python bench/bench_lookalikes.py --seeds {seeds[0]}-{seeds[-1]}" + (f" --seeds-other {other_txt}" if other_txt else "") + "`.", "",
         "Each run: seed-rlv with one hidden effect at scale 1 (Table 2 noise), preprocess, EKF + MBF, band-path "
         "flight data, `diagnose` the default models. *recommended* = diagnosis.json `recommended`. For the two "
         "look-alikes the wrong one is then added and the flight re-diagnosed: *closed on wrong* = the "
         "re-diagnosis ends the loop (`loop_closed`, \"nothing missing\"). Floor = the diagnosis' `floor_rms` "
         "(aerosid/diagnosis/floor.py: the band path's coefficient sigma and the angles' part measured by refits, "
         "in quadrature); excess = sqrt(residual^2 - floor^2).", "",
         "## Look-alikes", "",
         "| effect | true effect recommended | wrong one recommended | none recommended | verdicts | closed on the wrong one | re-diagnosis after the wrong one: recommends the true / unresolved |",
         "|---|---|---|---|---|---|---|"]
    for name in WRONG:
        g = df[df["effect"] == name]
        if not len(g):
            continue
        verd = ", ".join(f"{k} {v}" for k, v in g["lookalike_verdict"].replace("", "none").value_counts().items())
        L.append(f"| {name} | {int((g['recommended'] == name).sum())}/{len(g)} | "
                 f"{int((g['recommended'] == WRONG[name]).sum())}/{len(g)} | {int((g['recommended'] == '').sum())}/{len(g)} "
                 f"| {verd} | {int(g['closed_on_wrong'].sum())}/{len(g)} | "
                 f"{int((g['after_wrong_recommended'] == name).sum())} / {int((g['after_wrong_verdict'] == 'unresolved').sum())} |")
    none = df[df["effect"] == "none"]
    if len(none):
        L += ["", f"No hidden effect: something recommended in {int((none['recommended'] != '').sum())}/{len(none)} "
                  f"flights; loop closed in {int(none['loop_closed'].sum())}/{len(none)}."]
    L += ["", "## The error against its floor", "",
          "*Above its detection floor*: |true coefficient| > the diagnosis' `detectable_size` for it on that flight "
          "(t(p = 0.001) x its coloured-residual sigma); *detected*: the diagnosis calls it significant. Drops are "
          "1 - excess_after / excess_before per run.", "",
          "| effect | ch | above its detection floor | detected | floor | RMS(meas - LP(true)) | ratio | RMS(meas - true) | ratio | residual before -> after (drop) | excess before -> after | excess drop over runs above the floor: mean, min, runs >= 50 % | same over detected runs |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    eff = df[df["effect"] != "none"]
    for name, g in eff.groupby("effect", sort=False):
        def drops(a):
            return (f"{a['excess_drop'].mean():.0%}, {a['excess_drop'].min():.0%}, "
                    f"{int((a['excess_drop'] >= 0.5).sum())}/{len(a)}" if len(a) else "-")

        drop = drops(g[g["above_floor"]]) + " | " + drops(g[g["significant"]])
        L.append(f"| {name} | {g['channel'].iloc[0]} | {int(g['above_floor'].sum())}/{len(g)} "
                 f"| {int(g['significant'].sum())}/{len(g)} | {g['floor_sigma'].mean():.2e} "
                 f"| {g['err_vs_lp_truth'].mean():.2e} | {(g['floor_sigma'] / g['err_vs_lp_truth']).mean():.2f} "
                 f"| {g['err_vs_truth'].mean():.2e} | {(g['floor_sigma'] / g['err_vs_truth']).mean():.2f} "
                 f"| {g['resid_before'].mean():.2e} -> {g['resid_after'].mean():.2e} ({g['resid_drop'].mean():.0%}) "
                 f"| {g['excess_before'].mean():.2e} -> {g['excess_after'].mean():.2e} | {drop} |")
    L += ["", "Per-run rows: `bench/results/lookalikes_runs.csv`."]
    return "\n".join(L) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--effects", default=",".join(EFFECTS))
    ap.add_argument("--out", default=str(Path(__file__).parent / "results"))
    ap.add_argument("--cache", default=None, help="folder to keep (and reuse) each run's flight data and truth")
    ap.add_argument("--seeds-other", default=None,
                    help="seeds for the effects other than the two look-alikes and none (default: --seeds)")
    args = ap.parse_args()
    seeds = _seeds(args.seeds)
    other = _seeds(args.seeds_other) if args.seeds_other else seeds
    names = args.effects.split(",")
    first = [n for n in names if n in WRONG]
    jobs = ([(n, s, args.cache) for n in first for s in seeds] + [("none", s, args.cache) for s in seeds]
            + [(n, s, args.cache) for n in names if n not in WRONG for s in other])
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = []
        for r in pool.map(one, jobs):
            rows.append(r)
            print(f"{r['effect']} {r['seed']}: recommended {r['recommended'] or '-'} ({r['seconds']:.0f} s)", flush=True)
    df = pd.DataFrame(rows)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    df.to_csv(out / "lookalikes_runs.csv", index=False)
    text = _report(df, seeds, time.perf_counter() - t0, args.seeds_other)
    (out / "lookalikes.md").write_text(text)
    print(text)
    print(platform.platform())


if __name__ == "__main__":
    main()
