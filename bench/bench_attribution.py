"""Attribution of the C_m biases of the generalisation bench (issue 16) by substitution.

    python bench/bench_attribution.py [--vehicles F4N,OV10,pa28] [--seeds 0-4]
    -> bench/results/attribution.md and bench/results/attribution_runs.csv

Per (vehicle, seed) the flight is simulated and estimated once (bench/attribution_cache.py:
bench_generalisation.simulate + aerosid.ebm.estimate_flight_data, cached under
/tmp/aerosid-attrib with the band-limiting each segment went through).  The C_m channel's
default model is then refitted (ordinary least squares on the samples of the Mach window,
as aerosid.identification.identify.identify fits it before the SIMEX correction) with one group of the
flight data's columns replaced by the noise-free truth, passed through THE SAME
band-limiting the flight data went through (aerosid.identification.band.low_pass_runs
with the segment's band edge and filter runs):

  base         the pipeline's flight data (the naive fit, no SIMEX)
  base+SIMEX   aerosid.identification.identify.identify (the reported estimate)
  a: Cm(gyro)  the dependent C_m from the noise-free gyros (low-passed, differentiated,
               Euler equations with the vehicle file's inertia), the pipeline's qbar
  a: Cm(JSB)   the dependent C_m from JSBSim's own aerodynamic + propulsive pitching
               moment (low-passed), the pipeline's qbar
  b: alpha     alpha (alpha_dot_hat follows: the pipeline's derivative of the new alpha)
  b: alphadot  alpha_dot_hat alone: JSBSim's alpha-dot, low-passed (no derivative window)
  beta         beta (the |beta| term)
  c: q         the pitch rate (q_hat)
  d: delta_p   the surface deflection (JSBSim's surface position the aerodynamics read:
               the telemetry carries it plus white noise, after the actuator)
  e: air data  V (q_hat, alpha_dot_hat) and qbar (the dependent's normalisation)
  f: inertia   not a substitution: the vehicle file's I_yy, mass, CG against JSBSim's
               (reported below the tables)
  b + X        the true alpha and group X (SIMEX aims at the true-alpha answer)
  all          every group at once (a: Cm(JSB), b: alpha, c, d, e, beta)
  all+adot     every group and JSBSim's alpha-dot (what the band-limited truth gives)
  all but X    every group but X (the error X's noise makes when all else is true)
  oracle       the bench's oracle: the default model fitted to the unfiltered truth

Errors are % of the linear truth (flight.coefficients); damping = C_m_q + C_m_alpha_dot.
"""
from __future__ import annotations

import argparse
import math
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

TARGETS = {"Cm_alpha": "Cm_alpha", "Cm_delta": "Cm_delta_p", "damping": None}


# ------------------------------------------------------------------------------ the truth, band-limited

