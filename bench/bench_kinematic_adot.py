"""alpha_dot_hat from the flight-path kinematics (aerosid.modelling.flight_path) against the vane
derivative, on the cached flights of the attribution bench (bench/attribution_cache.py).

    python bench/bench_kinematic_adot.py [--vehicles F4N,OV10,pa28] [--seeds 0-9]
        [--cache-dir /tmp/aerosid-attrib-ab2] [--fractions 5] [--out kinematic_adot]
    -> bench/results/<out>.md and <out>_runs.csv

Per cached flight the C_m channel's default model is identified with
aerosid.identification.identify.identify (defaults: the Mach window, SIMEX on), once with
alpha_dot_hat the vanes' derivative ("vane", the code before) and once per band fraction with the
complementary kinematic alpha-dot (f_c = band / fraction; "kin/5" is the default).  The naive
columns are the ordinary least squares before SIMEX.  Errors are % of the flight's linear truth;
coverage = |estimate - truth| <= 1.96 sigma; damping = C_m_q + C_m_alpha_dot (sigma of the sum).
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

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
import attribution_cache  # noqa: E402
from bench_accuracy import parse_seeds  # noqa: E402

TARGETS = ("Cm_alpha", "Cm_delta", "damping")


def truth_of(coef: dict) -> dict:
    return {"Cm_alpha": coef["Cm_alpha"], "Cm_delta": coef["Cm_delta_p"],
            "damping": coef.get("Cm_q_plus_alpha_dot", coef.get("Cm_q", math.nan) + coef.get("Cm_alpha_dot", 0.0))}


def estimates(fd: pd.DataFrame, vehicle) -> dict:
    """(estimate, sigma) per target from identify (SIMEX on), and the naive OLS estimates."""
    from aerosid.identification.identify import identify
    from bench_attribution import fit_cm
    from aerosid.modelling.models import default_models

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ident = identify(fd, vehicle, {"Cm": default_models(vehicle)["Cm"]}, bias_pairs=0)  # as recorded
    fit = ident.fits["Cm"]
    est = dict(zip(fit.names, np.asarray(fit.estimate, float)))
    se = dict(zip(fit.names, np.asarray(fit.std_error, float)))
    weights = {"Cm_q": 1.0, **({"Cm_alpha_dot": 1.0} if "Cm_alpha_dot" in fit.names else {})}
    d_est, d_se, *_ = fit.combination(weights)
    naive = fit_cm(fd, vehicle)
    return {"Cm_alpha": (est["Cm_alpha"], se["Cm_alpha"]), "Cm_delta": (est["Cm_delta_p"], se["Cm_delta_p"]),
            "damping": (d_est, d_se),
            "naive": {"Cm_alpha": naive["Cm_alpha"], "Cm_delta": naive["Cm_delta_p"],
                      "damping": naive["Cm_q"] + naive.get("Cm_alpha_dot", 0.0)}}


def gyros_shifted(fd: pd.DataFrame, shift_s: float) -> pd.DataFrame:
    """The flight data with p, q, r read shift_s later (negative: earlier), per segment (linear
    interpolation; the ends held): the JSBSim flights' gyros lead their alpha and accelerations
    by half a step (docs/estimation.md), this tests what that costs."""
    f = fd.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    groups = (f["flight"].astype(str) + "/" + f["segment"].astype(str)).to_numpy()
    t = f["t_s"].to_numpy(float)
    for c in ("p_rad_s", "q_rad_s", "r_rad_s"):
        x = f[c].to_numpy(float).copy()
        for g in pd.unique(groups):
            i = np.flatnonzero(groups == g)
            x[i] = np.interp(t[i] + shift_s, t[i], x[i])
        f[c] = x
    return f


def run(vehicles, seeds, cache_dir: Path, fractions, adot_fractions=(), gyro_shift_ms: float = 0.0) -> pd.DataFrame:
    import aerosid.modelling.flight_path as fp
    import aerosid.modelling.models as models

    variants = ([("vane", False, False, None)] + [(f"adot kin/{f:g}", True, False, f) for f in adot_fractions]
                + [(f"alpha+adot kin/{f:g}", True, True, f) for f in fractions])
    rows = []
    keep = (models.KINEMATIC_ALPHA_DOT, models.KINEMATIC_ALPHA, fp.KINEMATIC_BAND_FRACTION)
    try:
        for v in vehicles:
            for s in seeds:
                data = attribution_cache.load(v, s, cache_dir)
                truth = truth_of(data["coefficients"])
                for name, on, alpha_on, frac in variants:
                    t0 = time.perf_counter()
                    models.KINEMATIC_ALPHA_DOT, models.KINEMATIC_ALPHA = on, alpha_on
                    if frac is not None:
                        fp.KINEMATIC_BAND_FRACTION = frac
                    fd = data["flight_data"] if not gyro_shift_ms else gyros_shifted(data["flight_data"],
                                                                                     gyro_shift_ms / 1000)
                    e = estimates(fd, data["vehicle_obj"])
                    row = {"vehicle": v, "seed": s, "variant": name, "time_s": time.perf_counter() - t0}
                    for k in TARGETS:
                        est, se = e[k]
                        row[f"{k}_pct"] = 100 * (est / truth[k] - 1)
                        row[f"{k}_naive_pct"] = 100 * (e["naive"][k] / truth[k] - 1)
                        row[f"{k}_sigma_pct"] = 100 * abs(se / truth[k])
                        row[f"{k}_cover"] = bool(abs(est - truth[k]) <= 1.96 * se)
                    rows.append(row)
                print(f"{v} seed {s} done", flush=True)
    finally:
        models.KINEMATIC_ALPHA_DOT, models.KINEMATIC_ALPHA, fp.KINEMATIC_BAND_FRACTION = keep
    return pd.DataFrame(rows)


def structure(vehicles, seeds, cache_dir: Path) -> pd.DataFrame:
    """The naive C_m fit with and without C_m_alpha_dot in the model, per alpha_dot_hat variant,
    with the largest variance inflation factor of the design, and the short-period prediction of
    what a model without C_m_alpha_dot measures: alpha-dot = q + a_n/V + G makes
    C_m_alpha_dot alpha_dot_hat = C_m_alpha_dot (q_hat - rho S c/(4 m) C_N + ...), so
    C_m_alpha_eff = C_m_alpha - C_m_alpha_dot rho S c C_N_alpha/(4 m)."""
    from aerosid.identification.identify import mach_window_mask
    from aerosid.modelling.models import ChannelModel, default_models
    import aerosid.modelling.models as models

    rows = []
    keep = (models.KINEMATIC_ALPHA_DOT, models.KINEMATIC_ALPHA)
    try:
        for v in vehicles:
            for s in seeds:
                data = attribution_cache.load(v, s, cache_dir)
                fd = data["flight_data"].sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
                veh, c = data["vehicle_obj"], data["coefficients"]
                truth = truth_of(c)
                k = float(fd["rho_kg_m3"].mean()) * veh.S_m2 * veh.length_pitch_m / (4 * veh.mass_kg)
                eff = c["Cm_alpha"] - c.get("Cm_alpha_dot", 0.0) * k * c["CN_alpha"]
                full = default_models(veh)["Cm"]
                reduced = ChannelModel("Cm", tuple(t for t in full.terms if t.coefficient != "Cm_alpha_dot"))
                for name, flags in (("vane", (False, False)), ("adot kin/5", (True, False)),
                                    ("alpha+adot kin/5", (True, True))):
                    models.KINEMATIC_ALPHA_DOT, models.KINEMATIC_ALPHA = flags
                    sig = models.vehicle_signals(fd, veh)
                    ok = mach_window_mask(fd["mach"].to_numpy(float), veh.mach_reference, 0.5)
                    for label, m in (("with Cm_alpha_dot", full), ("without", reduced)):
                        X = m.regressors(sig).to_numpy(float)[ok]
                        b = dict(zip(m.names, np.linalg.lstsq(X, fd["Cm"].to_numpy(float)[ok], rcond=None)[0]))
                        Z = X[:, [j for j, n in enumerate(m.names) if n != "Cm_0"]]
                        vif = float(np.max(np.diag(np.linalg.inv(np.corrcoef(Z.T)))))
                        rows.append({"vehicle": v, "seed": s, "variant": name, "model": label, "max_vif": vif,
                                     "Cm_alpha_pct": 100 * (b["Cm_alpha"] / truth["Cm_alpha"] - 1),
                                     "Cm_delta_pct": 100 * (b["Cm_delta_p"] / truth["Cm_delta"] - 1),
                                     "damping_pct": 100 * ((b["Cm_q"] + b.get("Cm_alpha_dot", 0.0)) / truth["damping"] - 1),
                                     "Cm_alpha_eff_pct": 100 * (eff / truth["Cm_alpha"] - 1)})
    finally:
        models.KINEMATIC_ALPHA_DOT, models.KINEMATIC_ALPHA = keep
    return pd.DataFrame(rows)


def structure_report(st: pd.DataFrame) -> str:
    lines = ["", "## Why: C_m_alpha and C_m_alpha_dot are confounded (naive OLS, mean (sd) error % over the seeds)", "",
             "max VIF = the largest variance inflation factor of the C_m design.  Without C_m_alpha_dot the fit "
             "measures C_m_alpha_eff = C_m_alpha - C_m_alpha_dot rho S c C_N_alpha/(4 m) (the short period's "
             "identifiable combination), shown as 'predicted'.", "",
             "| vehicle | model | alpha_dot_hat | max VIF | Cm_alpha | Cm_delta | damping | predicted Cm_alpha_eff |",
             "|---|---|---|---|---|---|---|---|"]
    for (v, m, var), g in st.groupby(["vehicle", "model", "variant"], sort=False):
        cells = [f"{g[f'{k}_pct'].mean():+.1f} ({g[f'{k}_pct'].std():.1f})" for k in TARGETS]
        pred = f"{g['Cm_alpha_eff_pct'].mean():+.1f}" if m == "without" else "-"
        lines.append(f"| {v} | {m} | {var} | {g['max_vif'].mean():.0f} | " + " | ".join(cells) + f" | {pred} |")
    return "\n".join(lines) + "\n"


def report(df: pd.DataFrame, seeds) -> str:
    lines = [f"# alpha_dot_hat: vane derivative vs flight-path kinematics ({len(seeds)} seeds per vehicle)", "",
             f"{date.today()}, Python {platform.python_version()}; bench/bench_kinematic_adot.py on the cached "
             "flights of bench/attribution_cache.py.  identify defaults (Mach window, SIMEX on); naive = OLS before "
             "SIMEX.  Cells: mean / RMS error % of the linear truth, 95 % coverage, [naive mean], (mean sigma %).", "",
             "| vehicle | alpha_dot_hat | " + " | ".join(TARGETS) + " |", "|---|---|" + "---|" * len(TARGETS)]
    for (v, var), g in df.groupby(["vehicle", "variant"], sort=False):
        cells = []
        for k in TARGETS:
            e = g[f"{k}_pct"]
            cells.append(f"{e.mean():+.1f} / {np.sqrt((e ** 2).mean()):.1f} / {g[f'{k}_cover'].mean():.0%} "
                         f"[{g[f'{k}_naive_pct'].mean():+.1f}] ({g[f'{k}_sigma_pct'].mean():.1f})")
        lines.append(f"| {v} | {var} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", default="F4N,OV10,pa28")
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--cache-dir", default="/tmp/aerosid-attrib-ab2")
    ap.add_argument("--fractions", default="5", help="band fractions of the complementary corner, comma-separated")
    ap.add_argument("--adot-fractions", default="", help="the same with alpha_dot_hat alone kinematic (alpha the vane's)")
    ap.add_argument("--out", default="kinematic_adot")
    ap.add_argument("--gyro-shift-ms", type=float, default=0.0,
                    help="read the gyros this much later (negative: earlier) before fitting (the timing test)")
    ap.add_argument("--structure-only", action="store_true", help="only the confounding table (naive fits, fast)")
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    out = Path(__file__).parent / "results"
    st = structure(args.vehicles.split(","), seeds, Path(args.cache_dir))
    st.to_csv(out / f"{args.out}_structure.csv", index=False, float_format="%.5g")
    if args.structure_only:
        print(structure_report(st))
        return
    df = run(args.vehicles.split(","), seeds, Path(args.cache_dir), [float(f) for f in args.fractions.split(",")],
             [float(f) for f in args.adot_fractions.split(",") if f], args.gyro_shift_ms)
    df.to_csv(out / f"{args.out}_runs.csv", index=False, float_format="%.5g")
    text = report(df, seeds) + structure_report(st)
    if args.gyro_shift_ms:
        text = (f"Gyros (p, q, r) read {args.gyro_shift_ms:+g} ms shifted before every fit of the first table "
                "(gyros_shifted); the confounding table is unshifted.\n\n" + text)
    (out / f"{args.out}.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
