"""Would a model-structure rule for C_m,alpha_dot help?  Each JSBSim flight is simulated and run
through the pipeline once; the default Cm model is then fitted with and without its
Cm_alpha_dot term (t of that term with the coloured-residual sigma recorded).

    python bench/bench_adot_structure.py pa28,F4N,OV10,T37,c172x 4
    -> bench/results/adot_structure_runs.csv (results and reading: bench/results/adot_structure.md)
"""
import sys
import tempfile
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pandas as pd
sys.path.insert(0, str(Path(__file__).resolve().parent))

def one(job):
    veh, seed = job
    warnings.simplefilter("ignore")
    import bench_generalisation as bg
    from aerosid.ebm import process_telemetry
    from aerosid.identification.identify import identify
    from aerosid.modelling.models import default_models, ChannelModel
    with tempfile.TemporaryDirectory() as tmp:
        fl, v = bg.simulate(veh, seed, Path(tmp))
        run = process_telemetry(fl.telemetry, v)
    fd = run.flight_data
    rows = []
    tr = {k: bg.truth_of(fl, k) for k in ("Cm_alpha", "Cm_delta", "damping")}
    base = default_models(v)
    for tag in ("default", "no_adot"):
        ms = dict(base)
        if tag == "no_adot":
            ms["Cm"] = ChannelModel("Cm", tuple(t for t in base["Cm"].terms if t.coefficient != "Cm_alpha_dot"))
        ident = identify(fd, v, ms, bias_pairs=0)  # as recorded
        row = {"vehicle": veh, "seed": seed, "variant": tag}
        tab = ident.table().set_index("coefficient")
        if "Cm_alpha_dot" in tab.index:
            row["adot_t"] = float(tab.loc["Cm_alpha_dot", "estimate"] / tab.loc["Cm_alpha_dot", "std_error"])
            row["adot_est"] = float(tab.loc["Cm_alpha_dot", "estimate"])
        for name in ("Cm_alpha", "Cm_delta", "damping"):
            est, se = bg.estimate_of(ident, name)
            t = tr[name]
            row[f"{name}_err"] = 100 * (est / t - 1)
            row[f"{name}_cover"] = abs(est - t) <= 1.96 * se
        rows.append(row)
    return rows

if __name__ == "__main__":
    vehs = sys.argv[1].split(","); seeds = range(int(sys.argv[2]))
    jobs = [(v, s) for v in vehs for s in seeds]
    out = []
    with ProcessPoolExecutor(2) as ex:
        for rows in ex.map(one, jobs):
            out += rows
            print(rows[0]["vehicle"], rows[0]["seed"], " | ".join(f"{r['variant']}: a {r['Cm_alpha_err']:+.1f} d {r['Cm_delta_err']:+.1f} q {r['damping_err']:+.1f} t_adot {r.get('adot_t', float('nan')):+.1f}" for r in rows), flush=True)
    pd.DataFrame(out).to_csv(Path(__file__).resolve().parent / "results" / "adot_structure_runs.csv", index=False)
