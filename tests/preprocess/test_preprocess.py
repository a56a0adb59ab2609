"""Tests of aerosid.preprocess on synthetic telemetry with known injected faults.

The simulator is written in parallel, so ``make_flight`` builds its own flights:
smooth signals below 2 Hz (a pitch pull-up at 0.5 rad/s^2 with a pitch fin step,
a 3-sample fin ramp, a fin doublet), the seed's noise levels, and faults with
known masks (dropout bursts as deleted rows and as NaN rows, a sync gap, spikes,
frozen runs, sentinels, single-channel loss, timestamp jitter).
"""
from __future__ import annotations

import math
import pickle
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aerosid.preprocess import (
    DETECTION,
    DROPOUT,
    PreprocessParams,
    PreprocessResult,
    QualityFlag,
    TelemetryError,
    flag_names,
    preprocess,
    read_preprocessed_parquet,
    usable_mask,
    write_preprocessed_parquet,
)
from schemas.telemetry import CHANNELS, PreprocessedTelemetry, validate

DEG = math.pi / 180.0
#: 1-sigma noise per channel (seed Table 2 for accelerometers and gyros), SI units.
NOISE = {
    "ax_m_s2": 0.8, "ay_m_s2": 1.0, "az_m_s2": 2.0,
    "p_rad_s": 4 * DEG, "q_rad_s": 2 * DEG, "r_rad_s": 1 * DEG,
    "d1_rad": 0.02 * DEG, "d2_rad": 0.02 * DEG, "d3_rad": 0.02 * DEG, "d4_rad": 0.02 * DEG,
    "V_m_s": 0.1, "h_m": 0.5,
}
F = QualityFlag


# ---------------------------------------------------------------------------
# Synthetic flights
# ---------------------------------------------------------------------------

def _ramp(t, t_on, rate, top):
    """0 before t_on, then rising at `rate` up to `top`."""
    return np.clip((t - t_on) * rate, 0.0, top)


def truth_signals(t: np.ndarray) -> dict[str, np.ndarray]:
    """Noise-free channels.  Sharpest manoeuvre at 10-11 s: pitch fins step by 0.3 rad
    in one sample and q pulls up at 0.5 rad/s^2 (az swings by -V q ~ -120 m/s^2 at
    150 m/s^3); a 3-sample fin ramp at 30 s; a fin doublet at 40 s."""
    V = 300.0 + 5.0 * np.sin(2 * np.pi * 0.05 * t)
    q = (_ramp(t, 10.0, 0.5, 0.4) - _ramp(t, 14.0, 0.5, 0.4) + 0.05 * np.sin(2 * np.pi * 1.5 * t))
    p = 0.3 * np.sin(2 * np.pi * 0.5 * t)
    r = 0.05 * np.sin(2 * np.pi * 0.3 * t + 1.0)
    pitch_step = np.where((t >= 10.0) & (t < 20.0), 0.3, 0.0)
    d1 = 0.02 * np.sin(2 * np.pi * 0.2 * t) - _ramp(t, 30.0, 0.25 / 0.03, 0.25) * (t < 35.0)
    d2 = 0.02 * np.sin(2 * np.pi * 0.2 * t + 0.5) + pitch_step
    d3 = 0.02 * np.sin(2 * np.pi * 0.2 * t + 1.0) + np.where((t >= 40.0) & (t < 40.5), 0.2, 0.0) \
        - np.where((t >= 40.5) & (t < 41.0), 0.2, 0.0)
    d4 = 0.02 * np.sin(2 * np.pi * 0.2 * t + 1.5) - pitch_step
    return {
        "ax_m_s2": -20.0 + 2.0 * np.sin(2 * np.pi * 0.1 * t),
        "ay_m_s2": V * r + 1.0 * np.sin(2 * np.pi * 1.8 * t),
        "az_m_s2": -V * q - 9.81 + 3.0 * np.sin(2 * np.pi * 2.0 * t),
        "p_rad_s": p, "q_rad_s": q, "r_rad_s": r,
        "d1_rad": d1, "d2_rad": d2, "d3_rad": d3, "d4_rad": d4,
        "V_m_s": V, "h_m": 5000.0 + 50.0 * t,
    }


#: Windows [s] of the genuine manoeuvres (the sharpest is the first).
MANOEUVRES = ((9.5, 12.0), (13.5, 15.5), (19.5, 20.5), (29.5, 30.5), (34.5, 35.5), (39.5, 41.5))


@dataclass
class Flight:
    raw: pd.DataFrame
    t_nominal: np.ndarray              # nominal time of every grid sample (before deletion)
    truth: dict                        # noise-free signals on the full grid
    deleted: np.ndarray                # bool, full grid: row deleted
    nan_cells: dict = field(default_factory=dict)      # channel -> bool (full grid)
    spikes: list = field(default_factory=list)         # (grid index, channel, size in sigma)
    frozen: dict = field(default_factory=dict)         # channel -> bool repeats (full grid)
    sentinel: dict = field(default_factory=dict)       # channel -> bool (full grid)

    def fault_mask(self, channel: str) -> np.ndarray:
        m = self.deleted.copy()
        for d in (self.nan_cells, self.frozen, self.sentinel):
            if channel in d:
                m |= d[channel]
        for k, c, _ in self.spikes:
            if c == channel:
                m[k] = True
        return m


