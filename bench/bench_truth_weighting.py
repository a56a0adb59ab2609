"""How a piecewise-linear JSBSim table's slope is weighted by a flight (issue 16, beside the
flight-averaged truth of bench/generalisation_avg.py).

    python bench/bench_truth_weighting.py [--aircraft c172x,pa28,OV10,T37,F4N]
    -> bench/results/truth_weighting.md

For each aircraft's bench flight (the truth does not depend on the seed) and each of
CN_alpha, Cm_alpha, Cm_delta_p: the model along ONE variable v (alpha or the elevator), every
other input held at the trim sample, and three slopes of it, in % of the at-trim truth:
the uniform mean of dC/dv over the flight's v samples (what the flight-averaged truth does
for that variable), and the least-squares slope Cov(v, C(v)) / Var(v) over the same samples
(what a linear fit on v alone estimates: it weights the derivative at a level t by
E[(v - mean v) 1{v > t}], i.e. by the large excursions, where the uniform mean weights by time;
the two agree for Gaussian v, Stein's lemma).  The "full average" column is the flight-averaged
truth (every input at its sample's value).  The simulators' record is captured by wrapping
the hooks that compute the flight-averaged truth (no copy of the simulators).
"""
from __future__ import annotations

import argparse
from datetime import date
from pathlib import Path

import numpy as np

CASES = (("alpha", "CN", "CN_alpha"), ("alpha", "Cm", "Cm_alpha"), ("delta_p", "Cm", "Cm_delta_p"))


def captured_flight(aircraft: str):
    """(flight, evaluate with every input at the trim sample, the flight's state x)."""
    import aerosid.simulation.jsbsim_aircraft as ja
    import aerosid.simulation.jsbsim_truth_avg as m
    from aerosid.simulation.jsbsim_flight import simulate_jsbsim

    cap = {}
    og, oc = ja.generated_flight_average, m.c172x_flight_average
    ja.generated_flight_average = lambda *a: (cap.__setitem__("g", a), og(*a))[1]
    m.c172x_flight_average = lambda *a: (cap.__setitem__("c", a), oc(*a))[1]
    try:
        flight = simulate_jsbsim(aircraft, "3211", 0, faults=False)
    finally:
        ja.generated_flight_average, m.c172x_flight_average = og, oc
    if "g" in cap:
        tables, rec, ctl, gains = cap["g"]
        n = len(rec["aero/alpha-rad"])
        at_trim = {k: np.full(n, np.asarray(v)[0]) for k, v in rec.items()}
        evaluate, x0 = m.generated_state(tables, at_trim, ctl, gains)
        _, x = m.generated_state(tables, rec, ctl, gains)
        return flight, evaluate, x0, x
    tables, rec, truth, arm, c, b = cap["c"]
    n = len(truth)
    x = {"alpha": truth["alpha_rad"].to_numpy(), "beta": truth["beta_rad"].to_numpy(),
         "delta_p": truth["delta_p_rad"].to_numpy(), "delta_r": np.asarray(rec["fcs/effective-aileron-pos"]),
         "delta_y": truth["delta_y_rad"].to_numpy(),
         **{k: truth[k].to_numpy() for k in ("p_hat", "q_hat", "r_hat", "alpha_dot_hat")}}
    at_trim = {k: np.full(n, np.asarray(v)[0]) for k, v in rec.items()}
    arm0 = tuple(np.full(n, np.asarray(a)[0]) for a in arm)
    evaluate, x0 = m.c172x_state(tables, at_trim, {k: np.full(n, v[0]) for k, v in x.items()}, arm0, c, b)
    return flight, evaluate, x0, x


def slopes(evaluate, x0: dict, v: np.ndarray, var: str, coef: str, h: float = 1e-4) -> tuple[float, float]:
    """(uniform mean of dC/dv, least-squares slope of C on v) over the samples v."""
    xs = dict(x0)
    xs[var] = v
    hi, lo = dict(xs), dict(xs)
    hi[var], lo[var] = v + h, v - h
    d = (evaluate(hi)[coef] - evaluate(lo)[coef]) / (2 * h)
    g = evaluate(xs)[coef]
    return float(d.mean()), float(np.sum((v - v.mean()) * (g - g.mean())) / np.sum((v - v.mean()) ** 2))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--aircraft", default="c172x,pa28,OV10,T37,F4N")
    args = ap.parse_args()
    lines = ["# Table slopes as a flight weights them", "", f"{date.today()}; bench/bench_truth_weighting.py "
             "(docstring: definitions).  % of the at-trim truth; the model along one variable, every other input "
             "at the trim sample; 'full average' = the flight-averaged truth (every input at its sample).", "",
             "| aircraft | derivative | at-trim truth | range of the variable over the flight | uniform mean % | "
             "least-squares slope % | full average % |", "|---|---|---|---|---|---|---|"]
    for ac in args.aircraft.split(","):
        flight, evaluate, x0, x = captured_flight(ac)
        for var, coef, name in CASES:
            v = np.asarray(x[var], float)
            mean, ls = slopes(evaluate, x0, v, var, coef)
            tr = flight.coefficients[name]
            full = flight.info["coefficients_flight_average"][name]
            span = f"{np.degrees(v.min()):+.2f}..{np.degrees(v.max()):+.2f} deg (trim {np.degrees(v[0]):+.2f})"
            lines.append(f"| {ac} | {name} | {tr:.5g} | {span} | {100 * (mean / tr - 1):+.2f} | "
                         f"{100 * (ls / tr - 1):+.2f} | {100 * (full / tr - 1):+.2f} |")
    text = "\n".join(lines) + "\n"
    (Path(__file__).parent / "results" / "truth_weighting.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
