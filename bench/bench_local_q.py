"""Local (time-varying) process noise, before/after (aerosid.estimation.local_q, issue 16 item 3).

    python bench/bench_local_q.py OUT.csv F4N:0-4 T37:0-4 pa28:0-2 seed-rlv:0-2 c172x:0-2

Runs bench_generalisation.one (simulate, process_telemetry with the vehicle file's defaults)
for each vehicle:seeds and writes one row per run, with C_Y_beta added to the coefficients.
Run it from two trees (before / after) and compare the CSVs; the recorded comparison is
bench/results/local_q.md.  One process, ~15-40 s per run on the shared 2-core machine.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
import pandas as pd  # noqa: E402

import bench_generalisation as bg  # noqa: E402
from bench_accuracy import parse_seeds  # noqa: E402

bg.COEFFICIENTS["CY_beta"] = "CY_beta"


def main() -> None:
    out = sys.argv[1]
    jobs = [(v, s) for spec in sys.argv[2:] for v, ss in [spec.split(":")] for s in parse_seeds(ss)]
    rows = []
    for job in jobs:
        t0 = time.time()
        r = bg.one(job)
        rows.append(r)
        errs = {k: round(r.get(f"{k}_err_pct", float("nan")), 1)
                for k in ("Cn_beta", "Cn_r", "Cn_delta", "Cl_p", "CY_beta", "Cm_alpha")}
        print(job, f"{time.time() - t0:.0f} s", errs, r.get("failed"), "|", r.get("findings"), flush=True)
        pd.DataFrame(rows).to_csv(out, index=False)


if __name__ == "__main__":
    main()