def make_flight(seed: int = 0, duration_s: float = 60.0, rate_hz: float = 100.0, faults: bool = True,
                jitter: float = 0.02) -> Flight:
    """A synthetic flight with known injected faults (see module docstring)."""
    rng = np.random.default_rng(seed)
    n = int(round(duration_s * rate_hz))
    t_nom = 100.0 + np.arange(n) / rate_hz
    truth = truth_signals(t_nom - 100.0)
    values = {c: truth[c] + NOISE[c] * rng.standard_normal(n) for c in CHANNELS}
    fl = Flight(raw=None, t_nominal=t_nom, truth=truth, deleted=np.zeros(n, bool))
    if faults:
        taken = np.zeros(n, bool)  # cells already used by a fault (any channel)
        # dropout bursts of all channels: half deleted rows, half NaN rows
        nan_rows = np.zeros(n, bool)
        for i in range(12):
            length = int(rng.uniform(0.05, 0.5) * rate_hz)
            k0 = int(rng.integers(int(2 * rate_hz), n - int(2 * rate_hz)))
            (fl.deleted if i % 2 == 0 else nan_rows)[k0:k0 + length] = True
        # the telemetry sync gap: 2 s of missing rows
        k0 = int(0.75 * n)
        fl.deleted[k0:k0 + int(2.0 * rate_hz)] = True
        taken |= fl.deleted | nan_rows
        for c in CHANNELS:
            fl.nan_cells[c] = nan_rows.copy()
        def free_start(length: int, margin: int = 5) -> int:
            """A start index whose run (plus a margin) touches no earlier fault."""
            busy = np.convolve(taken, np.ones(length + 2 * margin), mode="full")[length + margin - 1:][:n] > 0
            busy[n - length - margin:] = True
            busy[:margin] = True
            return int(rng.choice(np.flatnonzero(~busy)))

        # single-channel loss
        for c, dur in (("q_rad_s", 1.0), ("d3_rad", 0.2)):
            k0 = free_start(int(dur * rate_hz))
            fl.nan_cells[c][k0:k0 + int(dur * rate_hz)] = True
            taken[k0:k0 + int(dur * rate_hz)] = True
        # frozen runs (the first sample of the run is genuine, the repeats are stuck)
        for c, dur in (("az_m_s2", 0.3), ("p_rad_s", 2.0), ("h_m", 0.5)):
            k0 = free_start(int(dur * rate_hz) + 1)
            k1 = k0 + int(dur * rate_hz)
            values[c][k0 + 1:k1] = values[c][k0]
            m = np.zeros(n, bool)
            m[k0 + 1:k1] = True
            fl.frozen[c] = m
            taken[k0:k1 + 1] = True
        # sentinels
        for c, val in (("V_m_s", -9999.0), ("h_m", 1e30), ("ax_m_s2", 9999.0),
                       ("d2_rad", float(np.float32(1e30)))):
            k = free_start(1)
            values[c][k] = val
            m = np.zeros(n, bool)
            m[k] = True
            fl.sentinel[c] = m
            taken[k] = True
        # single-channel spikes, >= 5 sigma: 85 % log-uniform 5..100 sigma, 15 % absurd
        cand = np.flatnonzero(~taken)
        ks = rng.choice(cand, size=int(3 * duration_s), replace=False)
        for k in ks:
            c = CHANNELS[int(rng.integers(len(CHANNELS)))]
            size = (5.0 * np.exp(rng.uniform(0, np.log(20.0))) if rng.uniform() < 0.85
                    else 10 ** rng.uniform(3, 6))
            values[c][k] += rng.choice([-1.0, 1.0]) * size * NOISE[c]
            fl.spikes.append((int(k), c, float(size)))
        for c in CHANNELS:
            values[c][fl.nan_cells[c]] = np.nan
    t = t_nom + jitter / rate_hz * rng.uniform(-1, 1, n)
    keep = ~fl.deleted
    raw = pd.DataFrame({"t_s": t[keep], **{c: values[c][keep] for c in CHANNELS}})
    fl.raw = raw
    return fl


def flags_on_full_grid(fl: Flight, res: PreprocessResult, channel: str) -> np.ndarray:
    """The result's flags of `channel` mapped back onto the flight's full nominal grid."""
    fr = res.frame
    k = np.round((fr["t_s"].to_numpy() - fl.t_nominal[0]) * res.nominal_rate_hz).astype(int)
    assert k[0] == 0 and np.all(np.diff(k) == 1)
    out = np.zeros(fl.t_nominal.size, dtype=np.int64)
    out[k] = fr[f"flags_{channel}"].to_numpy()
    return out


def _raw_on_full_grid(fl: Flight, channel: str) -> np.ndarray:
    out = np.full(fl.t_nominal.size, np.nan)
    out[~fl.deleted] = fl.raw[channel].to_numpy()
    return out


def detection_rates(fl: Flight, res: PreprocessResult) -> dict:
    """Dropouts flagged, spikes flagged (by deviation from the truth), and false
    outliers on clean samples."""
    nom_t = fl.t_nominal - fl.t_nominal[0]
    in_sharpest = (nom_t >= MANOEUVRES[0][0]) & (nom_t < MANOEUVRES[0][1])
    in_any = np.zeros_like(in_sharpest)
    for a, b in MANOEUVRES:
        in_any |= (nom_t >= a) & (nom_t < b)
    n_drop = n_drop_flagged = 0
    n_spike = n_spike_flagged = 0
    n_dev = {7: 0, 8: 0}
    n_dev_flagged = {7: 0, 8: 0}
    n_clean = fp = n_clean_sharp = fp_sharp = n_clean_man = fp_man = 0
    for c in CHANNELS:
        f = flags_on_full_grid(fl, res, c)
        drop = fl.deleted | fl.nan_cells[c] | fl.sentinel.get(c, False) | fl.frozen.get(c, False)
        n_drop += int(drop.sum())
        n_drop_flagged += int(((f[drop] & int(DETECTION)) != 0).sum())
        dev = np.abs(_raw_on_full_grid(fl, c) - fl.truth[c]) / NOISE[c]
        for k, cc, size in fl.spikes:
            if cc == c and size > 5.0:
                n_spike += 1
                n_spike_flagged += int(f[k] & int(DETECTION) != 0)  # OUTLIER, or OUT_OF_RANGE
                for lim in n_dev:
                    if dev[k] > lim:
                        n_dev[lim] += 1
                        n_dev_flagged[lim] += int(f[k] & int(DETECTION) != 0)
        clean = ~fl.fault_mask(c)
        out = (f & int(F.OUTLIER)) != 0
        n_clean += int(clean.sum())
        fp += int((out & clean).sum())
        n_clean_sharp += int((clean & in_sharpest).sum())
        fp_sharp += int((out & clean & in_sharpest).sum())
        n_clean_man += int((clean & in_any).sum())
        fp_man += int((out & clean & in_any).sum())
    return {
        "dropouts_flagged": n_drop_flagged / n_drop,
        "spikes_flagged": n_spike_flagged / n_spike,
        "spikes_dev7_flagged": n_dev_flagged[7] / n_dev[7],
        "spikes_dev8_flagged": n_dev_flagged[8] / n_dev[8],
        "fp_rate": fp / n_clean,
        "fp_rate_sharpest": fp_sharp / n_clean_sharp,
        "fp_rate_manoeuvres": fp_man / n_clean_man,
        "n_spikes": n_spike,
        "fp": fp,
        "fp_sharpest": fp_sharp,
    }


