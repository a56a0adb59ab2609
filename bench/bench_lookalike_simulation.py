"""Issue 18: do look-alike models differ when they are *simulated*?  On the real pipeline.

The diagnosis compares look-alike candidates (control_alpha and alpha_nonlinearity on
seed-rlv: their columns correlate by r ~ 0.95) by equation error, where both lower the
residual by about as much and the floor of the flight-derived coefficient hides the rest.
An output-error simulation integrates the model's error over time instead.  Each run:

* seed-rlv with one hidden look-alike (scale 1, Table 2 noise, the INS attitude in the
  telemetry), the estimation chain in memory (preprocess -> EKF/MBF -> band-path flight data);
* three models identified by equation error on it (``identify``): the default, the default
  + the true term, the default + its look-alike;
* each simulated with that flight's measured controls, airspeed, dynamic pressure and attitude
  (aerosid validate's output prediction, lon axis, output offsets; C_N from the preflight
  database), on the flight itself ("own") and on another flight of the same vehicle with the same
  hidden effect (seed + 100, "other": what `aerosid validate RUN OTHER --version vNNN` gives);
* recorded: the RMS of the predicted minus the measured alpha (and q, a_z) per model.

``true_better`` = the true term's simulated alpha is closer to the measured one than the
look-alike's.  ``--effects none``: nothing hidden, "true" = + control_alpha and "wrong" = +
alpha_nonlinearity, both spurious: how much a term the flight does not have lowers the errors.  Nothing here is tuned: the models are the catalogue's terms, the simulation is
validate's.

    python bench/bench_lookalike_simulation.py --seeds 0-9 --jobs 2
    -> bench/results/lookalike_simulation.md, bench/results/lookalike_simulation_runs.csv
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from datetime import date
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
from bench_accuracy import parse_seeds  # noqa: E402
from machine import cpu_model  # noqa: E402

WRONG = {"control_alpha": "alpha_nonlinearity", "alpha_nonlinearity": "control_alpha"}
#: --effects none: nothing hidden; "true" and "wrong" are then these two terms, added to a model that
#: misses nothing (how far a term the flight does not have lowers the simulated error)
NONE_TERMS = ("control_alpha", "alpha_nonlinearity")
OTHER_SEED_OFFSET = 100
OUTPUTS = ("alpha_rad", "q_rad_s", "az_m_s2")


def _estimated(name: str, seed: int):
    """(flight data, preprocessed frame, raw telemetry) of seed-rlv with `name` hidden."""
    from aerosid.ebm import estimate_flight_data
    from aerosid.modelling.effects import CATALOGUE
    from aerosid.simulation import load_case, simulate

    case = load_case("seed-rlv")
    flight = simulate(case, () if name == "none" else ((CATALOGUE[name], 1.0),), seed=seed)
    est = estimate_flight_data(flight.telemetry, case.vehicle, flight="flight")
    fd = est.flight_data.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    return fd, est.preprocessed.frame, flight.telemetry


def _simulated_errors(model, fd, pre, raw, vehicle) -> dict:
    """RMS(predicted - measured) per lon output over the Mach window's spans (output offsets)."""
    from aerosid.identification.identify import mach_window_mask
    from aerosid.identification.output_prediction import predict_axis, prediction_inputs
    from aerosid.identification.validate import attitude_on, measured_outputs, spans_of

    span = spans_of(fd, mach_window_mask(fd["mach"].to_numpy(), vehicle.mach_reference, 0.5))
    att = attitude_on(raw, fd["t_s"].to_numpy(float), "telemetry")
    inputs = prediction_inputs(fd, vehicle, att[0], att[1], span)
    meas, _ = measured_outputs(pre, fd, vehicle)
    f = predict_axis(model, inputs, meas, vehicle, "lon", "offsets").frame
    use = f["span"].to_numpy() >= 0
    out = {}
    for o in OUTPUTS:
        d = (f[f"predicted_{o}"] - f[f"measured_{o}"]).to_numpy()[use]
        out[o] = float(np.sqrt(np.nanmean(d ** 2)))
    return out


def one(job: tuple[str, int]) -> dict:
    from aerosid.identification.identified import IdentifiedModel, with_preflight_identities
    from aerosid.identification.identify import identify
    from aerosid.modelling.models import default_models, parse_term
    from aerosid.simulation import load_case

    name, seed = job
    t0 = time.perf_counter()
    vehicle = load_case("seed-rlv").vehicle
    row = {"effect": name, "seed": seed, "other_seed": seed + OTHER_SEED_OFFSET}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        own = _estimated(name, seed)
        other = _estimated(name, seed + OTHER_SEED_OFFSET)
        variants = {"default": dict(default_models(vehicle))}
        terms = NONE_TERMS if name == "none" else (name, WRONG[name])
        for tag, term in zip(("true", "wrong"), terms):
            ms = dict(default_models(vehicle))
            ms["Cm"] = ms["Cm"].with_term(parse_term(term, "Cm"))
            variants[tag] = ms
        for tag, ms in variants.items():
            ident = identify(own[0], vehicle, ms, bias_pairs=0)
            tab = ident.table()
            model = IdentifiedModel(ms, dict(zip(tab["coefficient"], tab["estimate"])), tag)
            model, _ = with_preflight_identities(model, vehicle)
            row[f"{tag}_cm_rms_residual"] = float(ident.fits["Cm"].rms_residual)
            for where, (fd, pre, raw) in (("own", own), ("other", other)):
                for o, v in _simulated_errors(model, fd, pre, raw, vehicle).items():
                    row[f"{tag}_{where}_{o}"] = v
    for where in ("own", "other"):
        row[f"true_better_{where}"] = bool(row[f"true_{where}_alpha_rad"] < row[f"wrong_{where}_alpha_rad"])
    row["true_better_residual"] = bool(row["true_cm_rms_residual"] < row["wrong_cm_rms_residual"])
    row["seconds"] = time.perf_counter() - t0
    print(name, seed, " ".join(f"{k} {row[k]}" for k in ("true_better_residual", "true_better_own",
                                                          "true_better_other")),
          f"alpha own {row['default_own_alpha_rad']:.2e} -> true {row['true_own_alpha_rad']:.2e} / wrong "
          f"{row['wrong_own_alpha_rad']:.2e}", flush=True)
    return row


