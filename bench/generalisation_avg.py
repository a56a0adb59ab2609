"""The generalisation bench against a second truth: the FLIGHT-AVERAGED derivative
(aerosid.simulation.jsbsim_truth_avg), reported beside the at-trim truth, never instead.

Why a second truth: JSBSim's tables interpolate linearly between breakpoints, so the at-trim
truth (central difference h = 1e-4 at the trim point) is the slope of ONE table segment,
and which one depends on where the trim point falls relative to a breakpoint (pa28's
C_L(alpha): 5.743/rad on [-2, 0] deg, 5.914 on [0, 2] deg; trim at -0.48 deg, the flight
spans -2.6..+1.7 deg: no flight measures the at-trim segment slope alone).  The
flight-averaged truth is, per derivative, the mean over the flight's samples of the same
central difference of the same model at each sample's own state (alpha, beta, surfaces,
rates and every other input of the model as recorded; moments about the sample's CG).
By Stein's lemma, for jointly Gaussian excursions x the least-squares coefficients of a
smooth f on x equal E[grad f(x)]: for piecewise-linear tables the average is what a linear
model identified from that flight estimates.  The flight's excursions are NOT Gaussian
(3-2-1-1s and doublets from a trimmed state): the least-squares slope weights a sample's
derivative by how far the flight is from its mean there, the uniform mean does not, so
the averaged truth is a physically motivated second reference, not the identity the
oracle column is (measured: pa28 CN_alpha, average +0.14 % of the at-trim truth, least-squares
slope of the table along alpha +0.93 %, oracle +1.3 %; bench/bench_truth_weighting.py).  seed-rlv's truth is analytic and linear: its averaged truth IS its
truth (not computed).

Columns (per bench coefficient NAME): NAME_truth_avg, and against it NAME_err_pct_avg,
NAME_z_avg, NAME_cover_avg, NAME_oracle_pct_avg; silent_failure_avg.

``python bench/bench_generalisation.py --truth-only`` simulates every (vehicle, seed) of
bench/results/generalisation_runs.csv again WITHOUT the pipeline, checks that the at-trim
truth it computes is the CSV's (to the CSV's 6 significant digits: the simulation is
deterministic per seed), and merges the averaged truth into the rows;
``--from-csv`` then re-renders the tables.
"""
from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

SUFFIX = "_avg"


def truth_avg_of(flight, name: str, coefficients: dict, truth_of) -> float:
    """The flight-averaged truth of a bench coefficient (seed-rlv: its linear truth)."""
    table = flight.info.get("coefficients_flight_average")
    if table is None:   # seed-rlv: analytic and linear, the average is the truth
        return truth_of(flight, name)
    if name == "damping":
        return float(table["Cm_q"] + table.get("Cm_alpha_dot", 0.0))
    return float(table.get(coefficients[name], math.nan))


def against(row: dict, name: str, truth: float, suffix: str = SUFFIX) -> None:
    """Error, z and coverage of the row's estimate of `name` against `truth` (and the
    oracle's error against it) into row[f"{name}_err_pct{suffix}"], ..."""
    row[f"{name}_truth{suffix}"] = truth
    est, se = row.get(f"{name}_est", math.nan), row.get(f"{name}_se", math.nan)
    if not (math.isfinite(truth) and truth != 0):
        return
    if est is not None and math.isfinite(est):
        row[f"{name}_err_pct{suffix}"] = 100.0 * (est / truth - 1.0)
        row[f"{name}_z{suffix}"] = (est - truth) / se if se > 0 else math.inf
        row[f"{name}_cover{suffix}"] = bool(abs(est - truth) <= 1.96 * se)
    orc, t0 = row.get(f"{name}_oracle_pct"), row.get(f"{name}_truth")
    if orc is not None and t0 is not None and math.isfinite(orc) and math.isfinite(t0):
        row[f"{name}_oracle_pct{suffix}"] = 100.0 * (t0 * (1 + orc / 100.0) / truth - 1.0)


#: Bench names that are a combination of the model's terms (the run prints each term, not the sum,
#: so it never announces the sum as undetermined).
COMBINATIONS = ("damping",)


def announced_undetermined(row, name: str) -> bool:
    """The run printed this coefficient as NOT DETERMINED by the flight (its 95 % interval holds 0,
    aerosid.identification.term_report.undetermined; here with 1.96 sigma, no wider than the
    run's own Student-t interval, so the bench never credits a flag the run did not print)."""
    if name in COMBINATIONS:
        return False
    est, se = row.get(f"{name}_est"), row.get(f"{name}_se")
    try:
        est, se = float(est), float(se)
    except (TypeError, ValueError):
        return False
    return bool(np.isfinite(est) and np.isfinite(se) and abs(est) <= 1.96 * se)


def silent(row, barred, sigma: float, pct: float, suffix: str = "") -> str:
    """The bench's silent-failure rule against the truth of `suffix` ("" = at trim)."""
    if row.get("failed") or bool(row.get("diverged")) or (row.get("findings") or ""):
        return ""
    out = []
    for name in barred:
        z, e, cov = row.get(f"{name}_z{suffix}"), row.get(f"{name}_err_pct{suffix}"), row.get(f"{name}_cover{suffix}")
        if z is None or e is None or not np.isfinite(e):
            continue
        if announced_undetermined(row, name):
            continue
        if abs(z) > sigma or (abs(e) > pct and not bool(cov)):
            out.append(f"{name} {e:+.0f} % ({z:+.1f} sigma)")
    return "; ".join(out)


def add_columns(row: dict, flight, names, coefficients, truth_of, barred, sigma, pct) -> None:
    for name in names:
        against(row, name, truth_avg_of(flight, name, coefficients, truth_of))
    row[f"silent_failure{SUFFIX}"] = silent(row, barred, sigma, pct, SUFFIX)


