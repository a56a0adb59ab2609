"""Benchmark: compiled EKF + MBF smoother vs filterpy's EKF + rts_smoother (21 states, 6 measurements).

Run:  python bench/bench_filter.py [--samples 20000] [--out bench/results/filter.md]

Both run in the same process on the same synthetic data (aerosid.estimation.synthetic,
seed noise levels, 100 Hz), same x0, P0, Q, R.  filterpy gets the model through the
same compiled numba functions the kernel uses (so the comparison is of the filter
and smoother algebra, not of Python model code), its EKF predict is the textbook
P = F P F' + Q with F the exact Jacobian of the discrete map, and its smoother is
KalmanFilter.rts_smoother on the stored x(k|k), P(k|k) and F (the EKF
linearisation, mathematically the same smoother as MBF).  Times are best-of-3
wall times after a warm-up (JIT compile excluded), on one thread.  Peak memory is
tracemalloc's peak during the call (numpy allocations are traced; the kernel's
few fixed work arrays are not) divided by the number of samples.
"""
from __future__ import annotations

import argparse
import datetime as _dt
import os
import platform
import sys
import time
import tracemalloc
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import numpy as np  # noqa: E402


from machine import cpu_model as _cpu_model, loadavg as _loadavg  # noqa: E402  (bench/machine.py)


