"""Proof by simulation of `aerosid design` (issue 20): fly each designed manoeuvre over
seeds through the whole pipeline and check what the design promised.

* seed-rlv, Table 2 noise, one hidden effect (pitch_damping at Cm_q = -30 =
  the catalogue size; alpha_nonlinearity at its catalogue size): the design computed
  from ONE run of the reference flight (`aerosid design RUN --effect NAME --out DIR`)
  is flown with `simulate(case with inputs=DIR/input.parquet)` for every seed
  (noise, dropouts, outliers, sync gap), preprocess -> EKF/MBF -> flight data ->
  `diagnose`: is the effect ranked first and significant?  Its estimate, reported
  sigma and detectable size against the design's prediction.
* c172x (JSBSim): the design `--effect Cm_q --versus Cm_alpha_dot` flown for every
  seed (noise and faults), the pipeline's identification with the vehicle's default
  model (both terms): error of each against JSBSim's truth.

    python bench/bench_design.py rlv DESIGN_DIR --effect pitch_damping --seeds 0-9 --jobs 2
    python bench/bench_design.py c172x DESIGN_DIR --seeds 0-9 --jobs 2
    -> bench/results/design_runs_<tag>.csv; bench/results/design.md is written by hand from them
"""
from __future__ import annotations

import argparse
import json
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

RESULTS = Path(__file__).parent / "results"


def one_rlv(job: tuple) -> dict:
    from dataclasses import replace

    from aerosid.design.io import as_case_inputs, read_input
    from aerosid.diagnosis import diagnose
    from aerosid.ebm import process_telemetry
    from aerosid.modelling.effects import CATALOGUE
    from aerosid.simulation import load_case, simulate

    design_dir, effect, scale, seed = job
    t0 = time.perf_counter()
    case = load_case("seed-rlv")
    if design_dir:
        table = read_input(Path(design_dir) / "input.parquet")
        case = replace(case, inputs=as_case_inputs(table), duration_s=float(table["t_s"].iloc[-1]))
    eff = CATALOGUE[effect]
    flight = simulate(case, ((eff, scale),), seed=seed)
    row = {"design": str(design_dir or "reference"), "effect": effect, "scale": scale, "seed": seed,
           "truth": eff.value * scale}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            run = process_telemetry(flight.telemetry, case.vehicle)
            fd = run.flight_data.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
            d = diagnose(fd, case.vehicle)
    except Exception as exc:  # a failed run counts as a miss
        row["failed"] = f"{type(exc).__name__}: {exc}"
        return row
    e = d.effect(effect)
    tr = flight.truth
    row.update(top=d.top.name if d.effects else "", rank=d.rank_of(effect), significant=bool(e.significant),
               first_and_significant=bool(d.rank_of(effect) == 1 and e.significant), estimate=e.estimate,
               std_error=e.std_error, detectable_size=e.detectable_size, p_value=e.p_value,
               window_consistency=e.window_consistency, eiv_fraction=e.eiv_fraction,
               reasons="; ".join(e.reasons), n_significant=sum(x.significant for x in d.effects),
               fin_max_rad=float(np.max(np.abs(flight.telemetry[[f"d{i}_rad" for i in range(1, 5)]].to_numpy()))),
               alpha_min_deg=float(np.degrees(tr["alpha_rad"].min())),
               alpha_max_deg=float(np.degrees(tr["alpha_rad"].max())),
               seconds=time.perf_counter() - t0)
    return row


def one_c172x(job: tuple) -> dict:
    from aerosid.design.io import read_input
    from aerosid.ebm import process_telemetry
    from aerosid.simulation.jsbsim_flight import simulate_jsbsim
    from aerosid.vehicles.vehicle import load_vehicle

    design_dir, seed = job
    t0 = time.perf_counter()
    table = read_input(Path(design_dir) / "input.parquet") if design_dir else None
    flight = simulate_jsbsim("c172x", "3211", seed=seed, input_table=table)
    row = {"design": str(design_dir or "reference"), "seed": seed}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            run = process_telemetry(flight.telemetry, load_vehicle("c172x"), mach_half_width=None)
    except Exception as exc:
        row["failed"] = f"{type(exc).__name__}: {exc}"
        return row
    tab = run.identification.table().set_index("coefficient")
    for k in ("Cm_q", "Cm_alpha_dot", "Cm_alpha", "Cm_delta_p"):
        truth = flight.coefficients[k]
        est, se = float(tab.loc[k, "estimate"]), float(tab.loc[k, "std_error"])
        row.update({f"{k}_truth": truth, f"{k}_estimate": est, f"{k}_std_error": se,
                    f"{k}_err_pct": 100.0 * (est / truth - 1.0)})
    s = run.identification.fits["Cm"].combination({"Cm_q": 1.0, "Cm_alpha_dot": 1.0})
    truth = flight.coefficients["Cm_q"] + flight.coefficients["Cm_alpha_dot"]
    row["damping_err_pct"] = 100.0 * (s[0] / truth - 1.0)
    row["elevator_max_rad"] = float(np.max(np.abs(flight.truth["d1_rad"] - flight.truth["d1_rad"].iloc[0])))
    row["alpha_min_deg"] = float(np.degrees(flight.truth["alpha_rad"].min()))
    row["alpha_max_deg"] = float(np.degrees(flight.truth["alpha_rad"].max()))
    row["seconds"] = time.perf_counter() - t0
    return row