# --------------------------------------------------------------------------------------
# --truth-only
# --------------------------------------------------------------------------------------

def _same(a: float, b: float) -> bool:
    """Equal as the CSV writes them (float_format %.6g), nan equal to nan."""
    if not (np.isfinite(a) and np.isfinite(b)):
        return bool(np.isnan(a) and np.isnan(b))
    return f"{a:.6g}" == f"{b:.6g}"


def truth_only_job(job) -> dict:
    """Simulate one (vehicle, seed) and return its at-trim and averaged truths (no pipeline)."""
    vehicle, seed = job
    import bench_generalisation as bg

    if vehicle == "seed-rlv":
        return {"vehicle": vehicle, "seed": seed, "analytic": True}
    with tempfile.TemporaryDirectory() as tmp:
        flight, _ = bg.simulate(vehicle, seed, Path(tmp))
    out = {"vehicle": vehicle, "seed": seed, "analytic": False}
    for name in bg.COEFFICIENTS:
        out[f"{name}_truth"] = bg.truth_of(flight, name)
        out[f"{name}_truth{SUFFIX}"] = truth_avg_of(flight, name, bg.COEFFICIENTS, bg.truth_of)
    return out


def merge(df: pd.DataFrame, results: list[dict], names, barred, sigma, pct) -> tuple[pd.DataFrame, list[str]]:
    """The CSV's rows with the averaged truth merged in; every at-trim truth recomputed is
    checked against the CSV's.  Returns (rows, mismatches)."""
    by_key = {(r["vehicle"], int(r["seed"])): r for r in results}
    rows, bad = [], []
    for rec in df.to_dict("records"):
        res = by_key.get((rec["vehicle"], int(rec["seed"])))
        if res is None:
            rows.append(rec)
            continue
        for name in names:
            if res["analytic"]:
                truth = rec.get(f"{name}_truth", math.nan)
            else:
                if not _same(res[f"{name}_truth"], rec.get(f"{name}_truth", math.nan)):
                    bad.append(f"{rec['vehicle']} seed {rec['seed']} {name}: at-trim truth {res[f'{name}_truth']:.9g} "
                               f"recomputed, {rec.get(f'{name}_truth')} in the CSV")
                truth = res[f"{name}_truth{SUFFIX}"]
            for col in ("err_pct", "z", "cover", "oracle_pct"):
                rec.pop(f"{name}_{col}{SUFFIX}", None)
            against(rec, name, truth)
        rec[f"silent_failure{SUFFIX}"] = silent(rec, barred, sigma, pct, SUFFIX)
        rows.append(rec)
    out = pd.DataFrame(rows)
    ours = [f"{n}_{c}{SUFFIX}" for n in names for c in ("truth", "err_pct", "z", "cover", "oracle_pct")]
    ours = [c for c in ours + [f"silent_failure{SUFFIX}"] if c in out]
    return out[[c for c in out.columns if c not in ours] + ours], bad


# --------------------------------------------------------------------------------------
# report
# --------------------------------------------------------------------------------------

def with_average(g: pd.DataFrame) -> pd.DataFrame:
    """The rows that have the flight-averaged truth (all of them once --truth-only ran)."""
    col = f"Cm_alpha_truth{SUFFIX}"
    return g[g[col].notna()] if col in g else g.iloc[:0]


def vehicle_table(g: pd.DataFrame, ok: pd.DataFrame, names) -> list[str]:
    """Per coefficient: the averaged truth, how far it is from the at-trim one, and the
    errors and coverage against it (markdown lines)."""
    g, ok = with_average(g), with_average(ok)
    if g.empty:
        return ["", "vs the flight-averaged truth: not computed (`--truth-only`)"]
    lines = ["", "vs the flight-averaged truth:", "",
             "| coefficient | averaged truth | averaged vs at-trim truth % | mean error % | "
             "RMS error % | worst error % | 95 % coverage | oracle % | coverage of the oracle |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name in names:
        ta, t0 = g[f"{name}_truth{SUFFIX}"], g[f"{name}_truth"]
        if ta.notna().sum() == 0:
            continue
        d = 100 * (ta / t0 - 1)
        shift = "-"
        if d.notna().any():  # the truths do not depend on the seed (noise is added to the telemetry only)
            shift = f"{d.mean():+.2f}" + ("" if f"{d.min():+.2f}" == f"{d.max():+.2f}" else
                                          f" ({d.min():+.2f}..{d.max():+.2f})")
        col = f"{name}_err_pct{SUFFIX}"
        if col not in ok or ok[col].notna().sum() == 0:
            lines.append(f"| {name} | {ta.mean():.4g} | {shift} | - | - | - | - | - | - |")
            continue
        e = ok[col].dropna()
        cover = ok[f"{name}_cover{SUFFIX}"].fillna(False).astype(bool).sum() / len(g)
        orc = ok.get(f"{name}_oracle_pct{SUFFIX}")
        orc_txt, orc_cover = "-", "-"
        if orc is not None and orc.notna().any():
            orc_txt = f"{orc.mean():+.1f}"
            best = ok[f"{name}_truth{SUFFIX}"] * (1 + orc / 100)
            orc_cover = f"{((ok[f'{name}_est'] - best).abs() <= 1.96 * ok[f'{name}_se']).sum() / len(g):.0%}"
        lines.append(f"| {name} | {ta.mean():.4g} | {shift} | {e.mean():+.1f} | {np.sqrt((e ** 2).mean()):.1f} | "
                     f"{e.abs().max():.1f} | {cover:.0%} | {orc_txt} | {orc_cover} |")
    return lines
