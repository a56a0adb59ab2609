"""Would effective-variance weights fix the roll model's cos 4 phi_r? (measured, not adopted)

docs/modelling-loop.md §6 left "a fit weighted by the regressor's error variance" as the next
thing to try against C_l,cos4phi's attenuation on seed-rlv (cos 4 phi_r is noisy where alpha_r
is small).  This bench tries it.  Each sample's weight is 1 / (s_y^2 + v_i), v_i the variance the
angles' in-band noise puts into the model's prediction there (linearised: central differences of
the model's own columns in alpha and beta, alpha_r and phi_r following them; sigma = the flight
data's median eiv_sigma_* through the band's noise gain), s_y^2 = the unweighted fit's mean
square less the median v_i (at least a quarter of it); two refits, each from the last estimates.

Part 1, seed-rlv through the real pipeline (identify with SIMEX, no bias check): the Cl channel
fitted as it is and with the weights (the response and the columns scaled by sqrt(w), so SIMEX
refits with the same weights).  Part 2, a synthetic C_l = C_l0 + C_lc cos 4 phi_r with white
angle noise of known sigma, least squares against the weighted fit, 6 seeds per configuration.

    python bench/bench_effective_variance.py [--seeds 0-3] [--jobs 2]
    -> bench/results/effective_variance.md
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from machine import loadavg, run_jobs, run_line, seed_range  # noqa: E402

TRUTH = {"Cl_0": 0.0004, "Cl_alpha_r": 0.012, "Cl_cos4phi": 0.0003, "Cl_delta_r": -0.017,
         "Cl_delta_p": -0.017 * 0.05}


def _moved(signals, da, db):
    from aerosid.identification.inversion import total_angles

    out = dict(signals)
    out["alpha"], out["beta"] = np.asarray(signals["alpha"]) + da, np.asarray(signals["beta"]) + db
    out["alpha_r"], out["phi_r"] = total_angles(out["alpha"], out["beta"])
    return out


def weights(model, signals, theta, rms, sa, sb, h=1e-5):
    """Effective-variance weights (mean 1) of the module doc."""
    def slope(da, db):
        up = model.regressors(_moved(signals, da, db)).to_numpy(float) @ theta
        return (up - model.regressors(_moved(signals, -da, -db)).to_numpy(float) @ theta) / (2 * h)

    v = (slope(h, 0) * sa) ** 2 + (slope(0, h) * sb) ** 2
    s_y2 = max(rms ** 2 - float(np.nanmedian(v)), 0.25 * rms ** 2)
    w = 1.0 / (s_y2 + v)
    return w / np.nanmean(w)


def _scaled_model_class():
    from aerosid.modelling.models import ChannelModel

    @dataclass(frozen=True, eq=False)
    class Scaled(ChannelModel):
        scale: np.ndarray = field(default_factory=lambda: np.ones(0))

        def design(self, signals):
            X, notes = ChannelModel(self.channel, self.terms).design(signals)
            return X.mul(self.scale, axis=0), notes
    return Scaled


def one_flight(job) -> dict:
    from aerosid.ebm import estimate_flight_data
    from aerosid.identification.band import band_noise_gain
    from aerosid.identification.identify import identify, mach_window_mask
    from aerosid.modelling.effects import CATALOGUE
    from aerosid.modelling.models import default_models, parse_term, vehicle_signals
    from aerosid.simulation import load_case, simulate

    name, seed = job
    case = load_case("seed-rlv")
    veh = case.vehicle
    flight = simulate(case, () if name == "none" else ((CATALOGUE[name], 1.0),), seed=seed)
    fd = estimate_flight_data(flight.telemetry, veh, flight="flight").flight_data
    fd = fd[mach_window_mask(fd["mach"].to_numpy(float), veh.mach_reference, 0.5)]
    fd = fd.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    models = dict(default_models(veh))
    if name != "none":
        models["Cl"] = models["Cl"].with_term(parse_term(name, "Cl"))
    plain = identify(fd, veh, models, bias_pairs=0).fits["Cl"]
    sig = vehicle_signals(fd, veh)
    fs = 1.0 / float(np.median(np.diff(fd["t_s"])))
    gain = band_noise_gain(fs, float(fd["band_hz"].iloc[0]))
    sa, sb = (float(np.median(fd[c])) * gain for c in ("eiv_sigma_alpha_rad", "eiv_sigma_beta_rad"))
    fit, Scaled = plain, _scaled_model_class()
    for _ in range(2):
        w = weights(models["Cl"], sig, fit.params.to_numpy(float), fit.rms_residual, sa, sb)
        fdw = fd.assign(Cl=fd["Cl"].to_numpy(float) * np.sqrt(w))
        fit = identify(fdw, veh, {**models, "Cl": Scaled("Cl", models["Cl"].terms, np.sqrt(w))},
                       bias_pairs=0).fits["Cl"]
    row = {"flight": name, "seed": seed, "w_min": float(np.nanmin(w)), "w_max": float(np.nanmax(w))}
    for lab, f in (("plain", plain), ("ev", fit)):
        for k, v, s in zip(f.names, f.estimate, f.std_error):
            if k in TRUTH:
                row[f"{lab}_{k}"], row[f"{lab}_{k}_z"] = v / TRUTH[k], (v - TRUTH[k]) / s
    return row


def synthetic(seed, sa, sb, amp) -> tuple[float, float]:
    from aerosid.identification.inversion import total_angles
    from aerosid.identification.regression import fit_linear
    from aerosid.modelling.models import ChannelModel, parse_term

    rng = np.random.default_rng(seed)
    n = 4000
    t = np.arange(n) * 0.01
    alpha = 0.04 + amp * np.sin(2 * np.pi * 0.13 * t)
    beta = 0.004 * np.sin(2 * np.pi * 0.31 * t + 1.0)
    model = ChannelModel("Cl", tuple(parse_term(s, "Cl") for s in ("Cl_0 = 1", "Cl_cos4phi = cos(4*phi_r)")))

    def sig(a, b):
        ar, pr = total_angles(a, b)
        return {"alpha": a, "beta": b, "alpha_r": ar, "phi_r": pr}
    truth = np.array([0.0004, 0.0003])
    y = model.regressors(sig(alpha, beta)).to_numpy() @ truth + rng.normal(0, 2e-5, n)
    meas = sig(alpha + rng.normal(0, sa, n), beta + rng.normal(0, sb, n))
    X = model.regressors(meas)
    ols = fit_linear(y, X, names=model.names, channel="Cl")
    w = weights(model, meas, ols.params.to_numpy(), ols.rms_residual, sa, sb)
    ev = fit_linear(y, X, names=model.names, channel="Cl", weights=w)
    return ols.params.to_numpy()[1] / truth[1], ev.params.to_numpy()[1] / truth[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0-3")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results" / "effective_variance.md"))
    a = ap.parse_args()
    seeds = seed_range(a.seeds)
    jobs = [("none", s) for s in seeds] + [("fin_misalignment", s) for s in seeds[:2]]
    t0, load0 = time.time(), loadavg()
    rows = run_jobs(one_flight, jobs, a.jobs)
    L = ["# Effective-variance weights for the roll model's cos 4 phi_r (measured, not adopted)", "",
         run_line((load0, loadavg()), a.jobs, time.time() - t0)
         + f". `python bench/bench_effective_variance.py --seeds {a.seeds} --jobs {a.jobs}`.", "",
         "Method: the module docstring. Ratios estimate / truth; z = (estimate - truth) / reported sigma.", "",
         "## 1. seed-rlv, the real pipeline", "",
         "| flight | seed | weights min..max | Cl_cos4phi plain -> weighted (z) | Cl_0 plain -> weighted (z) "
         "| Cl_alpha_r | Cl_delta_r |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        def cell(k):
            return (f"{r['plain_' + k]:.3f} ({r['plain_' + k + '_z']:+.1f}) -> "
                    f"{r['ev_' + k]:.3f} ({r['ev_' + k + '_z']:+.1f})")
        L.append(f"| {r['flight']} | {r['seed']} | {r['w_min']:.2g}..{r['w_max']:.2g} | {cell('Cl_cos4phi')} "
                 f"| {cell('Cl_0')} | {cell('Cl_alpha_r')} | {cell('Cl_delta_r')} |")
    L += ["", "## 2. Synthetic C_l = C_l0 + C_lc cos 4 phi_r, white angle noise, 6 seeds", "",
          "alpha = 0.04 + A sin(2 pi 0.13 t), beta = 0.004 sin(2 pi 0.31 t + 1), 4000 samples at 100 Hz, "
          "C_l noise 2e-5.", "", "| sigma alpha, beta [rad] | A | C_lc least squares | weighted |", "|---|---|---|---|"]
    for sa, sb, amp in ((0.001, 0.0003, 0.035), (0.0019, 0.00096, 0.03), (0.001, 0.0005, 0.038),
                        (0.0019, 0.00096, 0.038)):
        r = np.array([synthetic(s, sa, sb, amp) for s in range(6)])
        L.append(f"| {sa}, {sb} | {amp} | {r[:, 0].mean():.3f} +- {r[:, 0].std():.3f} "
                 f"| {r[:, 1].mean():.3f} +- {r[:, 1].std():.3f} |")
    Path(a.out).write_text("\n".join(L) + "\n")
    print("\n".join(L))


if __name__ == "__main__":
    main()
