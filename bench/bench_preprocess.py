"""Benchmark: false outliers, false frozen runs and spike detection of the preprocessing stage.

Run:  python bench/bench_preprocess.py [--seeds 0 1 2 3] [--jsbsim-seeds 0 1] [--telemetry FILE ...]
                                       [--label NAME] [--out bench/results/preprocess.md]

* seed-rlv flights with the simulator's faults (``aerosid.simulation``, truth masks
  ``fault_outlier_<channel>``): injected spikes (6..40 sigma offsets on the IMU channels)
  found, and outliers flagged on samples without an injected spike (false outliers);
* JSBSim c172x flights without faults (needs the jsbsim extra): every outlier is false;
* any raw telemetry files given with ``--telemetry`` (e.g. real flight-test data
  converted to the raw contract): outliers, frozen and held samples, rows used.

Only ``aerosid.preprocess.preprocess`` and the frame's flag columns are used, so the same
script measures an older checkout (``PYTHONPATH=/path/to/old/checkout``): that is how the
"before" column of bench/results/preprocess.md was made.
"""
from __future__ import annotations

import argparse
import datetime as _dt
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
from machine import cpu_model as _cpu_model, loadavg as _loadavg  # noqa: E402  (bench/machine.py)


def _count(res, channels, bit):
    return {c: int(((res.frame[f"flags_{c}"].to_numpy() & int(bit)) != 0).sum()) for c in channels}


def _channels(res):
    return [c[len("flags_"):] for c in res.frame.columns if c.startswith("flags_")]


def simulated(seed: int) -> dict:
    from aerosid.preprocess import QualityFlag as F, preprocess
    from aerosid.simulation import load_case, simulate

    fl = simulate(load_case("seed-rlv"), seed=seed)
    res = preprocess(fl.telemetry, source=f"seed-rlv/{seed}")
    tr, fr = fl.truth, res.frame
    k = np.round((fr["t_s"].to_numpy() - tr["t_s"].iloc[0]) * res.nominal_rate_hz).astype(int)
    inj = found = false = 0
    for c in _channels(res):
        f = np.zeros(len(tr), dtype=np.int64)
        f[k] = fr[f"flags_{c}"].to_numpy()
        spike = tr[f"fault_outlier_{c}"].to_numpy().astype(bool) if f"fault_outlier_{c}" in tr else np.zeros(len(tr), bool)
        inj += int(spike.sum())
        found += int(((f[spike] & int(F.OUTLIER | F.OUT_OF_RANGE)) != 0).sum())
        false += int(((f[~spike] & int(F.OUTLIER)) != 0).sum())
    return {"flight": f"seed-rlv seed {seed} (faults)", "samples": len(fr) * len(_channels(res)),
            "spikes": inj, "found": found, "false_outliers": false,
            "frozen": sum(_count(res, _channels(res), F.FROZEN).values())}


def jsbsim(seed: int) -> dict | None:
    from aerosid.preprocess import QualityFlag as F, preprocess

    try:
        from aerosid.simulation.jsbsim_flight import JSBSimUnavailable, simulate_jsbsim
    except ImportError:
        return None
    try:
        flight = simulate_jsbsim("c172x", "3211", seed=seed, faults=False)
    except JSBSimUnavailable:
        return None
    res = preprocess(flight.telemetry, source=f"c172x/{seed}")
    ch = _channels(res)
    out = _count(res, ch, F.OUTLIER)
    return {"flight": f"JSBSim c172x seed {seed} (no faults)", "samples": len(res.frame) * len(ch),
            "spikes": 0, "found": 0, "false_outliers": sum(out.values()),
            "frozen": sum(_count(res, ch, F.FROZEN).values())}


def telemetry_file(path: str) -> dict:
    from aerosid.preprocess import QualityFlag as F, preprocess

    raw = pd.read_parquet(path)
    res = preprocess(raw, source=path)
    ch = _channels(res)
    held = _count(res, ch, F.HELD) if hasattr(F, "HELD") else {}
    used = getattr(res, "n_used_rows", None)
    return {"flight": Path(path).name, "samples": len(res.frame) * len(ch), "spikes": "-", "found": "-",
            "false_outliers": sum(_count(res, ch, F.OUTLIER).values()),
            "frozen": sum(_count(res, ch, F.FROZEN).values()),
            "held": sum(held.values()) if held else "-",
            "usable_rows": f"{res.n_usable_rows} of {res.n_grid_rows}",
            "rows_used": f"{used} of {res.n_raw_rows}" if used is not None else "-",
            "frozen_by_channel": {c: v for c, v in _count(res, ch, F.FROZEN).items() if v},
            "outliers_by_channel": {c: v for c, v in _count(res, ch, F.OUTLIER).items() if v}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="*", default=[0, 1, 2, 3])
    ap.add_argument("--jsbsim-seeds", type=int, nargs="*", default=[0, 1])
    ap.add_argument("--telemetry", nargs="*", default=[])
    ap.add_argument("--label", default="this checkout")
    ap.add_argument("--out", type=Path, default=None, help="append a markdown section to this file")
    a = ap.parse_args()
    rows = [simulated(s) for s in a.seeds] + [r for r in (jsbsim(s) for s in a.jsbsim_seeds) if r]
    rows += [telemetry_file(p) for p in a.telemetry]
    head = ("| flight | channel-samples | injected spikes | found | false outliers | frozen samples | held samples "
            "| usable rows (flags 0) | rows used |")
    lines = [f"## {a.label}", "",
             f"{_dt.datetime.now(_dt.timezone.utc):%Y-%m-%d %H:%M} UTC, {_cpu_model()}, load {_loadavg()}, "
             f"python {sys.version.split()[0]}", "", head, "|" + "---|" * 9]
    for r in rows:
        lines.append(f"| {r['flight']} | {r['samples']} | {r['spikes']} | {r['found']} | {r['false_outliers']} | "
                     f"{r['frozen']} | {r.get('held', '-')} | {r.get('usable_rows', '-')} | {r.get('rows_used', '-')} |")
    for r in rows:
        if r.get("frozen_by_channel") or r.get("outliers_by_channel"):
            lines.append(f"\n{r['flight']}: frozen {r.get('frozen_by_channel')}, outliers {r.get('outliers_by_channel')}")
    text = "\n".join(lines) + "\n"
    print(text)
    if a.out:
        with open(a.out, "a") as fh:
            fh.write("\n" + text)


if __name__ == "__main__":
    main()
