"""Monte-Carlo scatter of the SIMEX correction (aerosid.identification.eiv): the angles' draws as
identify makes them (sequential from one generator) against common random numbers across lambda
(as the gyros' draws are), each with 3 master seeds (the shipped SEED, 11, 12).

    python bench/bench_simex_mc.py      # ~10 min; caches as bench/bench_gyro_simex.py, plus seed-rlv:
    python bench/attribution_cache.py --vehicles seed-rlv --seeds 0-9 --dir /tmp/gs-rlv
    -> /tmp/gs_crn.csv and the summary on stdout (recorded in bench/results/simex_mc.md)

MC-sd: the spread over the master seeds, per flight, averaged over the 10 flights.  The shipped
SEED is the same for every flight, so the Monte-Carlo errors of a vehicle's flights are correlated."""
import sys, warnings, time
sys.path.insert(0, "bench")
import numpy as np, pandas as pd
from pathlib import Path
from types import SimpleNamespace
import attribution_cache as ac
import aerosid.identification.eiv as eiv
import aerosid.identification.identify as idm
from aerosid.identification.flight_data import build_flight_data_segments, load_database
from bench_generalisation import estimate_of, truth_of
warnings.simplefilter("ignore")

def make(mode, master):
    def simex(fd, y_by_channel, design, sigma_rad, cutoff_hz, rate_sigma=None, rate_cutoff_hz=None):
        rng = np.random.default_rng(master)
        groups = (fd["flight"].astype(str) + "/" + fd["segment"].astype(str)).to_numpy()
        def fit_all(frame):
            X = design(frame)
            return {ch: np.linalg.lstsq(X[ch], y, rcond=None)[0] for ch, y in y_by_channel.items()}
        naive = fit_all(fd); curves = {ch: [b] for ch, b in naive.items()}
        t = fd["t_s"].to_numpy(float); cache = {}
        for lam in eiv.LAMBDAS:
            acc = {ch: np.zeros_like(b) for ch, b in naive.items()}
            for b in range(eiv.REPLICATES):
                f = fd
                if sigma_rad is not None:
                    scaled = (tuple(np.asarray(x) * np.sqrt(lam) for x in sigma_rad) if isinstance(sigma_rad, tuple) else sigma_rad * np.sqrt(lam))
                    r = np.random.default_rng([master, b]) if mode == "crn" else rng
                    f = eiv.with_angle_noise(f, r, groups, scaled, cutoff_hz)
                if rate_sigma is not None:
                    if b not in cache:
                        cache[b] = eiv.rate_noise(np.random.default_rng([master + 1, b]), groups, t, rate_sigma, rate_cutoff_hz)
                    f = eiv.with_rate_noise(f, np.sqrt(lam) * cache[b], copy=f is fd)
                for ch, est in fit_all(f).items():
                    acc[ch] += est / eiv.REPLICATES
            for ch in curves: curves[ch].append(acc[ch])
        lams = np.array((0.0, *eiv.LAMBDAS))
        return {ch: eiv.SimexResult(np.array([eiv.extrapolate(lams, E[:, j]) for j in range(E.shape[1])]),
                                    np.array([eiv.extrapolation_spread(lams, E[:, j]) for j in range(E.shape[1])]), E[0].copy())
                for ch, E in ((ch, np.array(rows)) for ch, rows in curves.items())}
    return simex

rows = []
specs = [("seed-rlv", "/tmp/gs-rlv"), ("OV10", "/tmp/aerosid-attrib-ab2"), ("pa28", "/tmp/aerosid-attrib-ab2"), ("F4N", "/tmp/aerosid-attrib-ab2")]
for v, cdir in specs:
    for s in range(10):
        d = ac.load(v, s, Path(cdir)); veh = d["vehicle_obj"]
        fd = build_flight_data_segments(d["preprocessed"], d["smoothed"], veh, load_database(veh), "flight")
        fl = SimpleNamespace(coefficients=d["coefficients"])
        for mode in ("seq", "crn"):
            for master in (eiv.SEED, 11, 12):
                idm.simex_estimates = make(mode, master)
                ident = idm.identify(fd, veh, bias_pairs=0)  # SIMEX alone, as recorded
                row = {"vehicle": v, "seed": s, "mode": mode, "master": master}
                for c in ("Cm_alpha", "Cm_delta", "damping"):
                    tr = truth_of(fl, c); est, se = estimate_of(ident, c)
                    row[c] = 100 * (est / tr - 1); row[c + "_cov"] = abs(est - tr) <= 1.96 * se
                rows.append(row)
        print(v, s, flush=True)
    df = pd.DataFrame(rows); df.to_csv("/tmp/gs_crn.csv", index=False)
df = pd.DataFrame(rows)
for (v, mode), g in df.groupby(["vehicle", "mode"], sort=False):
    out = [f"{v:8s} {mode}"]
    for c in ("Cm_alpha", "Cm_delta", "damping"):
        mc = g.groupby("seed")[c].std().mean()  # MC scatter across master seeds
        d0 = g[g.master == eiv.SEED]
        out.append(f"{c}: mean {d0[c].mean():+.1f} rms {np.sqrt((d0[c]**2).mean()):.1f} cov {d0[c+'_cov'].mean():.0%} MC-sd {mc:.2f}")
    print(" | ".join(out))