def _drop(g: pd.DataFrame, what: str) -> str:
    d = 1 - g[f"true_{what}"] / g[f"default_{what}"]
    return f"{d.mean():.0%}, {d.min():.0%}, {d.max():.0%}"


def _ratio(g: pd.DataFrame, what: str) -> str:
    r = g[f"wrong_{what}"] / g[f"true_{what}"]
    return f"{r.min():.3f}..{r.max():.3f}"


def report(df: pd.DataFrame, cmd: str, wall_s: float, load: tuple[str, str]) -> str:
    lines = ["# Look-alikes simulated: does the true term predict the flight better?", "",
             f"{date.today()}, `{cmd}`, Python {platform.python_version()}, {cpu_model()}, load {load[0]} (start) / "
             f"{load[1]} (end), wall {wall_s / 60:.1f} min.", "",
             "Definitions: bench/bench_lookalike_simulation.py (docstring). alpha RMS: RMS(simulated - measured "
             "alpha) [rad] over the Mach window's spans, output offsets removed; own: the flight the models were "
             "identified on; other: seed + 100 with the same hidden effect. Residual: the equation-error fit's "
             "in-sample RMS residual of C_m (the diagnosis compares held-out errors).", "",
             "| hidden effect | runs | true term better by: C_m residual | simulated alpha, own flight | "
             "simulated alpha, other flight | alpha RMS own: default -> true / look-alike (mean) | "
             "alpha RMS other: default -> true / look-alike (mean) | C_m residual: default -> true / look-alike | "
             "adding the true term, drop of: C_m residual (mean, min, max) | simulated alpha, own (mean, min, max) | "
             "look-alike / true: C_m residual (min..max) | simulated alpha, own (min..max) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, g in df.groupby("effect", sort=False):
        n = len(g)
        def m(c):
            return float(g[c].mean())
        lines.append(
            f"| {name} | {n} | {int(g['true_better_residual'].sum())}/{n} | {int(g['true_better_own'].sum())}/{n} | "
            f"{int(g['true_better_other'].sum())}/{n} | {m('default_own_alpha_rad'):.2e} -> "
            f"{m('true_own_alpha_rad'):.2e} / {m('wrong_own_alpha_rad'):.2e} | {m('default_other_alpha_rad'):.2e} -> "
            f"{m('true_other_alpha_rad'):.2e} / {m('wrong_other_alpha_rad'):.2e} | "
            f"{m('default_cm_rms_residual'):.3e} -> {m('true_cm_rms_residual'):.3e} / "
            f"{m('wrong_cm_rms_residual'):.3e} | {_drop(g, 'cm_rms_residual')} | {_drop(g, 'own_alpha_rad')} | "
            f"{_ratio(g, 'cm_rms_residual')} | {_ratio(g, 'own_alpha_rad')} |")
    lines += ["", "Per-run rows: `bench/results/lookalike_simulation_runs.csv`."]
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--effects", default=",".join(WRONG))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results"))
    ap.add_argument("--report-only", action="store_true", help="rewrite the .md from the recorded runs CSV")
    args = ap.parse_args()
    out = Path(args.out)
    if args.report_only:
        md = out / "lookalike_simulation.md"
        head = md.read_text().splitlines()[2]  # the recorded run's date, command, machine, wall time
        text = report(pd.read_csv(out / "lookalike_simulation_runs.csv"), "", 0.0, ("", "")).splitlines()
        md.write_text("\n".join(text[:2] + [head] + text[3:]) + "\n")
        print(md.read_text())
        return
    jobs = [(e, s) for e in args.effects.split(",") for s in parse_seeds(args.seeds)]
    load0 = " ".join(f"{x:.2f}" for x in os.getloadavg())
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(one, jobs))
    wall = time.perf_counter() - t0
    df = pd.DataFrame(rows)
    df.to_csv(out / "lookalike_simulation_runs.csv", index=False)
    cmd = "python bench/bench_lookalike_simulation.py " + " ".join(sys.argv[1:])
    (out / "lookalike_simulation.md").write_text(
        report(df, cmd, wall, (load0, " ".join(f"{x:.2f}" for x in os.getloadavg()))))
    print((out / "lookalike_simulation.md").read_text())


if __name__ == "__main__":
    main()