def assert_invariants(raw: pd.DataFrame, res: PreprocessResult) -> None:
    """Row counts add up, raw values are kept bit for bit, flags are consistent."""
    fr = res.frame
    assert res.n_grid_rows == len(fr) == res.n_raw_rows + res.n_inserted_rows
    assert res.n_raw_rows == len(raw)
    present = ~np.isnan(fr["t_raw_s"].to_numpy())
    assert int(present.sum()) == len(raw)
    assert np.array_equal(fr["t_raw_s"].to_numpy()[present].view(np.int64), raw["t_s"].to_numpy().view(np.int64))
    for c in CHANNELS:
        assert np.array_equal(fr[c].to_numpy()[present].view(np.int64), raw[c].to_numpy().view(np.int64)), c
        assert np.all(np.isnan(fr[c].to_numpy()[~present]))
        f = fr[f"flags_{c}"].to_numpy()
        assert np.all(f[~present] & int(F.MISSING_ROW))
        assert not np.any(f[present] & int(F.MISSING_ROW))
    validate(fr, PreprocessedTelemetry, "test")
    assert sum(res.n_usable_by_channel.values()) == int(usable_mask(fr, list(CHANNELS)).sum())


# ---------------------------------------------------------------------------
# Acceptance: detection rates on simulated flights with known faults
# ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def flights():
    out = []
    for seed in (1, 2, 3):
        fl = make_flight(seed=seed)
        out.append((fl, preprocess(fl.raw, source=f"synthetic-{seed}")))
    return out


def test_acceptance_rates(flights):
    """Detection on three simulated flights (12 channels x 6000 samples each):

    * all injected dropouts (deleted rows, NaN rows, single-channel NaN, sentinels,
      frozen repeats) are flagged;
    * false outliers on clean samples: at most 1 per flight (the threshold is set for
      one false outlier per channel in 1000 records on Gaussian noise; the old fixed
      3.3-sigma test flagged 55-70 clean samples per flight), none in the sharpest
      manoeuvre (pull-up + pitch fin step);
    * >= 99 % of the spikes whose deviation from the truth |raw - truth| exceeds 8 sigma
      are flagged, >= 97 % of those beyond 7 sigma (the few misses lie next to a gap,
      where the test is one-sided, or within two windows of a fin step).  Spikes of
      5-7 sigma are mostly left to the Kalman filter's innovation gate (4.9 sigma): at
      a false-alarm rate that does not grow with the record, no test on one sample's
      neighbourhood can separate them from the noise.
    """
    rates = [detection_rates(fl, res) for fl, res in flights]
    for r in rates:
        assert r["dropouts_flagged"] == 1.0, r
        assert r["fp"] <= 1, r
        assert r["fp_sharpest"] == 0, r
    assert np.mean([r["spikes_dev8_flagged"] for r in rates]) >= 0.99, rates
    assert np.mean([r["spikes_dev7_flagged"] for r in rates]) >= 0.97, rates


def test_invariants_on_damaged_flight(flights):
    for fl, res in flights:
        assert_invariants(fl.raw, res)


def test_sync_gap_is_a_long_gap(flights):
    fl, res = flights[0]
    # the 2 s sync gap starts at 75 % of the 60 s flight (nominal t = 145 s)
    gaps = [g for g in res.long_gaps if abs(g[0] - (fl.t_nominal[0] + 45.0)) < 0.02]
    assert len(gaps) == 1
    a, b = gaps[0]
    assert b - a == pytest.approx(2.0 - 0.01, abs=0.015)
    assert res.longest_gap_s >= 2.0 - 1e-9
    fr = res.frame
    inside = (fr["t_s"] >= a) & (fr["t_s"] <= b)
    for c in CHANNELS:
        f = fr.loc[inside, f"flags_{c}"].to_numpy()
        assert np.all(f & int(F.LONG_GAP)) and np.all(f & int(F.MISSING_ROW))
        assert fr.loc[inside, f"{c}_clean"].isna().all()


def test_short_dropouts_interpolated_for_the_fft(flights):
    fl, res = flights[0]
    fr = res.frame
    f = fr["flags"].to_numpy()
    interp = (f & int(F.INTERPOLATED)) != 0
    assert interp.any()
    for c in CHANNELS:
        fc = fr[f"flags_{c}"].to_numpy()
        sel = (fc & int(F.INTERPOLATED)) != 0
        clean = fr[f"{c}_clean"].to_numpy()
        assert np.all(np.isfinite(clean[sel]))
    # the Kalman filter does not use interpolated samples
    m = usable_mask(fr, list(CHANNELS))
    assert not np.any(m[interp[:, None] & ((fr[[f"flags_{c}" for c in CHANNELS]].to_numpy()
                                            & int(F.INTERPOLATED)) != 0)])


def test_summary_and_metadata(flights):
    fl, res = flights[0]
    text = res.summary()
    assert "synthetic-1" in text and "longest all-channel gap" in text
    md = res.metadata()
    assert all(isinstance(k, str) and isinstance(v, str) for k, v in md.items())
    import json
    params = json.loads(md["aerosid.preprocess.params"])
    assert params["max_interp_gap_s"] == res.params.max_interp_gap_s
    assert params["outlier_threshold_sigma"] == res.params.outlier_threshold_sigma
    counts = json.loads(md["aerosid.preprocess.summary_counts"])
    assert counts["grid"] == counts["raw"] + counts["inserted"]
    assert counts["MISSING_ROW"] == res.n_inserted_rows
    assert res.summary_counts["OUTLIER"] >= 1
    assert json.loads(md["aerosid.preprocess.flag_bits"])["OUTLIER"] == int(F.OUTLIER)


