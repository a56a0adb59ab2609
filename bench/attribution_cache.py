"""Simulated flights and the pipeline's flight data, cached for the attribution bench
(bench/bench_attribution.py): one simulation and one estimation per (vehicle, seed), so the
substitutions refit in seconds.

    python bench/attribution_cache.py --vehicles F4N,OV10,pa28 --seeds 0-3 [--dir /tmp/aerosid-attrib]

Each cache file holds the flight's truth frame and linear truth, the vehicle file's
folder, the pipeline's preprocessed frame, its smoothed segment frames, its flight data
and, per segment, the band-limiting the flight data went through (band edge and the
filter runs of aerosid.identification.band, captured from aerosid.identification.flight_data)."""
from __future__ import annotations

import argparse
import pickle
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from bench_accuracy import parse_seeds  # noqa: E402

CACHE_DIR = Path("/tmp/aerosid-attrib")


def cache_path(vehicle: str, seed: int, root: Path = CACHE_DIR) -> Path:
    return root / f"{vehicle}-{seed}.pkl"


def build(vehicle: str, seed: int, root: Path = CACHE_DIR) -> Path:
    """Simulate, estimate the flight data (capturing each segment's band-limiting), save."""
    import aerosid.identification.flight_data as fdmod
    from aerosid.ebm import estimate_flight_data
    from bench_generalisation import simulate

    root.mkdir(parents=True, exist_ok=True)
    work = root / f"{vehicle}-{seed}-files"
    work.mkdir(exist_ok=True)
    flight, veh = simulate(vehicle, seed, work)
    captured = []
    original = fdmod._band_signals

    def spy(t, measured, smoothed, vehicle_, ok, segment):
        bl, used, findings = original(t, measured, smoothed, vehicle_, ok, segment)
        captured.append({"segment": segment, "t_s": t.copy(), "band_hz": bl.band_hz,
                         "filter_runs": tuple(bl.filter_runs), "used": bl.used.copy()})
        return bl, used, findings

    fdmod._band_signals = spy
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t0 = time.perf_counter()
            est = estimate_flight_data(flight.telemetry, veh)
            took = time.perf_counter() - t0
    finally:
        fdmod._band_signals = original
    vehicle_src = str(veh.source) if veh.source else vehicle
    payload = {
        "vehicle": vehicle, "seed": seed, "vehicle_source": vehicle_src,
        "truth": flight.truth, "coefficients": flight.coefficients, "info_mass": flight.info.get("mass", {}),
        "accel_offset_m": flight.info.get("accel_offset_m"),
        "preprocessed": est.preprocessed.frame, "smoothed": [s.frame for s in est.smoothed],
        "flight_data": est.flight_data, "findings": est.flight_data.attrs.get("findings", []),
        "bands": captured, "time_s": took,
    }
    out = cache_path(vehicle, seed, root)
    tmp = out.with_suffix(".tmp")
    tmp.write_bytes(pickle.dumps(payload))
    tmp.rename(out)
    return out


def load(vehicle: str, seed: int, root: Path = CACHE_DIR) -> dict:
    """The cached flight (built first if missing), with its Vehicle loaded."""
    from aerosid.vehicles.vehicle import load_vehicle

    path = cache_path(vehicle, seed, root)
    if not path.exists():
        build(vehicle, seed, root)
    data = pickle.loads(path.read_bytes())
    data["vehicle_obj"] = load_vehicle(data["vehicle_source"])
    return data


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", default="F4N,OV10,pa28")
    ap.add_argument("--seeds", default="0-3")
    ap.add_argument("--dir", default=str(CACHE_DIR))
    ap.add_argument("--force", action="store_true")
    args = ap.parse_args()
    root = Path(args.dir)
    for v in args.vehicles.split(","):
        for s in parse_seeds(args.seeds):
            if cache_path(v, s, root).exists() and not args.force:
                continue
            t0 = time.perf_counter()
            build(v, s, root)
            print(f"{v} seed {s}: {time.perf_counter() - t0:.0f} s", flush=True)


if __name__ == "__main__":
    main()