def oracle_scan(duration_s: float = 90.0, amplitude_rad: float = 0.07, power: str | None = None) -> str:
    """c172x: every candidate shape at one amplitude, noise-free; the default Cm model (1, alpha,
    delta_p, q_hat, alpha_dot_hat, |beta|) fitted to what the gyros see (aerodynamic Cm + the
    propeller's moment) with the true regressors: the model's own error on that manoeuvre.
    power="idle": flown in the power-off glide (throttle_cmd_norm = 0); the table then also
    gives the fit to the aerodynamic Cm alone and the propeller moment's spread."""
    from aerosid.design.flyers import lateral_doublets as _lateral_doublets
    from aerosid.design.waveforms import candidate_waveforms
    from aerosid.simulation.jsbsim_flight import simulate_jsbsim

    t = np.arange(int(round(duration_s / 0.01)) + 1) * 0.01
    extra = _lateral_doublets(t, duration_s - 16.0)
    if power is None:
        rows = [f"c172x oracle scan: {duration_s:g} s, elevator command amplitude {amplitude_rad:g} rad", "",
                "| shape | oracle Cm_q % | oracle Cm_alpha_dot % | load factor | alpha deg |", "|---|---|---|---|---|"]
    else:
        rows = [f"c172x oracle scan, power {power} (throttle_cmd_norm 0: trimmed glide at idle): {duration_s:g} s, "
                f"elevator command amplitude {amplitude_rad:g} rad", "",
                "| shape | oracle Cm_q % (Cm + Cm_prop) | oracle Cm_alpha_dot % (Cm + Cm_prop) | aero Cm only: Cm_q % "
                "| aero Cm only: Cm_alpha_dot % | std Cm_prop / std Cm | load factor | alpha deg |",
                "|---|---|---|---|---|---|---|---|"]
    for w in candidate_waveforms(t, 3.0, duration_s - 16.0, 0.34):
        tab = extra.copy()
        tab["elevator_cmd_rad"] = amplitude_rad * w.values
        if power == "idle":
            tab["throttle_cmd_norm"] = 0.0
        f = simulate_jsbsim("c172x", "3211", seed=0, faults=False, input_table=tab)
        T = f.truth
        X = np.column_stack([np.ones(len(T)), T["alpha_rad"], T["delta_p_rad"], T["q_hat"], T["alpha_dot_hat"],
                             np.abs(T["beta_rad"])])
        th = np.linalg.lstsq(X, T["Cm"].to_numpy() + T["Cm_prop"].to_numpy(), rcond=None)[0]
        c = f.coefficients
        n = -T["az_cg_m_s2"] / 9.80665
        cells = [f"{100 * (th[3] / c['Cm_q'] - 1):+.1f}", f"{100 * (th[4] / c['Cm_alpha_dot'] - 1):+.1f}"]
        if power is not None:
            ta = np.linalg.lstsq(X, T["Cm"].to_numpy(), rcond=None)[0]
            cells += [f"{100 * (ta[3] / c['Cm_q'] - 1):+.1f}", f"{100 * (ta[4] / c['Cm_alpha_dot'] - 1):+.1f}",
                      f"{T['Cm_prop'].std() / T['Cm'].std():.3f}"]
        rows.append(f"| {w.label()} | {' | '.join(cells)}"
                    f" | {n.min():.2f}..{n.max():.2f} | {np.degrees(T.alpha_rad.min()):.1f}.."
                    f"{np.degrees(T.alpha_rad.max()):.1f} |")
    return "\n".join(rows) + "\n"