def test_parquet_round_trip_keeps_bits_and_metadata(flights, tmp_path):
    fl, res = flights[0]
    path = write_preprocessed_parquet(res, tmp_path / "pre.parquet")
    df, md = read_preprocessed_parquet(path)
    assert md["aerosid.preprocess.source"] == "synthetic-1"
    for c in ("t_s", "t_raw_s", *CHANNELS, *(f"{c}_clean" for c in CHANNELS)):
        assert np.array_equal(df[c].to_numpy().view(np.int64), res.frame[c].to_numpy().view(np.int64)), c
    assert df["flags"].dtype == np.uint16


# ---------------------------------------------------------------------------
# Clean flight, rates, jitter
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("rate_hz", [50.0, 100.0, 1000.0])
def test_clean_flight_has_no_false_alarms_at_any_rate(rate_hz):
    duration = 20.0 if rate_hz < 1000 else 6.0
    fl = make_flight(seed=7, duration_s=duration, rate_hz=rate_hz, faults=False)
    res = preprocess(fl.raw)
    assert res.nominal_rate_hz == pytest.approx(rate_hz, rel=1e-3)
    assert res.n_inserted_rows == 0
    outl = res.flag_counts_by_channel
    total_out = sum(outl[c]["OUTLIER"] for c in CHANNELS)
    assert total_out <= 1  # the old fixed 3.3-sigma test: ~0.1 % of the samples
    for c in CHANNELS:
        assert outl[c]["FROZEN"] == outl[c]["NAN"] == outl[c]["SENTINEL"] == outl[c]["OUT_OF_RANGE"] == 0
    assert res.long_gaps == ()


def test_jitter_snaps_to_grid_and_large_offsets_are_flagged():
    fl = make_flight(seed=3, duration_s=5.0, faults=False, jitter=0.2)  # +-0.2 dt: snapped, not flagged
    raw = fl.raw.copy()
    t = raw["t_s"].to_numpy().copy()
    t[100] = fl.t_nominal[100] + 0.35 / 100.0  # 0.35 dt off: beyond snap_tolerance (0.25 dt)
    raw["t_s"] = t
    res = preprocess(raw)
    fr = res.frame
    assert res.n_inserted_rows == 0
    assert np.max(np.abs(fr["t_raw_s"] - fr["t_s"])) <= 0.5 / 100.0
    f = fr["flags"].to_numpy()
    assert f[100] & int(F.TIME_JITTER)
    assert all(fr[f"flags_{c}"].iloc[100] & int(F.TIME_JITTER) for c in CHANNELS)
    assert int(((f & int(F.TIME_JITTER)) != 0).sum()) == 1


def test_explicit_nominal_rate_inserts_rows_for_every_missing_sample():
    fl = make_flight(seed=4, duration_s=4.0, faults=False)
    raw = fl.raw.iloc[::2].reset_index(drop=True)  # every other row lost: median interval is 2 dt
    res_inferred = preprocess(raw)
    assert res_inferred.nominal_rate_hz == pytest.approx(50.0, rel=1e-3)
    res = preprocess(raw, PreprocessParams(nominal_rate_hz=100.0))
    assert res.n_inserted_rows == len(raw) - 1
    assert_invariants(raw, res)


# ---------------------------------------------------------------------------
# Required edge cases
# ---------------------------------------------------------------------------

def _clean_raw(seed=11, duration=10.0):
    return make_flight(seed=seed, duration_s=duration, faults=False).raw


def test_single_channel_loss():
    raw = _clean_raw()
    raw.loc[300:339, "q_rad_s"] = np.nan          # 0.4 s: interpolated
    raw.loc[600:899, "r_rad_s"] = np.nan          # 3 s: left as a gap, only in r
    res = preprocess(raw)
    fr = res.frame
    fq, fr_ = fr["flags_q_rad_s"].to_numpy(), fr["flags_r_rad_s"].to_numpy()
    assert np.all(fq[300:340] == F.NAN | F.INTERPOLATED)
    assert np.isfinite(fr["q_rad_s_clean"].to_numpy()[300:340]).all()
    assert np.all(fr_[600:900] == F.NAN | F.LONG_GAP)
    assert np.isnan(fr["r_rad_s_clean"].to_numpy()[600:900]).all()
    # other channels untouched; not an all-channel gap
    for c in CHANNELS:
        if c not in ("q_rad_s", "r_rad_s"):
            assert not np.any(fr[f"flags_{c}"].to_numpy()[300:900] & int(DROPOUT)), c
    assert res.long_gaps == ()
    assert res.longest_gap_s == 0.0
    assert res.longest_gap_s_by_channel["r_rad_s"] == pytest.approx(3.0, abs=1e-3)
    m = usable_mask(fr, ["q_rad_s", "r_rad_s", "p_rad_s"])
    assert m.shape == (len(fr), 3)
    assert not m[300:340, 0].any() and not m[600:900, 1].any() and m[300:900, 2].mean() > 0.99
    assert_invariants(raw, res)


@pytest.mark.parametrize("how", ["nan", "sentinel"])
def test_gap_at_the_very_start_and_end(how):
    raw = _clean_raw()
    val = np.nan if how == "nan" else -9999.0
    raw.loc[:19, list(CHANNELS)] = val     # first 0.2 s: short, but no anchor on the left
    raw.loc[len(raw) - 80:, list(CHANNELS)] = val  # last 0.8 s: long and at the edge
    res = preprocess(raw)
    fr = res.frame
    bit = F.NAN if how == "nan" else F.SENTINEL
    for c in CHANNELS:
        f = fr[f"flags_{c}"].to_numpy()
        assert np.all(f[:20] == bit | F.EDGE_GAP), c
        assert np.all(f[-80:] == bit | F.EDGE_GAP | F.LONG_GAP), c
        assert np.isnan(fr[f"{c}_clean"].to_numpy()[:20]).all()
        assert np.isnan(fr[f"{c}_clean"].to_numpy()[-80:]).all()
        assert np.isfinite(fr[f"{c}_clean"].to_numpy()[20:-80]).all()
    # the long edge gap is reported, the short one only counted
    assert len(res.long_gaps) == 1
    assert res.long_gaps[0] == (fr["t_s"].iloc[-80], fr["t_s"].iloc[-1])
    assert res.longest_gap_s == pytest.approx(0.8, abs=1e-3)
    assert_invariants(raw, res)


