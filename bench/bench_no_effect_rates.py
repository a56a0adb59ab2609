"""False alarms of the diagnosis on flights with nothing hidden, at other sample rates.

The look-alike and localisation benches fly seed-rlv at its 100 Hz.  A flight logged at 50 Hz
carries twice the in-band noise per sample in the angles inverted from the accelerometers
(beta's error went from ~0.9e-3 to 1.2e-3 rad against beta's 3.5e-3 rad spread), and the
errors-in-variables checks must hold there too.  Each seed: simulate seed-rlv with no hidden
effect at --rate, the estimation chain (preprocess -> EKF/MBF -> band-path flight data),
`diagnose` the default models; recorded: the recommendation, whether the loop closes, the three
candidates with the smallest p, and the significant localisation findings.

    python bench/bench_no_effect_rates.py --rate 50 --seeds 0-9 --jobs 2
    -> bench/results/no_effect_rate50.md, bench/results/no_effect_rate50_runs.csv
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from datetime import date
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from machine import cpu_model, loadavg  # noqa: E402


def one(job: tuple[float, int]) -> dict:
    from aerosid.diagnosis import diagnose
    from aerosid.ebm import estimate_flight_data
    from aerosid.simulation import load_case, simulate

    rate, seed = job
    t0 = time.perf_counter()
    case = dataclasses.replace(load_case("seed-rlv"), sample_rate_hz=rate)
    flight = simulate(case, (), seed=seed)
    fd = estimate_flight_data(flight.telemetry, case.vehicle, flight="flight").flight_data
    d = diagnose(fd, case.vehicle)
    top = sorted((e for e in d.effects if e.identifiable), key=lambda e: e.p_value)[:3]
    found = [f"{f.channel}: {f.suggested_expression}" for fs in d.localisation.values() for f in fs if f.significant]
    return {"rate_hz": rate, "seed": seed, "band_hz": float(fd["band_hz"].iloc[0]),
            "recommended": d.recommended or "", "loop_closed": bool(d.loop_closed),
            "top": "; ".join(f"{e.name} p={e.p_value:.1g}{' *' if e.significant else ''}" for e in top),
            "localised": "; ".join(found), "seconds": time.perf_counter() - t0}


def _seeds(text: str) -> list[int]:
    a, _, b = text.partition("-")
    return list(range(int(a), int(b) + 1)) if b else [int(a)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rate", type=float, default=50.0, help="sample rate [Hz]")
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args()
    seeds = _seeds(args.seeds)
    load0, t0 = loadavg(), time.perf_counter()
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(one, [(args.rate, s) for s in seeds]))
    df = pd.DataFrame(rows)
    name = f"no_effect_rate{args.rate:g}"
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    df.to_csv(out / f"{name}_runs.csv", index=False)
    n = len(df)
    L = [f"# No hidden effect, seed-rlv at {args.rate:g} Hz: what the diagnosis says ({n} seeds)", "",
         f"{date.today()}, {cpu_model()}, {os.cpu_count()} cores, load {load0} -> {loadavg()}; wall "
         f"{(time.perf_counter() - t0) / 60:.1f} min. `python bench/bench_no_effect_rates.py --rate {args.rate:g} "
         f"--seeds {args.seeds}`.", "",
         f"Something recommended: {int((df['recommended'] != '').sum())}/{n}; loop closed: "
         f"{int(df['loop_closed'].sum())}/{n}; a significant localisation finding: "
         f"{int((df['localised'] != '').sum())}/{n}.", "",
         "| seed | band [Hz] | recommended | loop closed | three smallest p (* significant) | significant localisation |",
         "|---|---|---|---|---|---|"]
    for r in df.itertuples():
        L.append(f"| {r.seed} | {r.band_hz:.2f} | {r.recommended or '-'} | {r.loop_closed} | {r.top} | "
                 f"{r.localised or '-'} |")
    (out / f"{name}.md").write_text("\n".join(L) + "\n")
    print("\n".join(L))


if __name__ == "__main__":
    main()
