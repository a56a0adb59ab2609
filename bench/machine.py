"""What machine a benchmark ran on (recorded beside every result), and how its jobs share it."""
from __future__ import annotations

import os
import platform
from concurrent.futures import ProcessPoolExecutor
from datetime import date
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


def run_line(load: tuple[str, str], jobs: int, wall_s: float) -> str:
    """The line every bench record opens with: date, Python, machine, its load at the start and the
    end, the worker processes and the wall time (no closing full stop)."""
    return (f"{date.today().isoformat()}, Python {platform.python_version()}, machine: {cpu_model()}, "
            f"{os.cpu_count()} cores, load average {load[0]} (start) / {load[1]} (end); {jobs} process(es), "
            f"wall time {wall_s / 60:.1f} min")


def seed_range(text: str) -> list[int]:
    """"3" -> [3]; "0-4" -> [0, 1, 2, 3, 4] (a bench's --seeds)."""
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))