def _seeds(text: str) -> list[int]:
    out = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b) + 1)) if b else [int(a)]
    return out


def _pct(x: float) -> str:
    return f"{x:+.1f}"


def report() -> str:
    """bench/results/design.md from the recorded runs and designs."""
    lines = ["# Designed manoeuvres flown in simulation (issue 20)", "",
             "`python bench/bench_design.py rlv DES --effect NAME --seeds 1-10` and `... c172x DES --seeds 1-10`; "
             "each design computed once by `aerosid design` from one run of the reference flight (seed 0), then "
             "flown with noise, dropouts, outliers (and the sync gap on seed-rlv) for seeds 1-10 through the whole "
             "pipeline. Per-run rows: `design_runs_*.csv`; the designs: `design_*.json`.", ""]
    for eff in ("pitch_damping", "alpha_nonlinearity"):
        f = RESULTS / f"design_runs_rlv_{eff}.csv"
        if not f.is_file():
            continue
        df = pd.read_csv(f)
        des = json.loads((RESULTS / f"design_rlv_{eff}.json").read_text())
        tgt = des["targets"][0]
        ok = df[df.get("failed", pd.Series([np.nan] * len(df))).isna()] if "failed" in df else df
        m = des["manoeuvre"]
        lines += [f"## seed-rlv, {eff} (truth {df['truth'].iloc[0]:g}), Table 2 noise", "",
                  f"Design: {m['label']}, amplitude {m['amplitude_rad']:.3f} rad of delta_p command "
                  f"({np.degrees(m['amplitude_rad'] / 2):.1f} deg of delta_p/2), {m['start_s']:.1f}-{m['end_s']:.1f} s; "
                  f"limits used (noise-free flight): surface {100 * des['limit_use']['surface']:.0f} %, rate "
                  f"{100 * des['limit_use']['surface_rate']:.0f} %, alpha {100 * des['limit_use']['alpha']:.0f} %, "
                  f"load factor {100 * des['limit_use']['load_factor']:.0f} %.", "",
                  "| | sigma | detectable size |", "|---|---|---|",
                  f"| run (reference flight, seed 0) | {des['before'][tgt]['sigma']:.3g} | "
                  f"{des['before'][tgt]['detectable_size']:.3g} |",
                  f"| design, predicted (one noisy simulated flight) | {des['after'][tgt]['sigma']:.3g} | "
                  f"{des['after'][tgt]['detectable_size']:.3g} |",
                  f"| design, predicted (noise-free regressors, run's residual) | "
                  f"{des['after']['noise_free_run_residual'][tgt]['sigma']:.3g} | "
                  f"{des['after']['noise_free_run_residual'][tgt]['detectable_size']:.3g} |",
                  f"| design flown, seeds 1-10 (median; range) | {ok['std_error'].median():.3g} "
                  f"({ok['std_error'].min():.3g}-{ok['std_error'].max():.3g}) | {ok['detectable_size'].median():.3g} "
                  f"({ok['detectable_size'].min():.3g}-{ok['detectable_size'].max():.3g}) |", "",
                  f"**First and significant: {int(ok['first_and_significant'].sum())}/{len(df)}** "
                  f"(significant {int(ok['significant'].sum())}/{len(df)}; failed runs {len(df) - len(ok)}); estimate "
                  f"{ok['estimate'].mean():.4g} +- {ok['estimate'].std():.3g} (truth {df['truth'].iloc[0]:g}); "
                  f"alpha {ok['alpha_min_deg'].min():.1f}..{ok['alpha_max_deg'].max():.1f} deg.", "",
                  "| seed | rank | top | significant | estimate | sigma | detectable | p | consistency |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for _, r in ok.iterrows():
            lines.append(f"| {r['seed']} | {r['rank']} | {r['top']} | {r['significant']} | {r['estimate']:.4g} | "
                         f"{r['std_error']:.3g} | {r['detectable_size']:.3g} | {r['p_value']:.2g} | "
                         f"{r['window_consistency']:.2f} |")
        lines.append("")
    f = RESULTS / "design_runs_c172x.csv"
    if f.is_file():
        df = pd.read_csv(f)
        des = json.loads((RESULTS / "design_c172x.json").read_text())
        m = des["manoeuvre"]
        lines += ["## c172x (JSBSim): separating Cm_q and Cm_alpha_dot", "",
                  f"Design: {m['label']}, amplitude {m['amplitude_rad']:.3f} rad of elevator command, "
                  f"{m['start_s']:.0f}-{m['end_s']:.0f} s, then an aileron and a rudder doublet; "
                  f"{m['duration_s']:.0f} s. Predicted (one noisy flight): "
                  + ", ".join(f"sigma({t}) {des['after'][t]['sigma']:.3g} (run: {des['before'][t]['sigma']:.3g})"
                              for t in des["targets"]) + ".", "",
                  "| coefficient | mean error % | RMS error % | max abs error % | seeds within 10 % | mean sigma % |",
                  "|---|---|---|---|---|---|"]
        for k in ("Cm_q", "Cm_alpha_dot", "Cm_alpha", "Cm_delta_p"):
            e = df[f"{k}_err_pct"]
            sg = 100 * df[f"{k}_std_error"] / df[f"{k}_truth"].abs()
            lines.append(f"| {k} | {e.mean():+.1f} | {np.sqrt((e ** 2).mean()):.1f} | {e.abs().max():.1f} | "
                         f"{int((e.abs() <= 10).sum())} / {len(df)} | {sg.mean():.1f} |")
        e = df["damping_err_pct"]
        lines.append(f"| Cm_q + Cm_alpha_dot | {e.mean():+.1f} | {np.sqrt((e ** 2).mean()):.1f} | {e.abs().max():.1f} | "
                     f"{int((e.abs() <= 10).sum())} / {len(df)} | |")
        both = int(((df["Cm_q_err_pct"].abs() <= 10) & (df["Cm_alpha_dot_err_pct"].abs() <= 10)).sum())
        failed = df["failed"].dropna() if "failed" in df else pd.Series([], dtype=str)
        lines += ["", f"**Both within 10 %: {both}/{len(df)}**; failed runs {len(failed)}"
                  + "".join(f" (seed {df.loc[i, 'seed']}: {str(m)[:160]}...)" for i, m in failed.items())
                  + ". Reference 3-2-1-1 flight (bench/results/jsbsim.md): Cm_q +10.4 % mean, Cm_alpha_dot "
                  "-14.7 % mean.", ""]
    notes = RESULTS / "design_notes.md"
    if notes.is_file():
        lines += [notes.read_text()]
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("kind", choices=("rlv", "c172x", "report", "oracle-scan"))
    ap.add_argument("design_dir", nargs="?", default="reference",
                    help="a directory written by `aerosid design`, or 'reference'")
    ap.add_argument("--effect", default="pitch_damping")
    ap.add_argument("--scale", type=float, default=1.0)
    ap.add_argument("--seeds", default="0-1")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--tag", default=None)
    ap.add_argument("--power", choices=("idle",), default=None, help="oracle-scan: fly the power-off glide")
    args = ap.parse_args()
    if args.kind == "oracle-scan":
        text = oracle_scan(power=args.power)
        name = "design_c172x_oracle_scan.md" if args.power is None else f"design_c172x_oracle_scan_{args.power}.md"
        (RESULTS / name).write_text(text)
        print(text)
        return
    if args.kind == "report":
        (RESULTS / "design.md").write_text(report())
        print((RESULTS / "design.md").read_text())
        return
    ddir = None if args.design_dir == "reference" else args.design_dir
    seeds = _seeds(args.seeds)
    if args.kind == "rlv":
        jobs, fn = [(ddir, args.effect, args.scale, s) for s in seeds], one_rlv
    else:
        jobs, fn = [(ddir, s) for s in seeds], one_c172x
    t0 = time.perf_counter()
    if args.jobs > 1:
        with ProcessPoolExecutor(args.jobs) as ex:
            rows = list(ex.map(fn, jobs))
    else:
        rows = [fn(j) for j in jobs]
    df = pd.DataFrame(rows)
    tag = args.tag or (f"{args.kind}_{args.effect}" if args.kind == "rlv" else "c172x")
    RESULTS.mkdir(exist_ok=True)
    out = RESULTS / f"design_runs_{tag}.csv"
    df.to_csv(out, index=False, float_format="%.6g")
    if ddir:
        (RESULTS / f"design_{tag}.json").write_text(json.dumps(json.loads((Path(ddir) / "design.json").read_text()),
                                                               indent=1))
    print(df.drop(columns=[c for c in ("reasons",) if c in df]).to_string())
    print(f"wall {time.perf_counter() - t0:.0f} s -> {out}")


if __name__ == "__main__":
    main()
