"""Fixed cost of `aerosid run`: a 10 s seed-rlv flight (1,001 samples at 100 Hz, no
faults: the default flight's 2 s sync gap would leave no 5 s segment; the flight spans
Mach 12.9-13.1, hence --mach-half-width 1), where
the numerics are a small share, so the wall and CPU time are mostly start-up: imports,
Prefect's ephemeral API server, the report.

    python bench/bench_fixed_cost.py [--label before|after] [--repeat N] [--tree CHECKOUT]

Each `aerosid run` is a fresh process.  "cold" = a fresh PREFECT_HOME (Prefect builds
its SQLite database), "warm" = the same PREFECT_HOME again with a new run folder (every
stage computed), "cached" = the same run folder again (every stage reused).  CPU time is
user + sys of the child process and its children (the Prefect server; resource.getrusage).
"to flow start" is the wall time from launching the command to Prefect's "Beginning flow
run" line (imports, pre-flight, server start).  --tree runs another checkout's code (e.g.
the code before a change, from `git worktree add`).  Appends a block to
bench/results/fixed_cost.md.
"""
from __future__ import annotations

import argparse
import os
import platform
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

from machine import cpu_model, loadavg  # bench/machine.py

ROOT = Path(__file__).resolve().parents[1]


def _flow_start(text: str, t0_wall: float) -> float:
    """Seconds from t0_wall (epoch) to the log line 'Beginning flow run' (NaN if none)."""
    for line in text.splitlines():
        if "Beginning flow run" in line:
            hms = line.split("|")[0].strip()
            t = datetime.strptime(hms, "%H:%M:%S.%f")
            start = datetime.fromtimestamp(t0_wall)
            stamp = start.replace(hour=t.hour, minute=t.minute, second=t.second, microsecond=t.microsecond)
            return (stamp - start).total_seconds()
    return float("nan")


def timed(cmd: list[str], env: dict) -> tuple[float, float, int, float]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0, t0_wall = time.perf_counter(), time.time()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if proc.returncode != 0:
        sys.stderr.write(proc.stdout[-3000:] + proc.stderr[-3000:])
    return wall, cpu, proc.returncode, _flow_start(proc.stdout + proc.stderr, t0_wall)


def _free_port() -> int:
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _with_running_server(py: str, env: dict, tel: str, tmp: Path) -> list:
    """`aerosid run` while a `prefect server start` runs: found on its address
    (PREFECT_SERVER_API_PORT, no PREFECT_API_URL), and named by PREFECT_API_URL."""
    import httpx

    port = _free_port()
    home = tmp / "prefect-home-server"
    e = {**env, "PREFECT_HOME": str(home), "PREFECT_SERVER_API_PORT": str(port), "PREFECT_UI_ENABLED": "false"}
    server = subprocess.Popen([py, "-m", "prefect", "server", "start", "--port", str(port)], env=e,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    rows = []
    try:
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < 600:
            try:
                if httpx.get(f"http://127.0.0.1:{port}/api/health", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            time.sleep(0.5)
        for label, extra in (("found on its address", {}),
                             ("PREFECT_API_URL set", {"PREFECT_API_URL": f"http://127.0.0.1:{port}/api"})):
            out = tmp / f"run-server-{len(rows)}"
            run = [py, "-m", "aerosid.cli", "run", tel, "--out", str(out), "--mach-half-width", "1"]
            rows.append((f"aerosid run, a `prefect server start` already running, {label}", *timed(run, {**e, **extra})))
    finally:
        server.terminate()
        try:
            server.wait(timeout=30)
        except subprocess.TimeoutExpired:
            server.kill()
    return rows


def _commit(tree: Path) -> str:
    proc = subprocess.run(["git", "-C", str(tree), "log", "-1", "--format=%h"], capture_output=True, text=True)
    return proc.stdout.strip() or "?"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--label", default="now")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--tree", type=Path, default=ROOT, help="checkout whose code runs (default: this one)")
    ap.add_argument("--with-server", action="store_true",
                    help="also run against an already running `prefect server start` (on a free port)")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="aerosid-fixed-"))
    env = {**os.environ, "PREFECT_SERVER_ANALYTICS_ENABLED": "false", "PYTHONPATH": str(args.tree.resolve())}
    env.pop("PREFECT_API_URL", None)
    py = sys.executable
    subprocess.run([py, "-m", "aerosid.cli", "simulate", "--case", "seed-rlv", "--duration", "10", "--seed", "0",
                    "--no-faults", "--out", str(tmp / "flight")], env=env, check=True, capture_output=True)
    tel = str(tmp / "flight" / "telemetry.parquet")
    load_before = loadavg()
    rows = []
    imports = {"python -c pass": [py, "-c", "pass"],
               "import aerosid.cli": [py, "-c", "import aerosid.cli"],
               "aerosid --help": [py, "-m", "aerosid.cli", "--help"],
               "import flows.pipeline": [py, "-c", "import flows.pipeline"]}
    for label, cmd in imports.items():
        best = min((timed(cmd, env) for _ in range(3)), key=lambda r: r[0])
        rows.append((label, *best))
    for k in range(args.repeat):
        home = tmp / f"prefect-home-{k}"
        e = {**env, "PREFECT_HOME": str(home)}
        run = [py, "-m", "aerosid.cli", "run", tel, "--out", str(tmp / f"run-{k}"), "--mach-half-width", "1"]
        rows.append((f"aerosid run, cold (fresh PREFECT_HOME) #{k + 1}", *timed(run, e)))
        shutil.rmtree(tmp / f"run-{k}")
        rows.append((f"aerosid run, warm PREFECT_HOME #{k + 1}", *timed(run, e)))
        rows.append((f"aerosid run, warm, every stage cached #{k + 1}", *timed(run, e)))
    if args.with_server:
        rows += _with_running_server(py, env, tel, tmp)
    lines = [f"### {args.label}: {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC", "",
             f"Code: {args.tree.resolve()} ({_commit(args.tree)}). Machine: {cpu_model()}, {os.cpu_count()} cores, "
             f"Python {platform.python_version()}, load average before {load_before} (other processes share "
             "the machine)", "",
             "| what | wall [s] | CPU user+sys [s] | to flow start [s] | exit |", "|---|---:|---:|---:|---:|"]
    lines += [f"| {label} | {wall:.1f} | {cpu:.1f} | {start:.1f} | {rc} |" for label, wall, cpu, rc, start in rows]
    lines += ["", f"load average after: {loadavg()}", ""]
    text = "\n".join(lines)
    print(text)
    out = ROOT / "bench" / "results" / "fixed_cost.md"
    head = "" if out.exists() else (
        "# Fixed cost of `aerosid run` (10 s flight, 1,001 samples)\n\n"
        "Written by `bench/bench_fixed_cost.py`; each block is one invocation.\n\n")
    with open(out, "a") as fh:
        fh.write(head + text + "\n")
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
