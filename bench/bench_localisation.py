"""Localisation of effects outside the diagnosis catalogue, on the real pipeline.

Each run simulates seed-rlv with one uncatalogued effect (``aerosid.simulation.hidden``:
a cubic in alpha, a 40 ms pitch-control lag, a drift of Cm_alpha with time) or none,
runs the whole estimation chain (preprocess -> EKF + MBF smoother -> flight data),
diagnoses the default models and reads the diagnosis' ``localisation``:

* ``named``: a finding in the effect's channel names the right shape (alpha**3 or
  another curvature of alpha for the cubic; a lag of delta_p for the lag; a time-like
  trend of Cm_alpha -- t, or Mach/qbar listed as indistinguishable from t -- for the
  drift) and is the channel's first finding or at least a significant one;
* ``model_err_before/after``: RMS(model on the TRUE signals - TRUE coefficient) over
  the regression window for the default model and for the default model plus the
  suggested expression of the finding that named it (what "the error falls" means
  when the truth is known; the measured residual cannot fall below the floor);
* on no-effect flights: the number of localisation findings (false findings).

The slow part (simulate + estimation chain, ~2 min per run) is cached in
``--cache`` (flight data + truth as Parquet), so the analysis can be rerun.

    python bench/bench_localisation.py --seeds 0-9 --jobs 2
    -> bench/results/localisation_runs.csv and bench/results/localisation.md
    (--effects pitch_control_lag=2,none: an effect at twice its default size; --label NAME:
    localisation_NAME.md and _runs.csv)
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from datetime import date
from pathlib import Path

import numpy as np
import pandas as pd

EFFECTS = ("alpha_cubic", "pitch_control_lag", "cm_alpha_drift")
CACHE = Path(os.environ.get("AEROSID_BENCH_CACHE", "/tmp/aerosid_bench_localisation"))


def _rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def flight(job: tuple[str, int, str]) -> tuple[str, int, float]:
    """Simulate + estimation chain for (effect, seed), cached as Parquet."""
    name, seed, cache = job
    out = Path(cache) / f"{name}_s{seed}"
    if (out / "done").exists():
        return name, seed, 0.0
    from aerosid.ebm import process_telemetry
    from aerosid.simulation import load_case, simulate
    from aerosid.simulation.hidden import HIDDEN

    t0 = time.perf_counter()
    case = load_case("seed-rlv")
    if name == "none":
        hidden = ()
    else:
        effect, scale = _effect(name)
        hidden = ((HIDDEN[effect], scale),)
    f = simulate(case, (), seed=seed, hidden=hidden)
    run = process_telemetry(f.telemetry, case.vehicle)
    fd = run.flight_data.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    out.mkdir(parents=True, exist_ok=True)
    fd.to_parquet(out / "flight_data.parquet")
    f.truth.to_parquet(out / "truth.parquet")
    import json

    (out / "truth.json").write_text(json.dumps(f.truth_document(), default=float))
    (out / "done").write_text("ok")
    return name, seed, time.perf_counter() - t0


def _effect(name: str) -> tuple[str, float]:
    """``NAME`` or ``NAME=SCALE`` (the effect at SCALE times its default size) -> (NAME, SCALE)
    (aerosid.simulation.hidden.parse_hidden_spec: an unknown name or a bad scale is refused)."""
    from aerosid.simulation.hidden import parse_hidden_spec

    effect, scale = parse_hidden_spec(name)
    return effect.name, scale


def _named(name: str, findings: list[dict]) -> dict | None:
    """The finding that names the hidden effect's regressor or shape, if any."""
    name = _effect(name)[0]
    for f in findings:
        if name == "alpha_cubic" and f["kind"] == "shape" and f["variable"] == "alpha":
            return f
        if name == "pitch_control_lag" and f["kind"] == "lag" and f["variable"] == "delta_p":
            return f
        if name == "cm_alpha_drift" and f["kind"] == "trend" and f.get("coefficient") == "Cm_alpha" and (
                f["variable"] == "t" or "trend:Cm_alpha:t" in f.get("confused_with", ())):
            return f
    return None