def test_missing_rows_right_after_the_first_and_before_the_last_row():
    """Rows lost before the first received row cannot be seen (the grid starts at the
    first received row); rows lost just after it and just before the last one are
    inserted and flagged, and every raw row is kept."""
    raw = _clean_raw()
    raw = raw.drop(index=list(range(1, 30)) + list(range(len(raw) - 30, len(raw) - 1))).reset_index(drop=True)
    res = preprocess(raw)
    fr = res.frame
    f = fr["flags"].to_numpy()
    assert np.all(f[1:30] & int(F.MISSING_ROW)) and np.all(f[-30:-1] & int(F.MISSING_ROW))
    assert res.n_inserted_rows == 58
    assert_invariants(raw, res)


def test_entirely_dropout_segment_is_a_flagged_empty_result():
    raw = _clean_raw(duration=2.0)
    raw.loc[:, list(CHANNELS)] = np.nan
    res = preprocess(raw)
    fr = res.frame
    assert res.n_usable_rows == 0
    for c in CHANNELS:
        assert fr[f"{c}_clean"].isna().all()
        assert np.all(fr[f"flags_{c}"].to_numpy() == F.NAN | F.EDGE_GAP | F.LONG_GAP)
    assert res.long_gaps == ((fr["t_s"].iloc[0], fr["t_s"].iloc[-1]),)
    assert res.longest_gap_s == pytest.approx(2.0, abs=1e-3)
    assert "usable rows (all channels): 0" in res.summary()
    assert_invariants(raw, res)


def test_frozen_values():
    raw = _clean_raw()
    raw.loc[200:259, "az_m_s2"] = raw.loc[200, "az_m_s2"]   # 60 identical samples: 0.59 s of repeats
    raw.loc[500:509, "d1_rad"] = raw.loc[500, "d1_rad"]     # exactly frozen_min_run (10)
    raw.loc[700:708, "V_m_s"] = raw.loc[700, "V_m_s"]       # 9 identical: below frozen_min_run
    res = preprocess(raw)
    fr = res.frame
    faz = fr["flags_az_m_s2"].to_numpy()
    assert faz[200] == 0                      # the last genuine update is kept
    assert np.all(faz[201:260] & int(F.FROZEN))
    assert np.all(faz[201:260] & int(F.LONG_GAP))   # 0.59 s > max_interp_gap_s
    fd = fr["flags_d1_rad"].to_numpy()
    assert fd[500] == 0 and np.all(fd[501:510] == F.FROZEN | F.INTERPOLATED)
    assert not np.any(fr["flags_V_m_s"].to_numpy()[700:709] & int(F.FROZEN))
    assert not np.any(usable_mask(fr, "az_m_s2")[201:260])
    assert res.flag_counts_by_channel["az_m_s2"]["FROZEN"] == 59
    assert_invariants(raw, res)


def test_frozen_whole_telemetry_frame_is_a_gap():
    raw = _clean_raw()
    raw.loc[400:500, list(CHANNELS)] = raw.loc[400, list(CHANNELS)].to_numpy()
    res = preprocess(raw)
    assert len(res.long_gaps) == 1
    a, b = res.long_gaps[0]
    assert (a, b) == (res.frame["t_s"].iloc[401], res.frame["t_s"].iloc[500])


def test_sentinels_and_out_of_range():
    raw = _clean_raw()
    raw.loc[100, "h_m"] = 1e30
    raw.loc[101, "h_m"] = float(np.float32(-9999.0))
    raw.loc[150, "d2_rad"] = float(np.float32(1e30))
    raw.loc[200, "p_rad_s"] = 25.0        # not a sentinel, beyond 10 rad/s
    raw.loc[250, "ax_m_s2"] = np.inf
    res = preprocess(raw)
    fr = res.frame
    assert fr["flags_h_m"].iloc[100] & int(F.SENTINEL) and fr["flags_h_m"].iloc[101] & int(F.SENTINEL)
    assert fr["flags_d2_rad"].iloc[150] & int(F.SENTINEL)
    assert fr["flags_p_rad_s"].iloc[200] & int(F.OUT_OF_RANGE)
    assert fr["flags_ax_m_s2"].iloc[250] & int(F.NAN)
    assert flag_names(fr["flags_h_m"].iloc[100]) == ["SENTINEL", "INTERPOLATED"]
    assert abs(fr["h_m_clean"].iloc[100] - fr["h_m_clean"].iloc[99]) < 5.0
    assert_invariants(raw, res)


# ---------------------------------------------------------------------------
# Outliers vs manoeuvres
# ---------------------------------------------------------------------------

def test_fin_steps_and_pull_up_are_not_outliers_but_spikes_on_them_are():
    fl = make_flight(seed=21, duration_s=45.0, faults=False)
    raw = fl.raw.copy()
    k_step = 1000  # the pitch-fin step sample (t = 10 s): d2 steps up by 0.3 rad, d4 down
    # 10-sigma spikes just after the step (a spike within ~2 outlier windows of a step
    # may be masked: the step widens the margin), and on the pull-up ramp of az and q
    # (8-sigma offsets are not enough: one landed on a -0.9 sigma noise sample, a
    # 7.1-sigma deviation, below the 6.3-sigma-plus margin of a 6000-sample record)
    spikes = {("d2_rad", k_step + 12): -10, ("d4_rad", k_step + 15): 10,
              ("az_m_s2", 1050): -10, ("q_rad_s", 1060): 10}
    for (c, k), size in spikes.items():
        raw.loc[k, c] += size * NOISE[c]
    res = preprocess(raw)
    fr = res.frame
    out = {c: (fr[f"flags_{c}"].to_numpy() & int(F.OUTLIER)) != 0 for c in CHANNELS}
    window = slice(950, 1200)
    for c, k in spikes:
        assert out[c][k], (c, k)
    # the step itself and its neighbours are not outliers, in any fin; nor anything
    # else in the manoeuvre
    for c in ("d1_rad", "d2_rad", "d3_rad", "d4_rad"):
        o = out[c].copy()
        o[[k for cc, k in spikes if cc == c]] = False
        assert not o[k_step - 20:k_step + 20].any(), (c, np.flatnonzero(o[window]) + 950)
        assert not o[window].any(), c
        # the 3-sample ramp at 30 s and the doublet at 40-41 s
        for a in (3000, 3500, 4000, 4050, 4100):
            assert not o[a - 20:a + 20].any(), (c, a)
    for c in ("q_rad_s", "az_m_s2"):
        o = out[c].copy()
        o[[k for cc, k in spikes if cc == c]] = False
        assert not o[window].any(), c


