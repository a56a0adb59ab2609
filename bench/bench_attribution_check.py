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


def summary(df: pd.DataFrame) -> str:
    """Markdown: per vehicle and label, mean / RMS error % and 95 % coverage of Cm_alpha, Cm_delta,
    damping, and the oracle's mean error % (what the model structure gives on the flight)."""
    names = ("Cm_alpha", "Cm_delta", "damping")
    lines = ["| vehicle | code | runs | " + " | ".join(f"{n} mean / RMS / cover (oracle)" for n in names) + " |",
             "|---|---|---|" + "---|" * len(names)]
    for v, g in df.groupby("vehicle", sort=False):
        for label, h in g.groupby("label", sort=False):
            ok = h[h["failed"].fillna("") == ""]
            cells = []
            for n in names:
                e = ok[f"{n}_err_pct"].dropna() if f"{n}_err_pct" in ok else pd.Series(dtype=float)
                if e.empty:
                    cells.append("-")
                    continue
                cover = ok[f"{n}_cover"].fillna(False).astype(bool).sum() / len(h)
                orc = ok.get(f"{n}_oracle_pct")
                orc_txt = f" ({orc.mean():+.1f})" if orc is not None and orc.notna().any() else ""
                cells.append(f"{e.mean():+.1f} / {(e ** 2).mean() ** 0.5:.1f} / {cover:.0%}{orc_txt}")
            lines.append(f"| {v} | {label} | {len(ok)} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--label", default=None)
    ap.add_argument("--summary", action="store_true", help="print the markdown summary of --out and stop")
    ap.add_argument("--vehicles", default="F4N,OV10,pa28,c172x,seed-rlv")
    ap.add_argument("--seeds", default="0-4")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "attribution_check.csv"))
    args = ap.parse_args()
    if args.summary:
        print(summary(pd.read_csv(args.out, dtype={"failed": str, "findings": str, "silent_failure": str})))
        return
    if not args.label:
        ap.error("--label is required")
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