def analyse(name: str, seed: int, cache: str) -> dict:
    import json

    from aerosid.diagnosis import diagnose
    from aerosid.diagnosis.synthetic import NO_NOISE, flight_data_from_truth
    from aerosid.identification.identify import identify, mach_window_mask
    from aerosid.modelling.models import default_models, parse_term, signals_from_flight_data
    from aerosid.vehicles.vehicle import load_vehicle

    d_in = Path(cache) / f"{name}_s{seed}"
    fd = pd.read_parquet(d_in / "flight_data.parquet")
    truth_all = pd.read_parquet(d_in / "truth.parquet")
    vehicle = load_vehicle("seed-rlv")
    t0 = time.perf_counter()
    d = diagnose(fd, vehicle)
    loc = {ch: [f.to_dict() for f in fs] for ch, fs in d.localisation.items()}
    n_findings = sum(len(v) for v in loc.values())
    n_sig = sum(f["significant"] for v in loc.values() for f in v)
    row = {"effect": name, "seed": seed, "n_findings": n_findings, "n_significant_findings": n_sig,
           "findings": " | ".join(f"{f['channel']}:{f['kind']}:{f['variable']}{'*' if f['significant'] else ''}"
                                  f"->{f['suggested_expression']}" for v in loc.values() for f in v),
           "catalogue_top": d.top.name if d.effects else "", "catalogue_significant": bool(d.significant),
           "diagnose_s": time.perf_counter() - t0}
    if name == "none":
        return row
    doc = json.loads((d_in / "truth.json").read_text())
    h = doc["hidden_effects"][0]
    ch = h["channel"]
    chan = loc.get(ch, [])
    hit = _named(name, [f for f in chan if f["significant"]])
    first = chan[0] if chan else None
    top = _named(name, chan[:1])  # the channel's strongest finding names it, significant or not
    row.update(channel=ch, named=hit is not None, named_first=bool(hit is not None and first is hit),
               named_strongest_any=top is not None,
               first_finding=(f"{first['kind']}:{first['variable']}" if first else ""),
               suggested=hit["suggested_expression"] if hit else "", p_value=hit["p_value"] if hit else np.nan,
               message=hit["message"] if hit else "")
    row["lag_truth_ms"] = 1e3 * h["lag_s"] if "lag_s" in h else np.nan
    if hit and hit["kind"] == "lag":
        row["lag_ms"] = 1e3 * hit["evidence"]["lag_s"]
        row["lag_scan_ms"] = 1e3 * hit["evidence"]["lag_scan_s"]
    if hit and hit["kind"] == "trend":
        row["drift_pct_per_min"] = hit["evidence"].get("change_pct_per_min", np.nan)
    # model error against the truth, before and after adding the suggested expression
    window = fd.loc[mach_window_mask(fd["mach"].to_numpy(), vehicle.mach_reference, 0.5)].reset_index(drop=True)
    truth = truth_all.set_index(np.round(truth_all["t_s"], 6)).loc[np.round(window["t_s"], 6)].reset_index(drop=True)
    true_c = truth[ch].to_numpy(float)
    true_signals = signals_from_flight_data(flight_data_from_truth(truth, NO_NOISE), vehicle.d_m)
    row["floor"] = _rms(window[ch].to_numpy(float) - true_c)
    models = dict(default_models())
    variants = {"before": models}
    # the suggested expression of the naming finding, else of the channel's first finding
    use = hit or first
    if use is not None:
        aug = dict(models)
        aug[ch] = models[ch].with_term(parse_term(use["spec_line"], ch))
        variants["after"] = aug
    true_term = dict(models)
    true_term[ch] = models[ch].with_term(parse_term(f"{h['coefficient']} = {h['term']}", ch))
    variants["true_term"] = true_term
    for tag, ms in variants.items():
        ident = identify(fd, vehicle, ms, bias_pairs=0)  # as recorded
        fit = ident.fits[ch]
        X = ident.models[ch].regressors(true_signals).to_numpy(float)
        ok = np.all(np.isfinite(X), axis=1)
        on_truth = X[ok] @ np.nan_to_num(fit.estimate)
        row[f"model_err_{tag}"] = _rms(on_truth - true_c[ok])
        if tag == "true_term":
            row["true_term_estimate"] = float(fit.estimate[-1])
            row["true_term_truth"] = float(h["coefficient_value"])
    if "model_err_after" in row:
        row["model_err_drop"] = 1 - row["model_err_after"] / row["model_err_before"]
    row["model_err_drop_true_term"] = 1 - row["model_err_true_term"] / row["model_err_before"]
    return row