def band_limited_truth(data: dict, values: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Truth signals (on the truth's grid) through each segment's low-pass, read at the
    flight data's rows (in the flight data's order)."""
    from aerosid.identification.band import low_pass_runs

    fd, T = data["flight_data"], data["truth"]
    tt = T["t_s"].to_numpy(float)
    out = {k: np.full(len(fd), np.nan) for k in values}
    seg_col = fd["segment"].astype(str).to_numpy()
    for b in data["bands"]:
        ts = b["t_s"]
        fs = 1.0 / float(np.median(np.diff(ts)))
        runs = [slice(a, c) for a, c in b["filter_runs"]]
        rows = np.flatnonzero(seg_col == str(b["segment"]))
        idx = np.searchsorted(ts, fd["t_s"].to_numpy(float)[rows] - 1e-9)
        if np.any(np.abs(ts[np.clip(idx, 0, len(ts) - 1)] - fd["t_s"].to_numpy(float)[rows]) > 1e-6):
            raise ValueError(f"segment {b['segment']}: flight-data rows not on the segment's grid")
        for k, v in values.items():
            x = np.interp(ts, tt, np.asarray(v, float))
            out[k][rows] = low_pass_runs(x, fs, b["band_hz"], runs)[idx]
    return out


def gyro_moment(data: dict) -> np.ndarray:
    """M_hat [rad/s^2] at the flight data's rows from the noise-free gyros, exactly as
    band_limited_signals builds it from the measured ones (low-pass, central difference,
    Euler equations with the vehicle file's inertia)."""
    from aerosid.identification.band import aero_angular_acceleration, low_pass_runs

    fd, T, veh = data["flight_data"], data["truth"], data["vehicle_obj"]
    tt = T["t_s"].to_numpy(float)
    w_true = T[["p_rad_s", "q_rad_s", "r_rad_s"]].to_numpy(float)
    inertia = (veh.Ixx_kg_m2, veh.Iyy_kg_m2, veh.Izz_kg_m2, veh.Ixz_kg_m2)
    out = np.full(len(fd), np.nan)
    seg_col = fd["segment"].astype(str).to_numpy()
    for b in data["bands"]:
        ts = b["t_s"]
        fs = 1.0 / float(np.median(np.diff(ts)))
        runs = [slice(a, c) for a, c in b["filter_runs"]]
        w = np.column_stack([np.interp(ts, tt, w_true[:, j]) for j in range(3)])
        wf = low_pass_runs(w, fs, b["band_hz"], runs)
        wd = np.full_like(wf, np.nan)
        for r in runs:
            wd[r] = np.gradient(wf[r], ts[r], axis=0)
        ang = aero_angular_acceleration(wf, wd, inertia)
        rows = np.flatnonzero(seg_col == str(b["segment"]))
        idx = np.searchsorted(ts, fd["t_s"].to_numpy(float)[rows] - 1e-9)
        out[rows] = ang[idx, 1]
    return out


# ------------------------------------------------------------------------------ the fits

def fit_cm(fd: pd.DataFrame, vehicle, overrides: dict | None = None, mach_half_width: float | None = 0.5) -> dict:
    """OLS of the default C_m model on fd (its Mach window), signals overridden by name
    (arrays in fd's row order).  Returns coefficient -> estimate."""
    from aerosid.identification.identify import mach_window_mask
    from aerosid.modelling.models import default_models, vehicle_signals

    order = np.lexsort((fd["t_s"].to_numpy(float), fd["flight"].astype(str).to_numpy()))
    f = fd.iloc[order].reset_index(drop=True)
    sig = vehicle_signals(f, vehicle)
    for k, v in (overrides or {}).items():
        sig[k] = np.asarray(v, float)[order]
    model = default_models(vehicle)["Cm"]
    X = model.regressors(sig).to_numpy(float)
    y = f["Cm"].to_numpy(float)
    ok = mach_window_mask(f["mach"].to_numpy(float), vehicle.mach_reference, mach_half_width)
    ok &= np.all(np.isfinite(X), axis=1) & np.isfinite(y)
    beta = np.linalg.lstsq(X[ok], y[ok], rcond=None)[0]
    return dict(zip(model.names, beta))


def simex_cm(fd: pd.DataFrame, vehicle) -> dict:
    """The C_m estimates aerosid.identification.identify.identify reports (SIMEX-corrected for vanes)."""
    from aerosid.identification.identify import identify
    from aerosid.modelling.models import default_models

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ident = identify(fd, vehicle, {"Cm": default_models(vehicle)["Cm"]}, bias_pairs=0,
                         control_eiv=False)  # as recorded (before the controls' part)
    fit = ident.fits["Cm"]
    return dict(zip(fit.names, np.asarray(fit.estimate, float)))


def targets(sol: dict) -> dict:
    return {"Cm_alpha": sol.get("Cm_alpha", math.nan), "Cm_delta": sol.get("Cm_delta_p", math.nan),
            "damping": sol.get("Cm_q", math.nan) + sol.get("Cm_alpha_dot", 0.0)}


def truth_targets(coef: dict) -> dict:
    return {"Cm_alpha": coef["Cm_alpha"], "Cm_delta": coef["Cm_delta_p"],
            "damping": coef.get("Cm_q_plus_alpha_dot", coef.get("Cm_q", math.nan) + coef.get("Cm_alpha_dot", 0.0))}


def substitutions(data: dict) -> dict[str, dict]:
    """Substitution name -> C_m estimates (the table's rows, in order)."""
    from bench_generalisation import oracle

    fd, T, veh = data["flight_data"], data["truth"], data["vehicle_obj"]
    fd = fd.copy()
    c, S = veh.length_pitch_m, veh.S_m2
    qbar_p = fd["qbar_pa"].to_numpy(float)
    V_p = fd["V_m_s"].to_numpy(float)
    moment_true = (T["Cm"] + T["Cm_prop"]).to_numpy(float) * T["qbar_pa"].to_numpy(float)
    lp = band_limited_truth(data, {
        "alpha": T["alpha_rad"], "beta": T["beta_rad"], "q": T["q_rad_s"], "V": T["V_m_s"],
        "delta_p": T["delta_p_rad"], "alpha_dot": T["alpha_dot_rad_s"], "moment": moment_true})
    qbar_true = np.interp(fd["t_s"].to_numpy(float), T["t_s"].to_numpy(float), T["qbar_pa"].to_numpy(float))
    cm_gyro = veh.Iyy_kg_m2 * gyro_moment(data) / (qbar_p * S * c)
    cm_jsb = lp["moment"] / qbar_p
    adot_hat_true = lp["alpha_dot"] * c / (2 * V_p)

    def with_cols(**cols) -> pd.DataFrame:
        f = fd.copy()
        for k, v in cols.items():
            f[k] = v
        return f

    no_eiv = {"eiv_sigma_alpha_rad": 0.0, "eiv_sigma_beta_rad": 0.0}
    # the groups: flight-data columns (and signal overrides) replaced by the band-limited truth
    groups = {
        "a": ({"Cm": lp["moment"] / qbar_p}, {}),
        "b": ({"alpha_rad": lp["alpha"], **no_eiv}, {}),
        "c": ({"q_rad_s": lp["q"]}, {}),
        "d": ({"delta_p_rad": lp["delta_p"]}, {}),
        "e": ({"V_m_s": lp["V"], "qbar_pa": qbar_true, "Cm": fd["Cm"] * qbar_p / qbar_true}, {}),
        "beta": ({"beta_rad": lp["beta"]}, {}),
    }

    def combined(names) -> tuple[dict, dict]:
        cols, over = {}, {}
        for g in names:
            c_, o_ = groups[g]
            cols.update(c_)
            over.update(o_)
        if "a" in names and "e" in names:  # the true moment normalised with the true qbar
            cols["Cm"] = lp["moment"] / qbar_true
        return cols, over

    out = {}
    out["base"] = fit_cm(fd, veh)
    out["base+SIMEX"] = simex_cm(fd, veh)
    out["a: Cm(gyro)"] = fit_cm(with_cols(Cm=cm_gyro), veh)
    out["a: Cm(JSB)"] = fit_cm(with_cols(Cm=cm_jsb), veh)
    out["a: Cm(JSB)+SIMEX"] = simex_cm(with_cols(Cm=cm_jsb), veh)
    out["b: alpha"] = fit_cm(with_cols(alpha_rad=lp["alpha"]), veh)
    out["b: alphadot"] = fit_cm(fd, veh, {"alpha_dot_hat": adot_hat_true})
    out["b: alpha+alphadot"] = fit_cm(with_cols(alpha_rad=lp["alpha"]), veh, {"alpha_dot_hat": adot_hat_true})
    out["beta"] = fit_cm(with_cols(beta_rad=lp["beta"]), veh)
    out["c: q"] = fit_cm(with_cols(q_rad_s=lp["q"]), veh)
    out["d: delta_p"] = fit_cm(with_cols(delta_p_rad=lp["delta_p"]), veh)
    out["e: air data"] = fit_cm(with_cols(**groups["e"][0]), veh)
    for g in ("a", "c", "d", "e"):  # on top of the true angle (what SIMEX aims at)
        cols, over = combined(["b", g])
        out[f"b + {g}"] = fit_cm(with_cols(**cols), veh, over)
    every = ["a", "b", "c", "d", "e", "beta"]
    cols, over = combined(every)
    out["all"] = fit_cm(with_cols(**cols), veh, over)
    out["all+adot"] = fit_cm(with_cols(**cols), veh, {"alpha_dot_hat": lp["alpha_dot"] * c / (2 * lp["V"])})
    for g in every:
        cols, over = combined([x for x in every if x != g])
        out[f"all but {g}"] = fit_cm(with_cols(**cols), veh, over)
    out["oracle"] = oracle(SimpleNamespace(truth=T), veh)
    out["oracle"] = {"Cm_alpha": out["oracle"].get("Cm_alpha"), "Cm_delta_p": out["oracle"].get("Cm_delta"),
                     "Cm_q": out["oracle"].get("damping"), "Cm_alpha_dot": 0.0}
    return out


def mass_check(data: dict) -> dict:
    """Group f: the vehicle file's mass properties against JSBSim's over the flight."""
    T, veh, m = data["truth"], data["vehicle_obj"], data["info_mass"]
    return {"mass_change_pct": 100 * (T["mass_kg"].iloc[-1] / T["mass_kg"].iloc[0] - 1),
            "mass_file_vs_jsb_pct": 100 * (veh.mass_kg / float(T["mass_kg"].mean()) - 1),
            "Iyy_file_vs_jsb_pct": 100 * (veh.Iyy_kg_m2 / m["Iyy_kg_m2"] - 1) if m.get("Iyy_kg_m2") else math.nan,
            "x_cg_span_mm": 1000 * float(np.ptp(T["x_cg_m"]))}


#: The curve's levels: SIMEX's usual ones (identify refits vane angles at 0.25..1 since 2026-11-28,
#: aerosid.identification.eiv.LAMBDAS_BY_SOURCE; this check of the premise keeps the curve it recorded).
SIMEX_LAMBDAS = (0.0, 0.5, 1.0, 1.5, 2.0)


def simex_curve(data: dict, replicates: int = 30, seed: int = 1) -> dict:
    """SIMEX's premise checked where alpha's noise is the only error: every other group is
    the band-limited truth; the naive C_m_alpha [% of the truth] with extra vane-like noise
    of variance lambda sigma^2 (aerosid.identification.eiv.with_angle_noise, the noise identify adds; independent
    draws at each lambda, not identify's antithetic pairs), averaged over `replicates` draws, against the answer with the true alpha (lambda = -1, what the
    extrapolation must reach) and aerosid.identification.eiv.extrapolate's quadratic."""
    from aerosid.identification.eiv import extrapolate, with_angle_noise
    from aerosid.identification.eiv_fit import angle_cutoff_hz

    fd, T, veh = data["flight_data"], data["truth"], data["vehicle_obj"]
    lp = band_limited_truth(data, {"beta": T["beta_rad"], "q": T["q_rad_s"], "V": T["V_m_s"],
                                   "delta_p": T["delta_p_rad"], "alpha": T["alpha_rad"],
                                   "moment": (T["Cm"] + T["Cm_prop"]).to_numpy(float) * T["qbar_pa"].to_numpy(float)})
    qbar = np.interp(fd["t_s"].to_numpy(float), T["t_s"].to_numpy(float), T["qbar_pa"].to_numpy(float))
    f = fd.copy()
    f["beta_rad"], f["q_rad_s"], f["V_m_s"], f["delta_p_rad"] = lp["beta"], lp["q"], lp["V"], lp["delta_p"]
    f["qbar_pa"], f["Cm"] = qbar, lp["moment"] / qbar
    truth = truth_targets(data["coefficients"])["Cm_alpha"]
    pct = lambda frame: 100 * (fit_cm(frame, veh)["Cm_alpha"] / truth - 1)  # noqa: E731
    rng = np.random.default_rng(seed)
    groups = (f["flight"].astype(str) + "/" + f["segment"].astype(str)).to_numpy()
    sig = f["eiv_sigma_alpha_rad"].to_numpy(float)
    curve = []
    for lam in SIMEX_LAMBDAS:
        if lam == 0:
            curve.append(pct(f))
            continue
        draws = [pct(with_angle_noise(f, rng, groups, (sig * np.sqrt(lam), 0 * sig), angle_cutoff_hz(f, veh)))
                 for _ in range(replicates)]
        curve.append(float(np.mean(draws)))
    g = f.copy()
    g["alpha_rad"] = lp["alpha"]
    return {"true_alpha": pct(g), **{f"lambda_{lam:g}": c for lam, c in zip(SIMEX_LAMBDAS, curve)},
            "quadratic_extrapolant": extrapolate(np.array(SIMEX_LAMBDAS), np.array(curve))}


def run(vehicles: list[str], seeds: list[int], cache_dir: Path = attribution_cache.CACHE_DIR) -> pd.DataFrame:
    rows = []
    for v in vehicles:
        for s in seeds:
            t0 = time.perf_counter()
            data = attribution_cache.load(v, s, cache_dir)
            truth = truth_targets(data["coefficients"])
            for name, sol in substitutions(data).items():
                est = targets(sol)
                row = {"vehicle": v, "seed": s, "substitution": name}
                for k in TARGETS:
                    row[f"{k}_pct"] = 100 * (est[k] / truth[k] - 1)
                rows.append(row)
            rows.append({"vehicle": v, "seed": s, "substitution": "f: mass check", **mass_check(data)})
            print(f"{v} seed {s}: {time.perf_counter() - t0:.0f} s", flush=True)
    return pd.DataFrame(rows)


def report(df: pd.DataFrame, seeds: list[int]) -> str:
    lines = [f"# Attribution of the C_m biases by substitution ({len(seeds)} seeds per vehicle)", "",
             f"{date.today()}, Python {platform.python_version()}; seeds {seeds[0]}..{seeds[-1]}; "
             "bench/bench_attribution.py (docstring: what each row substitutes).  Mean error % of the linear "
             "truth over the seeds (in brackets: the seeds' spread, 1 sd).  Every fit but `base+SIMEX` and "
             "`a: Cm(JSB)+SIMEX` is the naive OLS of the default C_m model on the Mach window.  What the tables "
             "say: bench/results/attribution_notes.md.", ""]
    for v, g in df.groupby("vehicle", sort=False):
        lines += [f"## {v}", "", "| substitution | Cm_alpha % | Cm_delta % | damping % |", "|---|---|---|---|"]
        for name, h in g[g["substitution"] != "f: mass check"].groupby("substitution", sort=False):
            cells = [f"{h[f'{k}_pct'].mean():+.1f} ({h[f'{k}_pct'].std():.1f})" for k in TARGETS]
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        m = g[g["substitution"] == "f: mass check"]
        if len(m):
            lines += ["", f"f (mass properties): mass change over the flight {m['mass_change_pct'].mean():+.2f} %, "
                      f"file mass vs JSBSim {m['mass_file_vs_jsb_pct'].mean():+.2f} %, file I_yy vs JSBSim's "
                      f"{m['Iyy_file_vs_jsb_pct'].mean():+.2f} %, CG travel {m['x_cg_span_mm'].mean():.1f} mm"]
        lines.append("")
    return "\n".join(lines) + "\n"


def simex_report(sc: pd.DataFrame) -> str:
    cols = [c for c in sc.columns if c.startswith("lambda_")]
    lines = ["## SIMEX's premise where alpha's noise is the only error", "",
             "Every group but alpha is the band-limited truth; naive C_m_alpha error % with extra vane-like noise of "
             "variance lambda sigma^2 (mean of 30 draws; lambda = 0: the flight's own vane noise only), the answer "
             "with the true alpha (where the extrapolation to lambda = -1 must land) and SIMEX's quadratic "
             "extrapolant through lambda 0..2 (mean over the seeds; identify refits vane angles at 0.25..1 since "
             "2026-11-28).", "",
             "| vehicle | true alpha | " + " | ".join(c.replace("lambda_", "lambda ") for c in cols) +
             " | quadratic extrapolant |", "|---|---|" + "---|" * len(cols) + "---|"]
    for v, g in sc.groupby("vehicle", sort=False):
        lines.append(f"| {v} | {g['true_alpha'].mean():+.1f} | " + " | ".join(f"{g[c].mean():+.1f}" for c in cols)
                     + f" | {g['quadratic_extrapolant'].mean():+.1f} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", default="F4N,OV10,pa28")
    ap.add_argument("--seeds", default="0-4")
    ap.add_argument("--out", default="attribution")
    ap.add_argument("--simex-seeds", default="0-2", help="seeds of the SIMEX-premise check ('' to skip)")
    ap.add_argument("--cache-dir", default=str(attribution_cache.CACHE_DIR),
                    help="where the simulated flights are cached (one folder per simulator version)")
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    df = run(args.vehicles.split(","), seeds, Path(args.cache_dir))
    out = Path(__file__).parent / "results"
    df.to_csv(out / f"{args.out}_runs.csv", index=False, float_format="%.5g")
    text = report(df, seeds)
    if args.simex_seeds:
        rows = [{"vehicle": v, "seed": s_, **simex_curve(attribution_cache.load(v, s_, Path(args.cache_dir)))}
                for v in args.vehicles.split(",") for s_ in parse_seeds(args.simex_seeds)]
        sc = pd.DataFrame(rows)
        sc.to_csv(out / f"{args.out}_simex.csv", index=False, float_format="%.4g")
        text += simex_report(sc)
    (out / f"{args.out}.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
