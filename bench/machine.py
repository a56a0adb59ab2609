"""What machine a benchmark ran on (recorded beside every result), and how its jobs share it."""
from __future__ import annotations

import platform
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def loadavg() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "n/a"


def run_jobs(fn, jobs: list, processes: int = 1) -> list:
    """[fn(job) for job in jobs], in that order; in `processes` worker processes when more than one
    (the machine is shared: the benches default to one)."""
    if processes > 1:
        with ProcessPoolExecutor(processes) as pool:
            return list(pool.map(fn, jobs))
    return [fn(j) for j in jobs]