def _analyse_job(job):
    return analyse(*job)


def _report(df: pd.DataFrame, seeds: list[int], wall_s: float, stem: str = "localisation",
            command: str = "") -> str:
    sys.path.insert(0, str(Path(__file__).parent))
    from machine import cpu_model, loadavg

    n = len(seeds)
    lines = [f"# Localisation of uncatalogued effects on the real pipeline, {n} seeds per row", "",
             f"{date.today()}, {cpu_model()}, {os.cpu_count()} cores, load {loadavg()}; analysis wall "
             f"{wall_s / 60:.1f} min (simulation + estimation chain cached). "
             f"`python bench/bench_localisation.py --seeds {seeds[0]}-{seeds[-1]}{command}`.", "",
             "Each run: simulate seed-rlv with one effect that is NOT a diagnosis candidate "
             "(`aerosid simulate --hidden NAME`; Table 2 noise, dropouts, outliers, sync gap), preprocess, "
             "EKF + MBF smoother, flight data, `diagnose` the default models, read `localisation`. "
             "`named`: a significant localisation finding in the channel names the right regressor or shape "
             "(cubic: a curvature of alpha; lag: a lag of delta_p; drift: Cm_alpha trending with t, or with "
             "Mach/qbar when the finding lists t as indistinguishable). `model error` = RMS(model on the true "
             "signals - true coefficient) over |M - 12.4| <= 0.5, default model -> default + the suggested "
             "expression; `true term` = default + the effect's own first-order term, for comparison.", "",
             "`named first`: that finding is the channel's first; `strongest names it`: the channel's strongest "
             "finding names it, significant or not (the hint an engineer gets when the rule is not passed).", "",
             "| effect | size (std ratio) | named | named first | strongest names it | suggested (most frequent) "
             "| corrected p (median over named runs) "
             "| model error before -> after (drop mean, min) | with the true term (drop) | floor | catalogue: "
             "something significant |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    eff = df[df["effect"] != "none"]
    for name, g in eff.groupby("effect", sort=False):
        sug = g.loc[g["suggested"].astype(str) != "", "suggested"]
        sug_txt = f"`{sug.value_counts().index[0]}` ({sug.value_counts().iloc[0]})" if len(sug) else "-"
        after = g["model_err_drop"].dropna() if "model_err_drop" in g else pd.Series(dtype=float)
        lines.append(
            f"| {name} | {g['size_ratio'].mean():.1%} | {int(g['named'].sum())}/{len(g)} "
            f"| {int(g['named_first'].sum())}/{len(g)} | {int(g['named_strongest_any'].sum())}/{len(g)} "
            f"| {sug_txt} | {g['p_value'].median():.2g} "
            f"| {g['model_err_before'].mean():.2e} -> {g['model_err_after'].mean():.2e} "
            f"({after.mean():.0%}, min {after.min():.0%}) "
            f"| {g['model_err_true_term'].mean():.2e} ({g['model_err_drop_true_term'].mean():.0%}) "
            f"| {g['floor'].mean():.2e} | {int(g['catalogue_significant'].sum())}/{len(g)} |")
    for name, lag in eff.groupby("effect", sort=False):
        if _effect(name)[0] != "pitch_control_lag" or "lag_ms" not in lag or not lag["lag_ms"].notna().any():
            continue
        which = "" if name == "pitch_control_lag" else f" of {name}"
        lines += ["", f"Lag estimates over the named runs{which} (truth {lag['lag_truth_ms'].iloc[0]:.0f} ms): "
                      f"derivative fit {lag['lag_ms'].mean():.1f} ± {lag['lag_ms'].std():.1f} ms, "
                      f"shift scan {lag['lag_scan_ms'].mean():.1f} ± {lag['lag_scan_ms'].std():.1f} ms."]
    for name, dr in eff.groupby("effect", sort=False):
        if _effect(name)[0] != "cm_alpha_drift" or "drift_pct_per_min" not in dr \
                or not dr["drift_pct_per_min"].notna().any():
            continue
        k = _effect(name)[1]
        which = "" if name == "cm_alpha_drift" else f" of {name}"
        lines += ["", f"Drift estimates over the runs{which} that named t (truth {-8 * k:.0f} % over 90 s = "
                      f"{-5.3 * k:.1f} %/min of Cm_alpha): "
                      f"{dr['drift_pct_per_min'].mean():.1f} ± {dr['drift_pct_per_min'].std():.1f} %/min."]
    none = df[df["effect"] == "none"]
    if len(none):
        lines += ["", f"No hidden effect ({len(none)} flights): significant localisation findings in "
                      f"{int((none['n_significant_findings'] > 0).sum())}/{len(none)} flights "
                      f"({int(none['n_significant_findings'].sum())} in all; listed, not significant: "
                      f"{int(none['n_findings'].sum() - none['n_significant_findings'].sum())})."]
        fp = none.loc[none["n_significant_findings"] > 0, ["seed", "findings"]]
        for _, r in fp.iterrows():
            lines.append(f"* seed {r['seed']}: {r['findings']}")
    lines += ["", f"Per-run rows: `bench/results/{stem}_runs.csv`."]
    return "\n".join(lines) + "\n"


def _seeds(text: str) -> list[int]:
    a, _, b = text.partition("-")
    return list(range(int(a), int(b) + 1)) if b else [int(a)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--effects", default=",".join(EFFECTS) + ",none")
    ap.add_argument("--cache", default=str(CACHE))
    ap.add_argument("--flights-only", action="store_true", help="only simulate + run the chain (fill the cache)")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results"))
    ap.add_argument("--label", default="", help="write localisation_LABEL.md and _runs.csv (not the bench's own)")
    args = ap.parse_args()
    seeds = _seeds(args.seeds)
    names = args.effects.split(",")
    for n in names:  # refused here, not inside a worker
        if n != "none":
            _effect(n)
    jobs = [(n, s, args.cache) for s in seeds for n in names]
    with ProcessPoolExecutor(args.jobs) as pool:
        for n, s, sec in pool.map(flight, jobs):
            print(f"flight {n} seed {s}: {sec:.0f} s", flush=True)
    if args.flights_only:
        return
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(_analyse_job, [(n, s, args.cache) for n in names for s in seeds]))
    df = pd.DataFrame(rows)
    df["size_ratio"] = [_size(r["effect"], r["seed"], args.cache) for _, r in df.iterrows()]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = f"localisation_{args.label}" if args.label else "localisation"
    df.to_csv(out / f"{stem}_runs.csv", index=False)
    command = (f" --effects {args.effects}" if args.effects != ap.get_default("effects") else "") + (
        f" --label {args.label}" if args.label else "")
    text = _report(df, seeds, time.perf_counter() - t0, stem, command)
    (out / f"{stem}.md").write_text(text)
    print(text)
    print(platform.platform())


def _size(name: str, seed: int, cache: str) -> float:
    """std of the effect's contribution / std of the true Cm over the regression window."""
    if name == "none":
        return float("nan")
    from aerosid.simulation import flight_model, load_case

    tr = pd.read_parquet(Path(cache) / f"{name}_s{seed}" / "truth.parquet")
    m = ((tr["mach"] - 12.4).abs() <= 0.5).to_numpy()
    c = flight_model(load_case("seed-rlv")).coefficients(
        tr["alpha_r_rad"], tr["phi_r_rad"], tr["mach"], tr["delta_p_rad"], tr["delta_y_rad"], tr["delta_r_rad"],
        tr["p_rad_s"], tr["q_rad_s"], tr["r_rad_s"], tr["V_m_s"], tr["qbar_pa"])
    contrib = (tr["Cm"] - c["Cm"]).to_numpy()[m]
    return float(np.std(contrib) / np.std(tr["Cm"].to_numpy()[m]))


if __name__ == "__main__":
    main()
