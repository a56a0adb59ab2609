"""The band order's column of cos 4 phi_r where alpha_r is small, and its guard (measured).

aerosid.identification.band_order forms a non-linear term f as f(x) + d, d = LP(f(x_w)) -
f(LP(x_w)), x the flight data's low-passed angles and x_w the wide-band ones.  That equals
LP(f(x_w)) only where x = LP(x_w); for angles inverted from the force database they differ
(the band path inverts low-passed forces, x_w comes from the smoother's), and where f is
ill-conditioned the bracket b = f(x) - f(LP(x_w)) is O(1): cos 4 phi_r at alpha_r -> 0, where
phi_r is undefined.  This bench counts how often the column leaves cos's range [-1, 1] on
seed-rlv (no hidden effect) and fits the default roll model (plain least squares, Mach window,
alpha_r with its own band order) with the column as it was before 2026-11-30 (no guard), as shipped
(guarded_column: a column outside the range f(x) and LP(f(x_w)) span takes LP(f(x_w))), and three
alternatives:

* LP(f(x_w)) where |b| is more than 5 MAD from its median (the rest as now);
* LP(f(x_w)) on every row where the band order applies;
* LP(f(x_w)) + LP(b) there (x still enters, through the same low-pass as the coefficient).

    python bench/bench_band_order_columns.py [--seeds 0-3] [--jobs 2]
    -> bench/results/band_order_columns.md
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from machine import loadavg, run_jobs, run_line, seed_range  # noqa: E402

TRUTH = np.array([0.0004, 0.012, 0.0003, -0.017])  # Cl_0, Cl_alpha_r, Cl_cos4phi, Cl_delta_r (simulation.toml)
VARIANTS = ("no guard", "shipped guard (range)", "LP(f(x_w)) where |b| > 5 MAD", "LP(f(x_w)) everywhere",
            "LP(f(x_w)) + LP(b)")


def one(seed: int) -> dict:
    from aerosid.diagnosis.lookalikes import scaled_lstsq
    from aerosid.ebm import estimate_flight_data
    from aerosid.identification.band_order import _wide_signals, guarded_column
    from aerosid.identification.identify import mach_window_mask
    from aerosid.modelling.expressions import evaluate
    from aerosid.modelling.models import vehicle_signals
    from aerosid.simulation import load_case, simulate

    case = load_case("seed-rlv")
    veh = case.vehicle
    fd = estimate_flight_data(simulate(case, (), seed=seed).telemetry, veh, flight="flight").flight_data
    fd = fd.sort_values(["flight", "t_s"], kind="stable")
    fd = fd[mach_window_mask(fd["mach"].to_numpy(float), veh.mach_reference, 0.5)].reset_index(drop=True)
    n = len(fd)
    W = _wide_signals(fd, veh)
    sig = vehicle_signals(fd, veh, with_band_order=False)

    def parts(expr):
        fx, flow = evaluate(expr, sig, n), evaluate(expr, W.low, n)
        fw = evaluate(expr, W.wide, n)
        lpw = W.low_pass(np.where(np.isfinite(fw), fw, flow))
        return fx, flow, lpw

    fx, flow, lpw = parts("cos(4*phi_r)")
    now = fx + np.where(W.inner, lpw - flow, 0.0)
    b = fx - flow
    bi = b[W.inner]
    mad = 1.4826 * np.median(np.abs(bi - np.median(bi)))
    out = W.inner & (np.abs(b - np.median(bi)) > 5 * mad)
    cols = {VARIANTS[0]: now, VARIANTS[1]: guarded_column(fx, np.where(W.inner, lpw - flow, 0.0), flow),
            VARIANTS[2]: np.where(out, lpw, now), VARIANTS[3]: np.where(W.inner, lpw, fx),
            VARIANTS[4]: np.where(W.inner, lpw + W.low_pass(np.where(np.isfinite(b), b, 0.0)), fx)}
    ax, alow, alpw = parts("alpha_r")
    alpha_r = ax + np.where(W.inner, alpw - alow, 0.0)
    y = fd["Cl"].to_numpy(float)
    row = {"seed": seed, "rows": int(W.inner.sum()), "out_of_range": int((np.abs(now) > 1 + 1e-9).sum()),
           "b_outliers": int(out.sum())}
    for k, col in cols.items():
        X = np.column_stack([np.ones(n), alpha_r, col, sig["delta_r"]])
        ok = np.all(np.isfinite(X), axis=1) & np.isfinite(y)
        th = scaled_lstsq(X[ok], y[ok])
        row[k] = (th / TRUTH, float(np.sqrt(np.mean((y[ok] - X[ok] @ th) ** 2))))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0-3")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results" / "band_order_columns.md"))
    a = ap.parse_args()
    t0, load0 = time.time(), loadavg()
    rows = run_jobs(one, seed_range(a.seeds), a.jobs)
    L = ["# The band order's cos 4 phi_r column on seed-rlv, with and without the guard", "",
         run_line((load0, loadavg()), a.jobs, time.time() - t0)
         + f". `python bench/bench_band_order_columns.py --seeds {a.seeds} --jobs {a.jobs}`.", "",
         "Method: the module docstring. Estimates / truth of the default roll model, plain least squares.", "",
         "| seed | rows with the band order | column outside [-1, 1] | bracket outliers | variant "
         "| Cl_0 | Cl_alpha_r | Cl_cos4phi | Cl_delta_r | residual RMS |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for k in VARIANTS:
            th, rms = r[k]
            L.append(f"| {r['seed']} | {r['rows']} | {r['out_of_range']} | {r['b_outliers']} | {k} | "
                     + " | ".join(f"{v:.3f}" for v in th) + f" | {rms:.3e} |")
    Path(a.out).write_text("\n".join(L) + "\n")
    print("\n".join(L))


if __name__ == "__main__":
    main()
