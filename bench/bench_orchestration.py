"""Orchestration overhead: `aerosid run` (Prefect flow, Parquet between stages, ledger)
on a 10-minute 100 Hz flight, against the core alone (aerosid.ebm.process_telemetry)
on the same telemetry.  Target: <= 30 s wall end to end.

    python bench/bench_orchestration.py            # writes bench/results/orchestration.md
"""
from __future__ import annotations

import os
import platform
import subprocess
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

import pandas as pd

from aerosid.ebm import process_telemetry
from aerosid.simulation import load_case, simulate
from machine import cpu_model  # bench/machine.py




def main() -> None:
    tmp = Path(tempfile.mkdtemp(prefix="aerosid-bench-"))
    case = load_case("seed-rlv", duration_s=600.0, sample_rate_hz=100.0)
    t0 = time.perf_counter()
    flight = simulate(case, seed=0)
    t_sim = time.perf_counter() - t0
    flight.write(tmp / "flight")
    raw = pd.read_parquet(tmp / "flight" / "telemetry.parquet")
    process_telemetry(raw.iloc[:3000], case.vehicle, mach_half_width=None)  # JIT warm-up, not timed
    t0 = time.perf_counter()
    core = process_telemetry(raw, case.vehicle)
    t_core = time.perf_counter() - t0

    env = {**os.environ, "PREFECT_HOME": str(tmp / "prefect-home"), "PREFECT_SERVER_ANALYTICS_ENABLED": "false"}
    env.pop("PREFECT_API_URL", None)
    cli = [sys.executable, "-m", "aerosid.cli", "run", str(tmp / "flight" / "telemetry.parquet"),
           "--out", str(tmp / "run")]
    rows = []
    for label in ("fresh PREFECT_HOME", "warm PREFECT_HOME", "warm, all stages cached"):
        if label.startswith("warm PREFECT") and (tmp / "run").exists():
            import shutil

            shutil.rmtree(tmp / "run")
        t0 = time.perf_counter()
        subprocess.run(cli, env=env, check=True, capture_output=True)
        rows.append((label, time.perf_counter() - t0))
    lines = [
        "# Orchestration overhead (10-minute flight, 100 Hz, 60,001 samples)", "",
        f"Machine: {cpu_model()}, {os.cpu_count()} cores, Python {platform.python_version()}; {date.today()}", "",
        f"- simulate the flight: {t_sim:.1f} s",
        f"- core alone (aerosid.ebm.process_telemetry, numba warm): {t_core:.1f} s "
        f"({len(core.smoothed)} segments, {len(core.flight_data)} flight-data rows)",
    ]
    lines += [f"- `aerosid run` end to end, {label}: {wall:.1f} s" for label, wall in rows]
    lines += ["", "Target: <= 30 s wall end to end (`aerosid run`). The difference to the core is Prefect's",
              "ephemeral API server start (a fresh PREFECT_HOME also builds its SQLite database), the",
              "Parquet writes with schema validation, the ledger, and numba's cached-JIT load in a new process."]
    out = Path(__file__).parent / "results" / "orchestration.md"
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