def test_actuator_dynamics_after_a_fin_step_are_not_outliers():
    """Fin steps through actuator dynamics are genuine manoeuvres: a second-order
    actuator (30 rad/s, damping 0.7: 4.6 % overshoot), a first-order lag (30 ms) and a
    rate-limited ramp over 4 samples, each followed later by the reverse step.
    (Much faster dynamics with large overshoot -- a 10 Hz actuator at 100 Hz
    sampling -- can be taken for a 2-3 sample spike burst: see detect.spike_mask.)"""
    rate = 100.0
    t = np.arange(0, 8.0, 1 / rate)
    rng = np.random.default_rng(5)

    def second_order(t_on, wn=30.0, zeta=0.7):
        tau = np.clip(t - t_on, 0, None)
        wd = wn * np.sqrt(1 - zeta**2)
        return 1 - np.exp(-zeta * wn * tau) * (np.cos(wd * tau) + zeta / np.sqrt(1 - zeta**2) * np.sin(wd * tau))

    shapes = {
        "d1_rad": 0.3 * (second_order(2.0) - second_order(5.0)),
        "d2_rad": -0.25 * ((1 - np.exp(-np.clip(t - 2.0, 0, None) / 0.03))
                           - (1 - np.exp(-np.clip(t - 5.0, 0, None) / 0.03))),
        "d3_rad": 0.3 * (np.clip((t - 2.0) * rate / 4, 0, 1) - np.clip((t - 5.0) * rate / 4, 0, 1)),
        "d4_rad": -0.3 * (second_order(2.0, 20.0, 0.6) - second_order(5.0, 20.0, 0.6)),
    }
    raw = make_flight(seed=5, duration_s=8.0, faults=False).raw
    raw = raw.assign(**{c: v + NOISE[c] * rng.standard_normal(t.size) for c, v in shapes.items()})
    res = preprocess(raw)
    fr = res.frame
    for c in shapes:
        out = (fr[f"flags_{c}"].to_numpy() & int(F.OUTLIER)) != 0
        # nothing at the transitions, nor elsewhere
        assert not out.any(), (c, np.flatnonzero(out))


def test_absurd_spike_is_flagged_and_replaced():
    raw = _clean_raw()
    raw.loc[321, "q_rad_s"] = 5.0e5   # absurd, out of range too
    raw.loc[322, "ay_m_s2"] += 200 * NOISE["ay_m_s2"]
    res = preprocess(raw)
    fr = res.frame
    assert fr["flags_q_rad_s"].iloc[321] & int(F.OUT_OF_RANGE)
    assert fr["flags_ay_m_s2"].iloc[322] & int(F.OUTLIER)
    assert fr["flags_ay_m_s2"].iloc[322] & int(F.INTERPOLATED)
    # neighbours are not dragged along
    assert fr["flags_ay_m_s2"].iloc[[320, 321, 323, 324]].eq(0).all()
    assert abs(fr["ay_m_s2_clean"].iloc[322] - fr["ay_m_s2_clean"].iloc[321]) < 10 * NOISE["ay_m_s2"]
    assert fr["q_rad_s_clean"].iloc[321] == pytest.approx(fr["q_rad_s_clean"].iloc[[320, 322]].mean())


def test_spike_bursts_of_two_and_three_samples_are_caught():
    raw = _clean_raw()
    raw.loc[400:401, "p_rad_s"] += 20 * NOISE["p_rad_s"]
    raw.loc[600:602, "d4_rad"] -= 50 * NOISE["d4_rad"]
    res = preprocess(raw)
    fr = res.frame
    assert np.all(fr["flags_p_rad_s"].to_numpy()[400:402] & int(F.OUTLIER))
    assert np.all(fr["flags_d4_rad"].to_numpy()[600:603] & int(F.OUTLIER))


# ---------------------------------------------------------------------------
# Errors
# ---------------------------------------------------------------------------

def test_duplicate_timestamps_raise_naming_file_column_and_rows():
    raw = _clean_raw()
    raw.loc[57, "t_s"] = raw.loc[56, "t_s"]
    with pytest.raises(TelemetryError) as ei:
        preprocess(raw, source="flight42.parquet")
    e = ei.value
    assert isinstance(e, ValueError)
    assert e.file == "flight42.parquet" and e.column == "t_s" and e.rows == [56, 57]
    assert "flight42.parquet" in str(e) and "'t_s'" in str(e) and "56" in str(e) and "duplicated" in str(e)
    e2 = pickle.loads(pickle.dumps(e))
    assert (e2.file, e2.column, e2.rows, str(e2)) == (e.file, e.column, e.rows, str(e))


def test_non_increasing_time_raises():
    raw = _clean_raw()
    raw.loc[80, "t_s"] = raw.loc[70, "t_s"] - 0.001
    with pytest.raises(TelemetryError, match="decreasing") as ei:
        preprocess(raw, source="f.parquet")
    assert ei.value.rows[:2] == [79, 80]


@pytest.mark.parametrize("mutate, column", [
    (lambda df: df.drop(columns=["q_rad_s"]), "q_rad_s"),
    (lambda df: df.assign(V_m_s=df["V_m_s"].astype("float32")), "V_m_s"),
    (lambda df: df.assign(t_s=df["t_s"].where(df.index != 5)), "t_s"),
    (lambda df: df.assign(d1_rad=df["d1_rad"] / DEG + 20.0), "d1_rad"),  # fins in degrees
    (lambda df: df.iloc[:0], None),
])
def test_bad_input_raises_telemetry_error(mutate, column):
    with pytest.raises(TelemetryError) as ei:
        preprocess(mutate(_clean_raw(duration=2.0)), source="bad.parquet")
    assert ei.value.file == "bad.parquet"
    assert ei.value.column == column


