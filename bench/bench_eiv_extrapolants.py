"""How much of the vane noise's attenuation does SIMEX recover?  A controlled test.

    python bench/bench_eiv_extrapolants.py [--vehicles c172p,sgs126,...] [--seeds 0-2]
    -> bench/results/eiv_extrapolants.md and bench/results/eiv_extrapolants_runs.csv

Per (vehicle, seed), on the attribution bench's cached flight (bench/attribution_cache.py: the
pipeline's flight data and the JSBSim truth), the C_m channel's default model is fitted four ways
on a flight whose only angle error is known exactly:

  clean     the flight data with alpha and beta replaced by the noise-free truth passed through
            the band's low-pass (every other column as the pipeline made it): the answer an
            errors-in-variables correction should reach;
  renoised  the same, with one fresh draw of the vanes' noise (the flight data's
            eiv_sigma_alpha_rad, eiv_sigma_beta_rad, through the same low-pass, as SIMEX draws it)
            added to the clean angles: naive least squares, attenuated;
  quadratic SIMEX on the renoised flight as aerosid.identification.eiv corrects the angles (its own
            draws, eiv.simex_frames at the source's levels identify uses, eiv_fit.simex_lambdas:
            lambda 0.25..1 for vanes, 0.5..2 for inverted angles; 40 replicates in antithetic pairs,
            the quadratic extrapolant; on the Mach window, cut first);
  moment    the exact extrapolant for linear columns: X^T X and X^T y averaged over the same
            replicates, extrapolated linearly to lambda = -1, then solved (corrected least squares).

recovered = (quadratic - renoised) / (clean - renoised): the share of the attenuation SIMEX
takes back; shortfall/correction = (clean - quadratic) / (quadratic - renoised).  Errors are %
of the linear truth (C_m_alpha, C_m_delta_p, damping = C_m_q + C_m_alpha_dot).  No gyro noise is
added (the rates are the flight's own in every variant).

--rlv-seeds: the same on seed-rlv (angles inverted from the force database; the noise SIMEX
draws for them, per sample, through the band), simulated and estimated here, every non-constant
term of its C_m, C_n and C_l models, quadratic only; the table gives medians over the seeds.
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
import warnings
from datetime import date
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
import attribution_cache  # noqa: E402
from bench_accuracy import parse_seeds  # noqa: E402
from bench_attribution import band_limited_truth, targets, truth_targets  # noqa: E402

TARGETS = ("Cm_alpha", "Cm_delta", "damping")


def _fits(frame: pd.DataFrame, vehicle, corrected: bool = True) -> dict[str, np.ndarray]:
    """naive (and, with `corrected`, quadratic SIMEX and moment-corrected) estimates of the default
    C_m model on the frame's Mach window (cut first, as identify does: the derivatives, the noise
    draws and their low-pass see the same rows)."""
    from aerosid.identification.eiv import REPLICATES, SimexResult, noise_free_gram, simex_frames
    from aerosid.identification.eiv_fit import angle_cutoff_hz, simex_lambdas
    from aerosid.identification.identify import mach_window_mask
    from aerosid.modelling.models import default_models, vehicle_signals

    model = default_models(vehicle)["Cm"]
    f0 = frame.loc[mach_window_mask(frame["mach"].to_numpy(float), vehicle.mach_reference, 0.5)]
    f0 = f0.reset_index(drop=True)
    y = f0["Cm"].to_numpy(float)

    def design(f):
        return model.regressors(vehicle_signals(f, vehicle)).to_numpy(float)

    X0 = design(f0)
    ok = np.all(np.isfinite(X0), axis=1) & np.isfinite(y)
    naive = np.linalg.lstsq(X0[ok], y[ok], rcond=None)[0]
    if not corrected:
        return {"naive": naive, "names": list(model.names)}
    sig = (f0["eiv_sigma_alpha_rad"].to_numpy(float), f0["eiv_sigma_beta_rad"].to_numpy(float))
    cut = angle_cutoff_hz(f0, vehicle)
    if not np.all(np.isfinite(np.concatenate(sig))):
        raise ValueError("the flight data's eiv_sigma_alpha_rad/eiv_sigma_beta_rad have non-finite values")
    lambdas = simex_lambdas(vehicle)
    sums = {lam: [0.0, 0.0, 0.0] for lam in lambdas}  # X^T X, X^T y, estimate: summed over the replicates
    for lam, f in simex_frames(f0, sig, cut, lambdas=lambdas):  # identify's own draws (antithetic common random numbers)
        X = design(f)[ok]
        for i, part in enumerate((X.T @ X, X.T @ y[ok], np.linalg.lstsq(X, y[ok], rcond=None)[0])):
            sums[lam][i] = sums[lam][i] + part
    M = [X0[ok].T @ X0[ok], *(sums[lam][0] / REPLICATES for lam in lambdas)]
    v = [X0[ok].T @ y[ok], *(sums[lam][1] / REPLICATES for lam in lambdas)]
    th = [naive, *(sums[lam][2] / REPLICATES for lam in lambdas)]
    lams = np.array((0.0, *lambdas))
    M, v, th = np.array(M), np.array(v), np.array(th)
    M1 = noise_free_gram(lams, M)  # X^T X on its line to lambda = -1, as identify's information measures
    v1 = np.array([-1.0, 1.0]) @ np.linalg.lstsq(np.vander(lams, 2), v, rcond=None)[0]  # X^T y: the same line
    return {"naive": naive, "quadratic": SimexResult.from_curve(lams, th).corrected,
            "moment": np.linalg.solve(M1, v1), "names": list(model.names)}


def one(vehicle: str, seed: int) -> list[dict]:
    from aerosid.identification.band import segment_keys
    from aerosid.identification.eiv import with_angle_noise, with_angles_moved
    from aerosid.identification.eiv_fit import angle_cutoff_hz

    data = attribution_cache.load(vehicle, seed)
    fd, T, veh = data["flight_data"], data["truth"], data["vehicle_obj"]
    truth = truth_targets(data["coefficients"])
    lp = band_limited_truth(data, {"alpha": T["alpha_rad"], "beta": T["beta_rad"]})
    order = np.lexsort((fd["t_s"].to_numpy(float), fd["flight"].astype(str).to_numpy()))
    # the true angles in the flight data's own row order (alpha_r, phi_r recomputed), then sorted
    clean = with_angles_moved(fd, lp["alpha"] - fd["alpha_rad"].to_numpy(float),
                              lp["beta"] - fd["beta_rad"].to_numpy(float))
    clean = clean.iloc[order].reset_index(drop=True)
    sig = (clean["eiv_sigma_alpha_rad"].to_numpy(float), clean["eiv_sigma_beta_rad"].to_numpy(float))
    renoised = with_angle_noise(clean, np.random.default_rng(1000 + seed), segment_keys(clean), sig,
                                angle_cutoff_hz(clean, veh))
    c = _fits(clean, veh, corrected=False)
    r = _fits(renoised, veh)
    rows = []
    for tag, b in (("clean", c["naive"]), ("renoised", r["naive"]), ("quadratic", r["quadratic"]),
                   ("moment", r["moment"])):
        est = targets(dict(zip(c["names"], b)))
        rows.append({"vehicle": vehicle, "seed": seed, "fit": tag,
                     **{f"{k}_pct": 100 * (est[k] / truth[k] - 1) for k in TARGETS}})
    return rows


def _shortfall_ratio(clean, quadratic, renoised):
    """shortfall / correction = (clean - quadratic) / (quadratic - renoised), signed."""
    return (clean - quadratic) / (quadratic - renoised)


def report(df: pd.DataFrame, wall_s: float, command: str) -> str:
    sys.path.insert(0, str(Path(__file__).parent))
    from machine import cpu_model

    lines = ["# How much of the angle noise's attenuation SIMEX recovers (a controlled test)", "",
             f"{date.today()}, {cpu_model()}, Python {platform.python_version()}, wall {wall_s / 60:.1f} min; "
             f"`{command}`.  Definitions: bench/bench_eiv_extrapolants.py (docstring).  Mean error % of the "
             "linear truth over the seeds (the seeds' spread, 1 sd).", "",
             "## JSBSim aircraft: vane angles", ""]
    piv = df.pivot_table(index=["vehicle", "seed"], columns="fit", values=[f"{k}_pct" for k in TARGETS])
    lines += ["| vehicle | coefficient | clean | renoised | quadratic (SIMEX) | moment (exact extrapolant) "
              "| recovered by SIMEX | shortfall / correction |", "|---|---|---|---|---|---|---|---|"]
    ratios = []  # abs(shortfall / correction) of every run attenuated by >= 3 %
    for v in df["vehicle"].unique():
        for k in TARGETS:
            p = piv.loc[v][f"{k}_pct"]
            rec = (p["quadratic"] - p["renoised"]) / (p["clean"] - p["renoised"])
            short = _shortfall_ratio(p["clean"], p["quadratic"], p["renoised"])
            cell = lambda s: f"{s.mean():+.1f} ({s.std():.1f})"  # noqa: E731
            big = (p["clean"] - p["renoised"]).abs() >= 3.0  # attenuation of 3 % or more: ratios meaningful
            lines.append(f"| {v} | {k} | {cell(p['clean'])} | {cell(p['renoised'])} | {cell(p['quadratic'])} | "
                         f"{cell(p['moment'])} | "
                         + (f"{rec[big].median():.0%} ({int(big.sum())} runs)" if big.any() else "-") + " | "
                         + (f"{short[big].median():.2f}" if big.any() else "-") + " |")
            ratios += list(short[big].abs())
    r = pd.Series(ratios)
    lines += ["", "recovered / shortfall: medians over the runs whose attenuation (clean - renoised) is at least "
              "3 % of the truth.", "",
              f"Over all {len(r)} such runs: abs(shortfall / correction) median {r.median():.2f}, 68th percentile "
              f"{r.quantile(0.68):.2f}, above 1 in {(r > 1).mean():.0%}, above 2 in {(r > 2).mean():.0%}.", "",
              "Per-run rows: `bench/results/eiv_extrapolants_runs.csv`."]
    return "\n".join(lines) + "\n"


def rlv_rows(seed: int) -> list[dict]:
    """The controlled test on one seed-rlv flight (aerosid's own simulator, inverted angles)."""
    from aerosid.ebm import estimate_flight_data
    from aerosid.identification.band import segment_keys
    from aerosid.identification.derivatives import zero_phase_low_pass
    from aerosid.identification.eiv import simex_estimates, with_angle_noise, with_angles_moved
    from aerosid.identification.eiv_fit import angle_cutoff_hz, simex_lambdas
    from aerosid.identification.identify import mach_window_mask
    from aerosid.modelling.models import default_models, vehicle_signals
    from aerosid.simulation import load_case, simulate

    case = load_case("seed-rlv")
    veh = case.vehicle
    flight = simulate(case, (), seed=seed)
    fd = estimate_flight_data(flight.telemetry, veh).flight_data
    fd = fd.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    tr = flight.truth
    tt = tr["t_s"].to_numpy(float)
    t = fd["t_s"].to_numpy(float)
    true_a, true_b = np.full(len(fd), np.nan), np.full(len(fd), np.nan)
    groups = segment_keys(fd)
    for g in pd.unique(groups):  # the band's low-pass over the segment's span of the (gap-free) truth grid
        i = np.flatnonzero(groups == g)
        on = (tt >= t[i].min()) & (tt <= t[i].max())
        fs, band = 1.0 / float(np.median(np.diff(tt[on]))), float(np.median(fd["band_hz"].to_numpy()[i]))
        true_a[i] = np.interp(t[i], tt[on], zero_phase_low_pass(tr["alpha_rad"].to_numpy(float)[on], fs, band))
        true_b[i] = np.interp(t[i], tt[on], zero_phase_low_pass(tr["beta_rad"].to_numpy(float)[on], fs, band))
    clean = with_angles_moved(fd, true_a - fd["alpha_rad"].to_numpy(), true_b - fd["beta_rad"].to_numpy())
    keep = mach_window_mask(fd["mach"].to_numpy(), veh.mach_reference, 0.5)
    fd, clean = fd.loc[keep].reset_index(drop=True), clean.loc[keep].reset_index(drop=True)
    groups = segment_keys(fd)
    sig = (fd["eiv_sigma_alpha_rad"].to_numpy(float), fd["eiv_sigma_beta_rad"].to_numpy(float))
    cut = angle_cutoff_hz(fd, veh)
    renoised = with_angle_noise(clean, np.random.default_rng(500 + seed), groups, sig, cut)
    models = default_models(veh)
    chans = [c for c in ("Cm", "Cn", "Cl") if c in models]

    def design(frame):
        s = vehicle_signals(frame, veh)
        return {c: models[c].regressors(s).to_numpy(float) for c in chans}

    X_clean = design(clean)
    res = simex_estimates(renoised, {c: renoised[c].to_numpy(float) for c in chans}, design, sig, cut,
                          lambdas=simex_lambdas(veh))
    rows = []
    for c in chans:
        y = clean[c].to_numpy(float)
        ok = np.all(np.isfinite(X_clean[c]), axis=1) & np.isfinite(y)
        b_clean = np.linalg.lstsq(X_clean[c][ok], y[ok], rcond=None)[0]
        for j, name in enumerate(models[c].names):
            if name.endswith("_0"):
                continue
            r = res[c]
            rows.append({"seed": seed, "coefficient": name, "clean": b_clean[j], "renoised": r.naive[j],
                         "quadratic": r.corrected[j], "spread": r.spread[j]})
    return rows


def rlv_report(df: pd.DataFrame, share: float) -> str:
    d = df.copy()
    d["attenuation_pct"] = 100 * (d["clean"].abs() - d["renoised"].abs()) / d["clean"].abs()
    d["recovered"] = (d["quadratic"] - d["renoised"]) / (d["clean"] - d["renoised"])
    d["ratio"] = _shortfall_ratio(d["clean"], d["quadratic"], d["renoised"]).abs()
    d["z_spread"] = (d["quadratic"] - d["clean"]).abs() / d["spread"]
    d["z_share"] = (d["quadratic"] - d["clean"]).abs() / np.maximum(d["spread"], share * (d["quadratic"] - d["renoised"]).abs())
    big = d["attenuation_pct"].abs() >= 3.0
    lines = ["", f"## seed-rlv: angles inverted from the force database ({d['seed'].nunique()} seeds)", "",
             "Medians per coefficient over the seeds; the ratio columns over the runs whose attenuation is at least "
             "3 % (their count in brackets). abs(shortfall / correction) = abs(clean - quadratic) / abs(quadratic - "
             f"renoised); z = abs(quadratic - clean) over the spread alone, and over the larger of the spread and "
             f"{share:g} x the correction (eiv.CORRECTION_SHARE['database']).", "",
             "| coefficient | attenuation by the noise [% of clean] | recovered by SIMEX | abs(shortfall / correction) "
             "| z, spread alone | z, adopted |", "|---|---|---|---|---|---|"]
    for name, g in d.groupby("coefficient", sort=False):
        b = g[big.loc[g.index]]
        ratio = f"{b['ratio'].median():.2f} ({len(b)})" if len(b) else "-"
        rec = f"{b['recovered'].median():.0%}" if len(b) else "-"
        lines.append(f"| {name} | {g['attenuation_pct'].median():+.1f} | {rec} | {ratio} | {g['z_spread'].median():.2f} "
                     f"| {g['z_share'].median():.2f} |")
    r = d.loc[big, "ratio"]
    lines += ["", f"Over all {len(r)} runs attenuated by >= 3 %: abs(shortfall / correction) median {r.median():.2f}, "
                  f"68th percentile {r.quantile(0.68):.2f}, above 1 in {(r > 1).mean():.0%}.",
              "", "Per-run rows: `bench/results/eiv_extrapolants_rlv_runs.csv`."]
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", default="c172x,pa28,OV10,T37,F4N,c172p,c182,sgs126,minisgs,J3Cub")
    ap.add_argument("--seeds", default="0-2")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results"))
    ap.add_argument("--rlv-seeds", default="0-4", help="seed-rlv flights for the inverted angles ('' to skip)")
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    t0 = time.perf_counter()
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for v in args.vehicles.split(","):
            for s in seeds:
                if not attribution_cache.cache_path(v, s).exists():
                    attribution_cache.build(v, s)
                rows += one(v, s)
                print(f"{v} seed {s}", flush=True)
        rlv = [r for s in (parse_seeds(args.rlv_seeds) if args.rlv_seeds else []) for r in rlv_rows(s)]
    df = pd.DataFrame(rows)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    df.to_csv(out / "eiv_extrapolants_runs.csv", index=False)
    text = report(df, time.perf_counter() - t0,
                  f"python bench/bench_eiv_extrapolants.py --vehicles {args.vehicles} --seeds {args.seeds} "
                  f"--rlv-seeds {args.rlv_seeds}")
    if rlv:
        pd.DataFrame(rlv).to_csv(out / "eiv_extrapolants_rlv_runs.csv", index=False)
        from aerosid.identification.eiv import CORRECTION_SHARE

        text += rlv_report(pd.DataFrame(rlv), CORRECTION_SHARE["database"])
    (out / "eiv_extrapolants.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
