"""Accuracy and interval coverage over many seeds of the seed-rlv reference flight
(no hidden effect, default noise and dropouts).  Records per seed: coefficient
errors, whether the corrected and the plain-OLS 95 % intervals cover the truth,
alpha/beta inversion RMS errors, smoothed-state RMS errors, R sigma errors, NIS.

    python bench/bench_accuracy.py --seeds 0-29 [--jobs 2]
    -> bench/results/accuracy_seeds.csv and bench/results/accuracy.md
"""
from __future__ import annotations

import argparse
import os
import platform
from concurrent.futures import ProcessPoolExecutor
from datetime import date
from pathlib import Path

import numpy as np
import pandas as pd

PITCH = ("CN_alpha", "CN_delta_p", "Cm_alpha", "Cm_delta_p", "CN_0", "Cm_0")
OTHER = ("CY_beta", "CY_delta_y", "Cn_beta", "Cn_delta_y", "Cl_0", "Cl_alpha_r", "Cl_cos4phi", "Cl_delta_r")
NOISE = np.array([0.8, 1.0, 2.0, *np.deg2rad([4.0, 2.0, 1.0])])


def one(seed: int) -> dict:
    from aerosid.ebm import process_telemetry
    from aerosid.simulation import load_case, simulate

    case = load_case("seed-rlv")
    flight = simulate(case, seed=seed)
    run = process_telemetry(flight.telemetry, case.vehicle)
    tab = run.identification.table().set_index("coefficient")
    row = {"seed": seed}
    for name in PITCH + OTHER:
        truth, r = flight.coefficients[name], tab.loc[name]
        row[f"{name}_err_pct"] = 100 * (r.estimate / truth - 1) if truth else np.nan
        row[f"{name}_z"] = (r.estimate - truth) / r.std_error
        row[f"{name}_cover"] = bool(r.ci_low <= truth <= r.ci_high)
        half_ols = (r.ci_high - r.ci_low) / 2 * r.std_error_ols / r.std_error
        row[f"{name}_cover_ols"] = bool(abs(r.estimate - truth) <= half_ols)
    fd = run.flight_data
    tr = flight.truth.set_index(np.round(flight.truth["t_s"], 6))
    t = tr.loc[np.round(fd["t_s"], 6)]
    near = (fd["mach"] - 12.4).abs().to_numpy() <= 0.5
    row["alpha_rms_deg"] = float(np.rad2deg(np.sqrt(np.mean((fd["alpha_rad"].to_numpy() - t["alpha_rad"].to_numpy())[near] ** 2))))
    row["beta_rms_deg"] = float(np.rad2deg(np.sqrt(np.mean((fd["beta_rad"].to_numpy() - t["beta_rad"].to_numpy())[near] ** 2))))
    sm = pd.concat([s.frame for s in run.smoothed], ignore_index=True)
    ts = tr.loc[np.round(sm["t_s"], 6)]
    for est, tru in (("q_rad_s", "q_rad_s"), ("q_dot_rad_s2", "q_dot_rad_s2"), ("X1_m_s2", "ax_cg_m_s2"),
                     ("Y1_m_s2", "ay_cg_m_s2"), ("Z1_m_s2", "az_cg_m_s2")):
        row[f"rms_{est}"] = float(np.sqrt(np.mean((sm[est].to_numpy() - ts[tru].to_numpy()) ** 2)))
    rs = np.array([s.result.R_sigma for s in run.smoothed])
    w = np.array([len(s.frame) for s in run.smoothed], float)
    r_sigma = (rs * w[:, None]).sum(0) / w.sum()
    for j, ch in enumerate(("ax", "ay", "az", "p", "q", "r")):
        row[f"R_sigma_err_pct_{ch}"] = 100 * (r_sigma[j] / NOISE[j] - 1)
    row["nis_filter"] = float(np.average([s.result.mean_nis_filter for s in run.smoothed], weights=w))
    row["nis_smoother"] = float(np.average([s.result.mean_nis_smoother for s in run.smoothed], weights=w))
    row["nis_in_band"] = all(s.result.nis_band[0] <= s.result.mean_nis_smoother <= s.result.nis_band[1] for s in run.smoothed)
    row["inversion_J_max"] = float(fd["inversion_J"].max())
    return row


def parse_seeds(text: str) -> list[int]:
    out = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out.extend(range(int(a), int(b) + 1) if b else [int(a)])
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="0-29")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(one, seeds))
    df = pd.DataFrame(rows).sort_values("seed")
    out = Path(__file__).parent / "results"
    df.to_csv(out / "accuracy_seeds.csv", index=False, float_format="%.6g")
    lines = [f"# Accuracy over {len(df)} seeds of the seed-rlv reference flight", "",
             f"{date.today()}, Python {platform.python_version()}, {os.cpu_count()} cores; "
             "no hidden effect, default noise, dropouts, outliers and sync gap; regression on |M - 12.4| <= 0.5.", "",
             "| coefficient | mean error % | RMS error % | max abs error % | 95 % coverage (corrected) | coverage (plain OLS) |",
             "|---|---|---|---|---|---|"]
    for name in PITCH + OTHER:
        e = df[f"{name}_err_pct"]
        lines.append(f"| {name} | {e.mean():+.2f} | {np.sqrt((e ** 2).mean()):.2f} | {e.abs().max():.2f} | "
                     f"{df[f'{name}_cover'].mean():.0%} | {df[f'{name}_cover_ols'].mean():.0%} |")
    lines += ["", "| quantity | mean | max |", "|---|---|---|"]
    for col in ("alpha_rms_deg", "beta_rms_deg", "rms_q_rad_s", "rms_q_dot_rad_s2", "rms_X1_m_s2", "rms_Y1_m_s2",
                "rms_Z1_m_s2", "nis_filter", "nis_smoother", "inversion_J_max",
                *[f"R_sigma_err_pct_{c}" for c in ("ax", "ay", "az", "p", "q", "r")]):
        lines.append(f"| {col} | {df[col].mean():.4g} | {df[col].abs().max():.4g} |")
    lines.append(f"| smoother NIS inside its band (fraction of flights) | {df['nis_in_band'].mean():.0%} | |")
    (out / "accuracy.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
