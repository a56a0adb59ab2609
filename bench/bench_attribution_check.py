"""Before/after check of a change found by the attribution (bench/bench_attribution.py): the
full pipeline (bench_generalisation.one, default settings) on a few seeds per vehicle, with
the code of the tree this file is run from.

    PYTHONPATH=<tree> python <tree>/bench/bench_attribution_check.py --label after \\
        [--vehicles F4N,OV10,pa28,c172x,seed-rlv] [--seeds 0-4] [--out results/attribution_check.csv]

Rows are appended to the CSV with the label; bench/results/attribution.md quotes them.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
from bench_accuracy import parse_seeds  # noqa: E402
from bench_generalisation import one  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--label", required=True)
    ap.add_argument("--vehicles", default="F4N,OV10,pa28,c172x,seed-rlv")
    ap.add_argument("--seeds", default="0-4")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "attribution_check.csv"))
    args = ap.parse_args()
    rows = []
    for v in args.vehicles.split(","):
        for s in parse_seeds(args.seeds):
            t0 = time.perf_counter()
            row = one((v, s))
            row["label"] = args.label
            rows.append(row)
            print(f"{args.label} {v} seed {s}: {time.perf_counter() - t0:.0f} s "
                  f"Cm_alpha {row.get('Cm_alpha_err_pct', float('nan')):+.1f} % "
                  f"Cm_delta {row.get('Cm_delta_err_pct', float('nan')):+.1f} % "
                  f"damping {row.get('damping_err_pct', float('nan')):+.1f} %", flush=True)
    df = pd.DataFrame(rows).drop(columns=["traceback"], errors="ignore")
    out = Path(args.out)
    if out.exists():
        df = pd.concat([pd.read_csv(out, dtype={"failed": str, "findings": str, "silent_failure": str}), df],
                       ignore_index=True)
    df.to_csv(out, index=False, float_format="%.6g")


if __name__ == "__main__":
    main()