def test_single_row_needs_a_nominal_rate():
    raw = _clean_raw(duration=1.0).iloc[:1]
    with pytest.raises(TelemetryError, match="nominal_rate_hz"):
        preprocess(raw)
    res = preprocess(raw, PreprocessParams(nominal_rate_hz=100.0))
    assert res.n_grid_rows == 1
    assert_invariants(raw, res)


def test_clock_jump_and_implausible_rate_raise():
    raw = _clean_raw(duration=2.0)
    t = raw["t_s"].to_numpy().copy()
    t[100:] += 1e4
    with pytest.raises(TelemetryError, match="clock"):
        preprocess(raw.assign(t_s=t))
    with pytest.raises(TelemetryError, match="sample rate"):
        preprocess(raw.assign(t_s=raw["t_s"] * 1e6))  # microseconds


def test_params_are_validated():
    with pytest.raises(ValueError):
        PreprocessParams(max_interp_gap_s=-1.0)
    with pytest.raises(ValueError):
        PreprocessParams(snap_tolerance=0.7)
    with pytest.raises(ValueError):
        PreprocessParams(frozen_channels=("alpha",))


def test_input_is_not_modified_and_extra_columns_are_reported():
    raw = _clean_raw(duration=2.0).assign(alpha_rad=0.01)
    before = raw.copy()
    res = preprocess(raw)
    pd.testing.assert_frame_equal(raw, before)
    assert res.ignored_columns == ("alpha_rad",)
    assert "alpha_rad" in res.summary()


def test_performance_scale_is_linear_enough():
    """10 minutes at 100 Hz must run in a few seconds; no timing assertion here (the
    bench does that) -- just that it runs and gives a sane result."""
    fl = make_flight(seed=5, duration_s=600.0)
    res = preprocess(fl.raw)
    assert res.n_grid_rows == 60_000
    r = detection_rates(fl, res)
    assert r["dropouts_flagged"] == 1.0 and r["fp_rate"] <= 0.005


# ---------------------------------------------------------------------------
# Property test: random damage never gives an unexplained traceback
# ---------------------------------------------------------------------------

_BASE = make_flight(seed=99, duration_s=6.0, faults=False).raw


@st.composite
def damaged(draw):
    raw = _BASE.copy()
    n = len(raw)
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    vals = {c: raw[c].to_numpy().copy() for c in CHANNELS}
    for _ in range(draw(st.integers(0, 6))):          # NaN cells / NaN rows
        k0 = int(rng.integers(n)); length = int(rng.integers(1, 120))
        cols = CHANNELS if rng.uniform() < 0.5 else [CHANNELS[int(rng.integers(12))]]
        for c in cols:
            vals[c][k0:k0 + length] = np.nan
    for _ in range(draw(st.integers(0, 20))):         # spikes, sentinels, inf
        k = int(rng.integers(n)); c = CHANNELS[int(rng.integers(12))]
        vals[c][k] = rng.choice([vals[c][k] * 50 + 10, -9999.0, 1e30, np.inf, -np.inf, 0.0])
    for _ in range(draw(st.integers(0, 4))):          # frozen runs
        k0 = int(rng.integers(n)); c = CHANNELS[int(rng.integers(12))]
        vals[c][k0:k0 + int(rng.integers(2, 300))] = vals[c][k0]
    raw = raw.assign(**vals)
    keep = np.ones(n, bool)
    for _ in range(draw(st.integers(0, 5))):          # deleted rows
        k0 = int(rng.integers(n)); keep[k0:k0 + int(rng.integers(1, 400))] = False
    if draw(st.booleans()):
        keep[rng.integers(n, size=int(rng.integers(1, n)))] = False   # scattered losses
    raw = raw[keep].reset_index(drop=True)
    if len(raw) > 3 and draw(st.integers(0, 9)) == 0:  # occasionally a duplicated time
        raw.loc[2, "t_s"] = raw.loc[1, "t_s"]
    return raw


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(damaged())
def test_random_damage_gives_result_or_telemetry_error(raw):
    try:
        res = preprocess(raw, source="random.parquet")
    except TelemetryError as e:
        assert e.file == "random.parquet"
        return
    assert_invariants(raw, res)
    fr = res.frame
    for c in CHANNELS:
        f = fr[f"flags_{c}"].to_numpy()
        clean = fr[f"{c}_clean"].to_numpy()
        assert np.all(np.isfinite(clean[f == 0]))
        assert np.all(np.isnan(clean[(f & int(F.LONG_GAP | F.EDGE_GAP)) != 0]))


# ---------------------------------------------------------------------------
# Acceptance on the project's simulator (seed-rlv reference flight, known faults)
# ---------------------------------------------------------------------------

def test_acceptance_on_the_simulated_reference_flight(reference_flight):
    """aerosid.simulation's fault masks (truth columns fault_*): every dropout sample
    flagged, >= 99 % of the outliers (6..40 sigma) flagged (50 of 50), at most 2 false
    outliers among the 100 000 clean samples (1; the old fixed 3.3-sigma test: 150) and
    none within 1 s of the sharpest pitch manoeuvre (max |q_dot|)."""
    fl = reference_flight
    res = preprocess(fl.telemetry, source="seed-rlv/0")
    assert_invariants(fl.telemetry, res)
    tr, fr = fl.truth, res.frame
    t_truth = tr["t_s"].to_numpy()
    k = np.round((fr["t_s"].to_numpy() - t_truth[0]) * res.nominal_rate_hz).astype(int)
    assert k[0] == 0 and np.all(np.diff(k) == 1) and k[-1] < len(tr)
    drop = tr["fault_dropout"].to_numpy().astype(bool)
    t_sharp = t_truth[int(np.argmax(np.abs(tr["q_dot_rad_s2"].to_numpy())))]
    sharp = np.abs(t_truth - t_sharp) <= 1.0
    n_out = n_out_flagged = n_clean = fp = n_clean_sharp = fp_sharp = 0
    for c in CHANNELS:
        f = np.zeros(len(tr), dtype=np.int64)
        f[k] = fr[f"flags_{c}"].to_numpy()
        assert np.all(f[drop] & int(DETECTION)), c
        out = tr[f"fault_outlier_{c}"].to_numpy().astype(bool) if f"fault_outlier_{c}" in tr else np.zeros_like(drop)
        n_out += int(out.sum())
        n_out_flagged += int(((f[out] & int(DETECTION)) != 0).sum())
        clean = ~drop & ~out
        flagged = (f & int(F.OUTLIER)) != 0
        n_clean += int(clean.sum())
        fp += int((flagged & clean).sum())
        n_clean_sharp += int((clean & sharp).sum())
        fp_sharp += int((flagged & clean & sharp).sum())
    assert n_out > 10
    assert n_out_flagged / n_out >= 0.99
    assert fp <= 2 and n_clean > 100_000
    assert fp_sharp == 0 and n_clean_sharp > 2000
    assert len(res.long_gaps) >= 1 and res.longest_gap_s >= 1.9   # the 2 s sync gap


