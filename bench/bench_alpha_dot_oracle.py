"""Noise-free C_m,alpha with different alpha-dot regressors (docs/estimation.md, "The
pitch-damping split").

For each JSBSim aircraft (seed 0, the generated flight design): the default C_m model is fitted by
least squares to JSBSim's C_m (+ the propulsion's) through the band's low-pass, with every
regressor from the truth through the same low-pass; only alpha_dot_hat changes:

* ``jsbsim``: JSBSim's own alpha-dot through the band;
* ``central``: the central difference of the band-limited alpha;
* ``savgol``: what the pipeline uses (aerosid.modelling.models: a Savitzky-Golay derivative of the
  band-limited alpha, half-window BAND_DERIVATIVE_CYCLES / band);
* ``none``: the model without the alpha_dot_hat term.

The band edge comes from the true gyros (aerosid.identification.band.signal_band_edge_hz).
Errors in % of the at-trim truth.  Writes bench/results/alpha_dot_oracle.md.

    python bench/bench_alpha_dot_oracle.py [--vehicles c172x,pa28,...]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from datetime import date
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import bench_generalisation as B  # noqa: E402
from aerosid.identification.band import low_pass_runs, signal_band_edge_hz  # noqa: E402
from aerosid.identification.derivatives import smooth_derivative  # noqa: E402
from aerosid.modelling.models import BAND_DERIVATIVE_CYCLES, ChannelModel, default_models  # noqa: E402

VARIANTS = ("jsbsim", "central", "savgol", "none")


def one(vehicle_name: str, seed: int = 0) -> dict:
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        flight, vehicle = B.simulate(vehicle_name, seed, Path(tmp))
    T, truth = flight.truth, flight.coefficients
    t = T["t_s"].to_numpy()
    dt = float(np.median(np.diff(t)))
    band = signal_band_edge_hz(T[["p_rad_s", "q_rad_s", "r_rad_s"]].to_numpy(), dt)

    def lp(x):
        return low_pass_runs(np.asarray(x, float), 1.0 / dt, band, [slice(0, len(x))])

    sig = {k: (x if k == "t" else lp(x)) for k, x in B.truth_signals(T).items()}
    y = lp((T["Cm"] + T["Cm_prop"]).to_numpy())
    model = default_models(vehicle)["Cm"]
    half = 1.0 / dt  # the filter's start and end transients left out (1 s)
    keep = slice(int(half), -int(half))
    scale = vehicle.length_pitch_m / (2 * sig["V"])
    alpha_dots = {"jsbsim": sig["alpha_dot_hat"], "central": np.gradient(sig["alpha"], t) * scale,
                  "savgol": smooth_derivative(t, sig["alpha"], None, BAND_DERIVATIVE_CYCLES / band) * scale}
    row = {"vehicle": vehicle_name, "band_hz": band, "Cm_alpha_dot_truth": truth.get("Cm_alpha_dot", 0.0),
           "Cm_q_truth": truth.get("Cm_q", np.nan)}
    for v in VARIANTS:
        m = model if v != "none" else ChannelModel("Cm", tuple(tm for tm in model.terms
                                                                if tm.coefficient != "Cm_alpha_dot"))
        s = dict(sig)
        if v != "none":
            s["alpha_dot_hat"] = alpha_dots[v]
        X = m.regressors(s)
        sol = dict(zip(X.columns, np.linalg.lstsq(X.to_numpy()[keep], y[keep], rcond=None)[0]))
        row[f"{v}_Cm_alpha_pct"] = 100.0 * (sol["Cm_alpha"] / truth["Cm_alpha"] - 1.0)
        row[f"{v}_Cm_alpha_dot"] = sol.get("Cm_alpha_dot", np.nan)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", default="c172x,pa28,OV10,T37,F4N,J3Cub,pc7,c182,p51d,DHC6,F80C,B747,t6texan2,C130,"
                                          "A320,sgs233")
    args = ap.parse_args()
    rows = [one(v) for v in args.vehicles.split(",")]
    lines = [f"# Noise-free C_m,alpha with different alpha-dot regressors, seed 0 ({date.today()})", "",
             "`python bench/bench_alpha_dot_oracle.py` (docstring: what each column is). C_m,alpha error % of the "
             "at-trim truth; in brackets the fitted C_m,alpha_dot.", "",
             "| aircraft | band [Hz] | C_m,alpha_dot / C_m,q truth | " + " | ".join(VARIANTS) + " |",
             "|---|---|---|" + "---|" * len(VARIANTS)]
    for r in rows:
        cells = [f"{r[f'{v}_Cm_alpha_pct']:+.1f}" + ("" if v == "none" else f" ({r[f'{v}_Cm_alpha_dot']:.1f})")
                 for v in VARIANTS]
        lines.append(f"| {r['vehicle']} | {r['band_hz']:.2f} | {r['Cm_alpha_dot_truth']:.1f} / {r['Cm_q_truth']:.1f} | "
                     + " | ".join(cells) + " |")
    out = Path(__file__).resolve().parent / "results" / "alpha_dot_oracle.md"
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