def _best(fn, reps=3):
    best = np.inf
    out = None
    for _ in range(reps):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=20000)
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "filter.md")
    args = ap.parse_args(argv)

    import numba
    import filterpy
    from filterpy.kalman import ExtendedKalmanFilter, KalmanFilter

    from aerosid.estimation import (EBMOptions, discrete_process_noise, initial_state, run_filter_smoother,
                                    smooth_flight)
    from aerosid.estimation import _fast
    from aerosid.estimation.synthetic import simulate_flight

    load0 = _loadavg()
    N = int(args.samples)
    sf = simulate_flight(duration_s=N / 100.0, rate_hz=100.0, seed=42)
    model = sf.model
    valid = np.ones_like(sf.z, bool)
    R = sf.noise_sigma**2
    q_chain = np.array([1.0e6, 1.0e6, 2.0e6, 3.0e4, 3.0e4, 3.0e4])
    Qd = discrete_process_noise(q_chain, model)
    x0, P0, _ = initial_state(sf.t_s, sf.z, valid, model, sf.noise_sigma)
    gate = 23.93

    # ---- ours: warm-up (compile / load cache), then time
    run_filter_smoother(sf.z[:200], valid[:200], x0, P0, model, Qd, R, gate)
    t_ours, run = _best(lambda: run_filter_smoother(sf.z, valid, x0, P0, model, Qd, R, gate))
    # time-varying process noise (aerosid.estimation.local_q): Y and N chains x30 on 10 % of the steps
    from aerosid.estimation.core_run import chain_shares

    ql = np.ones((N, 6))
    ql[N // 2:N // 2 + N // 10, [1, 5]] = 30.0
    shares = chain_shares(q_chain, model)
    t_loc, _ = _best(lambda: run_filter_smoother(sf.z, valid, x0, P0, model, Qd, R, gate, q_local=ql, q_shares=shares))

    # forward pass alone (kernel only)
    NP = _fast.NP
    seg = 64
    nseg = (N + seg - 1) // seg
    x0p = np.zeros(NP)
    x0p[:21] = x0
    P0p = np.zeros((NP, NP))
    P0p[:21, :21] = P0
    Qp = np.zeros((NP, NP))
    Qp[:21, :21] = Qd
    zc = np.ascontiguousarray(sf.z)
    bufs = dict(xf=np.empty((N, 21)), sf=np.empty((N, 21)), nis=np.empty(N), dof=np.empty(N, np.int64),
                used=np.empty((N, 6), bool), gated=np.empty((N, 6), bool), ckpt=np.empty((nseg, NP, NP)),
                stats=np.zeros((5, 6)), innov=np.empty((N, 6)))
    Qc, qm = np.zeros((6, NP, NP)), np.ones((0, 6))  # stationary process noise
    t_fwd, _ = _best(lambda: _fast.forward(zc, valid, x0p, P0p, model.params, Qp, Qc, qm, R, gate, True, np.ones(0, np.bool_),
                                           np.zeros(6, np.int64), seg,
                                           bufs["xf"], bufs["sf"], bufs["nis"], bufs["dof"], bufs["used"],
                                           bufs["gated"], bufs["ckpt"], bufs["stats"], bufs["innov"]))

    # ---- peak memory of ours
    tracemalloc.start()
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    run_m = run_filter_smoother(sf.z, valid, x0, P0, model, Qd, R, gate)
    peak = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.stop()
    out_bytes = sum(a.nbytes for a in (run_m.x_filter, run_m.sigma_filter, run_m.x_smooth, run_m.sigma_smooth,
                                       run_m.nis_filter, run_m.nis_smoother, run_m.dof, run_m.used, run_m.gated,
                                       run_m.angacc, run_m.angacc_sigma))
    del run_m

    # ---- filterpy EKF + rts_smoother, model through the same compiled functions
    prm = model.params
    xn = np.empty(NP)
    F3 = np.empty((3, 12))
    wv, Wi, J, accJ = np.empty((4, 3)), np.empty((3, 12)), np.empty((3, 12)), np.empty((3, 12))
    hx = np.empty(6)
    Hm = np.zeros((6, NP))
    xpad = np.zeros(NP)
    h2 = 0.5 * model.dt_s**2
    chain = np.array([[1.0, model.dt_s, h2], [0.0, 1.0, model.dt_s], [0.0, 0.0, 1.0]])
    Fbase = np.zeros((21, 21))
    for s in range(3, 21, 3):
        Fbase[s:s + 3, s:s + 3] = chain

    def fx_and_F(x):
        xpad[:21] = x.ravel()
        _fast._propagate(xpad, prm, xn, F3, wv, Wi, J, accJ)
        F = Fbase.copy()
        F[0:3, 0:3] = F3[:, 0:3]
        F[0:3, 12:21] = F3[:, 3:12]
        return xn[:21].reshape(21, 1).copy(), F

    def HJ(x):
        xpad[:21] = x.ravel()
        _fast._measure(xpad, prm, hx, Hm)
        return Hm[:, :21].copy()

    def Hx(x):
        xpad[:21] = x.ravel()
        _fast._measure(xpad, prm, hx, Hm)
        return hx.reshape(6, 1).copy()

    def filterpy_run():
        ekf = ExtendedKalmanFilter(21, 6)
        ekf.x = x0.reshape(21, 1).copy()
        ekf.P = P0.copy()
        ekf.Q = Qd
        ekf.R = np.diag(R)
        state = {}

        def predict_x(u=0):
            ekf.x = state["xn"]

        ekf.predict_x = predict_x
        Xs = np.empty((N, 21, 1))
        Ps = np.empty((N, 21, 21))
        Fs = np.empty((N, 21, 21))
        Fs[0] = np.eye(21)
        for k in range(N):
            if k > 0:
                state["xn"], ekf.F = fx_and_F(ekf.x)
                Fs[k] = ekf.F
                ekf.predict()
            ekf.update(zc[k].reshape(6, 1), HJ, Hx)
            Xs[k] = ekf.x
            Ps[k] = ekf.P
        t1 = time.perf_counter()
        kf = KalmanFilter(21, 6)
        xr, Pr, _, _ = kf.rts_smoother(Xs, Ps, Fs=Fs, Qs=[Qd] * N)   # Fs[k+1]: k -> k+1
        t2 = time.perf_counter()
        return Xs, xr, Pr, t2 - t1

    fp_reps = 1 if N > 5000 else 3
    t_fp, (Xs_fp, xr_fp, Pr_fp, t_rts) = _best(filterpy_run, reps=fp_reps)
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    filterpy_small = None
    Nm = min(N, 2000)
    # filterpy's memory per sample measured on a shorter run (it grows linearly)
    zc_full = zc
    zc = zc_full[:Nm]
    N_saved = N
    N = Nm
    filterpy_small = filterpy_run()
    peak_fp = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.stop()
    N = N_saved
    zc = zc_full
    del filterpy_small

    # agreement (same linearisation -> same numbers up to rounding)
    sc = np.max(np.abs(xr_fp.reshape(N, 21)), axis=0)
    agree_x = float(np.max(np.abs(run.x_smooth - xr_fp.reshape(N, 21)) / sc))
    agree_xf = float(np.max(np.abs(run.x_filter - Xs_fp.reshape(N, 21)) / np.max(np.abs(Xs_fp.reshape(N, 21)), axis=0)))
    sig_fp = np.sqrt(np.maximum(np.diagonal(Pr_fp, axis1=1, axis2=2), 0))
    agree_s = float(np.max(np.abs(run.sigma_smooth - sig_fp) / np.max(sig_fp, axis=0)))

    # ---- the whole smooth_flight (init + auto-tuning iterations), for information
    t_sf, res = _best(lambda: smooth_flight(sf.t_s, sf.z, valid, model.inertia_kg_m2, model.sensor_offset_m,
                                            options=EBMOptions()), reps=1)
    load1 = _loadavg()

    us_ours = t_ours / N * 1e6
    us_fwd = t_fwd / N * 1e6
    us_fp = t_fp / N * 1e6
    us_rts = t_rts / N * 1e6
    lines = [
        "# Filter + smoother benchmark (bench/bench_filter.py)",
        "",
        f"- date: {_dt.datetime.now().isoformat(timespec='seconds')}",
        f"- machine: {_cpu_model()}, {os.cpu_count()} cores, load average {load0} (start) / {load1} (end)",
        f"- Python {platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}, "
        f"filterpy {filterpy.__version__}",
        f"- data: synthetic 21-state flight, {N} samples at 100 Hz, 6 measurements, seed noise levels",
        "",
        "| what | µs per sample | target |",
        "| --- | ---: | ---: |",
        f"| aerosid EKF + MBF smoother (numba, one thread) | {us_ours:.2f} | ≤ 6 |",
        f"| of which: forward EKF pass alone | {us_fwd:.2f} | |",
        f"| the same with a local process-noise multiplier on 10 % of the steps | {t_loc / N * 1e6:.2f} | |",
        f"| filterpy ExtendedKalmanFilter + KalmanFilter.rts_smoother | {us_fp:.1f} | (~90 expected) |",
        f"| of which: rts_smoother | {us_rts:.1f} | |",
        f"| speed-up | {us_fp / us_ours:.1f}x | |",
        f"| smooth_flight end to end (spectra, init, {len(res.tuning_history)} tuning passes) | "
        f"{t_sf / N * 1e6:.1f} | |",
        "",
        "| memory | bytes per sample | target |",
        "| --- | ---: | ---: |",
        f"| aerosid peak (tracemalloc) | {peak / N:.0f} | ≤ 1024 |",
        f"| of which the returned arrays (x, sigma filter and smoother, NIS, flags, p'q'r' with sigma) | "
        f"{out_bytes / N:.0f} | |",
        f"| filterpy EKF + rts_smoother peak (measured on {Nm} samples) | {peak_fp / Nm:.0f} | |",
        "",
        "Agreement with filterpy on the same data (max |difference| / column max):",
        f"filtered state {agree_xf:.2e}, smoothed sigma {agree_s:.2e}, smoothed state {agree_x:.2e}.",
        "The smoothed states differ because filterpy's rts_smoother predicts the mean linearly, F x(k|k),",
        "where the EKF's prediction is f(x(k|k)); F x - f(x) = -dt * (gyroscopic terms), a systematic",
        "error of the linear RTS on this plant, not of the MBF: on a linear plant the two agree to 1e-9, and",
        "on this plant the MBF equals an RTS that predicts the mean with f(x) to ~1e-12",
        "(tests/estimation/test_filter.py).",
        "",
        "Notes: the machine is shared (see the load average); times are best of 3 for aerosid, one run for",
        "filterpy at 20,000 samples.  The compiled smoother re-runs the forward covariance recursion",
        "segment by segment from checkpoints every 64 samples (to stay under 1 KB/sample), so its cost is",
        "about two forward passes plus the backward sweep.",
    ]
    text = "\n".join(lines) + "\n"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