def test_a_record_in_unix_time_is_processed_in_seconds_since_its_first_whole_second():
    """At 1.7e9 s a float64 timestamp resolves 2.4e-7 s: the grid's steps would scatter by 2e-5 of
    a 100 Hz step, and the smoother refused the flight as a broken clock."""
    fl = make_flight(seed=11, duration_s=30.0)
    raw = fl.raw.copy()
    raw["t_s"] = raw["t_s"] + 1.7e9
    ref, res = preprocess(fl.raw), preprocess(raw)
    assert ref.time_origin_s == 0.0 and res.time_origin_s == math.floor(1.7e9 + fl.raw["t_s"].iloc[0])
    t = res.frame["t_s"].to_numpy()
    d = np.diff(t)
    # the first grid point is within half a step of the first (jittered) timestamp
    assert -0.005 <= t[0] < 1.005 and np.allclose(d, np.median(d), rtol=1e-9, atol=0.0)  # the smoother's test, tighter
    np.testing.assert_allclose(t, ref.frame["t_s"].to_numpy() - (res.time_origin_s - 1.7e9), atol=1e-5)  # 1e-3 step
    assert np.array_equal(res.frame["flags"].to_numpy(), ref.frame["flags"].to_numpy())
    assert res.metadata()["aerosid.preprocess.time_origin_s"] == repr(res.time_origin_s)
    assert f"times in s since {res.time_origin_s:.0f}" in res.summary()


def test_a_clock_with_gaussian_jitter_keeps_its_rate_and_loses_only_the_rows_off_the_grid():
    """0.2 step rms of timestamp jitter: counting whole steps between rows took intervals stretched
    past 1.5 steps for dropouts (103.2 Hz inferred for 100 Hz), and rows half a step off collided
    with their neighbours; the coherent rate and the collision rule keep the record."""
    fl = make_flight(seed=12, duration_s=30.0, faults=False, jitter=0.0)
    raw = fl.raw.copy()
    rng = np.random.default_rng(12)
    t = raw["t_s"].to_numpy() + 0.2 / 100.0 * rng.standard_normal(len(raw))
    keep = np.r_[True, np.diff(t) > 0] & np.r_[np.diff(t) > 0, True]  # a sorted record
    raw = raw[keep].assign(t_s=t[keep]).reset_index(drop=True)
    res = preprocess(raw)
    assert res.rate_inferred and res.nominal_rate_hz == pytest.approx(100.0, rel=1e-5)
    jit = (res.frame["flags"].to_numpy() & int(F.TIME_JITTER)) != 0
    assert 0.15 < jit.mean() < 0.28  # P(|e| > 0.25 step) = 0.21 at 0.2 rms
    assert res.n_grid_rows == res.n_raw_rows + res.n_inserted_rows and res.n_inserted_rows < 0.01 * res.n_raw_rows
    off = np.abs(res.frame["t_raw_s"] - res.frame["t_s"]).to_numpy() * 100.0
    assert np.nanmax(off[~jit]) <= 0.25 + 1e-9 and np.nanmax(off) <= 1.0


def test_two_rows_on_one_grid_point_keep_the_closer_and_a_wrong_rate_is_still_refused():
    fl = make_flight(seed=13, duration_s=5.0, faults=False)
    raw = fl.raw.copy()
    t = raw["t_s"].to_numpy().copy()
    t[200] = t[199] + 0.0024  # 2.4 ms after its neighbour (c182 with 2 ms rms of jitter had such a pair)
    raw["t_s"] = t
    res = preprocess(raw, PreprocessParams(nominal_rate_hz=100.0))
    fr = res.frame
    moved = np.flatnonzero(np.isclose(fr["t_raw_s"].to_numpy(), t[200], rtol=0, atol=1e-12))
    assert moved.size == 1 and fr["flags"].iloc[moved[0]] & int(F.TIME_JITTER)  # missing, not used late
    assert not fr["flags"].iloc[moved[0] - 1] & int(F.TIME_JITTER)  # the row on its own point is kept
    assert res.n_grid_rows == res.n_raw_rows + res.n_inserted_rows
    with pytest.raises(TelemetryError, match="same grid point"):  # every neighbour taken: a wrong rate
        preprocess(fl.raw, PreprocessParams(nominal_rate_hz=50.0))


def test_a_window_in_the_record_s_unix_clock_is_moved_to_the_run_s_time(tmp_path):
    from aerosid.cli.run import _windows_in_run_time

    path = tmp_path / "t.parquet"
    pd.DataFrame({"t_s": 1.7e9 + 0.25 + np.arange(1000) * 0.01}).to_parquet(path)
    assert _windows_in_run_time(path, [(1.7e9 + 2.0, 1.7e9 + 8.0), (1.0, 3.0)]) == ((2.0, 8.0), (1.0, 3.0))
    pd.DataFrame({"t_s": 100.0 + np.arange(1000) * 0.01}).to_parquet(path)
    assert _windows_in_run_time(path, [(101.0, 105.0)]) == ((101.0, 105.0),)
