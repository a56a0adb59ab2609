"""Preprocessing that knows real sensors (aerosid.preprocess.sensors, params): held
(sample-and-hold) and quantised channels are not faults, a stuck sensor still is, the
outlier test does not fire on quiet noise, and the thresholds can be set per sensor."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from aerosid.preprocess import (
    FAULT,
    PreprocessParams,
    QualityFlag,
    SettingsError,
    merge_settings,
    parse_assignments,
    parse_settings,
    preprocess,
    usable_mask,
)
from aerosid.preprocess import detect, sensors
from schemas.telemetry import CHANNELS, validate, PreprocessedTelemetry
from tests.preprocess.test_preprocess import NOISE, make_flight

F = QualityFlag
DEG = math.pi / 180.0


def hold(x: np.ndarray, every: float, phase: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Sample-and-hold of x: updated at the samples round(phase + j * every), held
    between (returns the held series and the update indices)."""
    n = x.size
    upd = np.unique(np.round(phase + np.arange(0, n / every + 1) * every).astype(int))
    upd = upd[upd < n]
    idx = upd[np.searchsorted(upd, np.arange(n), side="right") - 1]
    out = x.copy()
    out[upd[0]:] = x[idx[upd[0]:]]
    return out, upd


def flags(res, c):
    return res.frame[f"flags_{c}"].to_numpy()


# ---------------------------------------------------------------------------
# Held (sample-and-hold) channels
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("channel, every", [("V_m_s", 5), ("q_rad_s", 5), ("h_m", 100 / 12)])
def test_a_held_channel_is_recognised_and_interpolated_between_its_updates(channel, every):
    """A channel updated at 1/5 of the rate (or 12 Hz in a 100 Hz record) is held, not
    frozen: its repeats are HELD (not a fault; the row is used), its updates are
    measurements, and the clean value is the straight line between update instants."""
    raw = make_flight(seed=31, duration_s=10.0, faults=False).raw
    held, upd = hold(raw[channel].to_numpy(), every)
    raw[channel] = held
    res = preprocess(raw)
    prof = res.sensors[channel]
    assert prof["update_interval"] == pytest.approx(every, abs=0.05)
    assert not prof["at_rest"]
    f = flags(res, channel)
    assert res.flag_counts_by_channel[channel]["FROZEN"] == 0
    assert res.flag_counts_by_channel[channel]["OUTLIER"] == 0
    assert np.all(f[upd] == 0)                                    # every update is a measurement
    rest = np.setdiff1d(np.arange(upd[0] + 1, upd[-1]), upd)
    assert np.all(f[rest] == F.HELD | F.INTERPOLATED)
    assert np.all(f[upd[-1] + 1:] == F.HELD | F.EDGE_GAP)       # after the last update: no right anchor
    clean = res.frame[f"{channel}_clean"].to_numpy()
    expect = np.interp(np.arange(len(raw)), upd, held[upd])
    np.testing.assert_allclose(clean[upd[0]:upd[-1] + 1], expect[upd[0]:upd[-1] + 1], rtol=0, atol=1e-9)
    assert res.n_used_rows == res.n_raw_rows and res.usable_share["share"] == 1.0
    assert res.usable_share["by_channel"][channel]["used"] == len(raw)
    assert not usable_mask(res.frame, channel)[rest].any()       # the Kalman filter skips held samples
    assert "held: updated every" in res.summary()
    validate(res.frame, PreprocessedTelemetry, "test")


def test_a_spike_on_a_held_update_is_flagged_with_the_samples_holding_it():
    raw = make_flight(seed=32, duration_s=10.0, faults=False).raw
    held, upd = hold(raw["az_m_s2"].to_numpy(), 5)
    k = upd[100]
    held[k:upd[101]] += 30 * NOISE["az_m_s2"]     # one bad update, held for 5 samples
    raw["az_m_s2"] = held
    res = preprocess(raw)
    f = flags(res, "az_m_s2")
    assert np.all(f[k:upd[101]] & int(F.OUTLIER)) and not np.any(f[k:upd[101]] & int(F.HELD))
    assert not np.any(f[:k] & int(F.OUTLIER)) and not np.any(f[upd[101]:] & int(F.OUTLIER))
    clean = res.frame["az_m_s2_clean"].to_numpy()
    assert np.all(np.abs(clean[k:upd[101]] - raw["az_m_s2"].to_numpy()[k - 5]) < 15 * NOISE["az_m_s2"])


def test_a_stuck_held_channel_is_still_frozen():
    """Held at 1/5 of the rate, then stuck for 2 s (40 updates) while everything else
    moves: FROZEN from the first repeat of the last update; the hold around is HELD."""
    raw = make_flight(seed=33, duration_s=10.0, faults=False).raw
    held, upd = hold(raw["p_rad_s"].to_numpy(), 5)
    k0 = upd[80]
    held[k0:k0 + 200] = held[k0]
    raw["p_rad_s"] = held
    res = preprocess(raw)
    f = flags(res, "p_rad_s")
    assert f[k0] == 0 and np.all(f[k0 + 1:k0 + 200] & int(F.FROZEN))
    assert np.all(f[k0 + 1:k0 + 200] & int(F.LONG_GAP))
    assert res.flag_counts_by_channel["p_rad_s"]["FROZEN"] == 199
    assert np.all(f[upd[10] + 1:upd[11]] == F.HELD | F.INTERPOLATED)


# ---------------------------------------------------------------------------
# Quantised channels
# ---------------------------------------------------------------------------

def _quantise(x, step):
    return np.round(x / step) * step


def test_a_quantised_surface_holding_still_is_not_frozen():
    """A surface recorded at 0.01 deg that holds still between doublets (noise below one
    step: it flickers by a step now and then), one that never moves, and an airspeed recorded at 0.17 ft/s falling slowly
    (runs of one value up to a second, as on NASA's Twin Otter): no FROZEN, all used."""
    rate, n = 50.0, 600
    t = np.arange(n) / rate
    rng = np.random.default_rng(41)
    raw = make_flight(seed=41, duration_s=n / rate, rate_hz=rate, faults=False).raw
    step = 0.01 * DEG
    doublet = np.where((t > 3) & (t < 3.5), 2 * DEG, 0) - np.where((t >= 3.5) & (t < 4), 2 * DEG, 0)
    # a level's centre plus 0.4 steps of noise: the value flickers by one step now and then
    raw["d1_rad"] = _quantise(0.5 * DEG + doublet + 0.004 * DEG * rng.standard_normal(n), step)
    raw["d3_rad"] = _quantise(np.full(n, -0.1 * DEG), step)          # never moves
    raw["V_m_s"] = _quantise(72.0 - 0.15 * t + 0.005 * rng.standard_normal(n), 0.1686 * 0.3048)
    res = preprocess(raw)
    for c in ("d1_rad", "d3_rad", "V_m_s"):
        assert res.flag_counts_by_channel[c]["FROZEN"] == 0, c
        assert res.flag_counts_by_channel[c]["OUTLIER"] == 0, c
        assert res.sensors[c]["at_rest"], (c, res.sensors[c])
        assert res.usable_share["by_channel"][c]["share"] == 1.0
    assert res.sensors["d1_rad"]["resolution"] == pytest.approx(step, rel=1e-6)
    assert res.sensors["d3_rad"]["constant"]
    assert res.n_used_rows == n
    assert "not tested for frozen runs" in res.summary()


def test_a_noisy_quantised_channel_stuck_is_frozen_and_a_limit_catches_a_still_one():
    """Noise of 2 steps: updates rarely repeat, so 1 s of one value is a stuck sensor.
    A channel at rest is only frozen past the still time given for that sensor."""
    raw = make_flight(seed=42, duration_s=10.0, faults=False).raw
    step = NOISE["q_rad_s"] / 2
    q = _quantise(raw["q_rad_s"].to_numpy(), step)
    q[400:500] = q[400]
    raw["q_rad_s"] = q
    # a surface at rest (0.4 steps of noise about a level's centre) that sticks for 4 s
    n = len(raw)
    still = _quantise(0.2 + 0.004 * DEG * np.random.default_rng(3).standard_normal(n), 0.01 * DEG)
    still[500:900] = still[500]
    raw["d4_rad"] = still
    res = preprocess(raw)
    f = flags(res, "q_rad_s")
    assert res.sensors["q_rad_s"]["resolution"] == pytest.approx(step, rel=1e-6)
    assert not res.sensors["q_rad_s"]["at_rest"]
    assert np.all(f[401:500] & int(F.FROZEN)) and not np.any(f[:400] & int(F.FROZEN))
    assert res.flag_counts_by_channel["d4_rad"]["FROZEN"] == 0
    assert res.sensors["d4_rad"]["at_rest"]
    res = preprocess(raw, PreprocessParams(sensors={"d4_rad": {"frozen_max_still_s": 3.0}}))
    f = flags(res, "d4_rad")
    starts, ends = sensors.value_runs(still)
    first = starts[np.searchsorted(starts, 500, side="right") - 1]   # the stuck run began at or before 500
    assert np.all(f[first + 1:900] & int(F.FROZEN)) and not np.any(f[:first + 1] & int(F.FROZEN))
    assert res.flag_counts_by_channel["d4_rad"]["FROZEN"] == ends[starts == first][0] - first - 1


def test_resolution_and_update_interval_detectors():
    rng = np.random.default_rng(5)
    x = rng.standard_normal(2000)
    assert sensors.resolution(x) == 0.0 and sensors.update_interval(x) == 1.0
    q = _quantise(3 * x, 1.0) * 0.01 * DEG                       # 0.01 deg steps, ~3 steps of noise
    assert sensors.resolution(q) == pytest.approx(0.01 * DEG, rel=1e-9)
    h, _ = hold(x, 4)
    assert sensors.update_interval(h) == 4.0
    h, _ = hold(x, 50 / 12)                                        # 12 Hz in a 50 Hz record
    assert sensors.update_interval(h) == pytest.approx(50 / 12, abs=0.05)
    assert sensors.update_interval(_quantise(np.cumsum(0.1 * x), 1.0)) == 1.0  # quantised random walk: not held


# ---------------------------------------------------------------------------
# Outliers: no false alarms on quiet noise, spikes still found
# ---------------------------------------------------------------------------

def test_a_quiet_gaussian_channel_of_1e5_samples_yields_at_most_one_outlier():
    """Every channel white Gaussian noise around a constant (quantised at 0.3 sigma for
    d1 and 3 steps of 1 LSB... far below it for d2), 10^5 samples: at most 1 outlier
    per channel (the threshold, 5.7 sigma of the test's residual here, is set for one
    false outlier in 1000 such records); the old fixed 3.3-sigma test flagged ~100."""
    n = 100_000
    rng = np.random.default_rng(51)
    base = {"ax_m_s2": -20.0, "ay_m_s2": 0.5, "az_m_s2": -9.81, "p_rad_s": 0.0, "q_rad_s": 0.01, "r_rad_s": 0.0,
            "d1_rad": 0.01, "d2_rad": 0.02, "d3_rad": 0.0, "d4_rad": 0.0, "V_m_s": 300.0, "h_m": 5000.0}
    raw = pd.DataFrame({"t_s": np.arange(n) / 100.0,
                        **{c: base[c] + NOISE[c] * rng.standard_normal(n) for c in CHANNELS}})
    raw["d1_rad"] = _quantise(raw["d1_rad"].to_numpy(), NOISE["d1_rad"] / 0.3)  # noise 0.3 step
    raw["d2_rad"] = _quantise(raw["d2_rad"].to_numpy(), NOISE["d2_rad"] / 3)    # noise 3 steps
    res = preprocess(raw)
    for c in CHANNELS:
        assert res.flag_counts_by_channel[c]["OUTLIER"] <= 1, (c, res.flag_counts_by_channel[c])
        assert res.flag_counts_by_channel[c]["FROZEN"] == 0, c
    assert res.sensors["ax_m_s2"]["threshold_sigma"] == pytest.approx(detect.gaussian_threshold(n, 1e-3))


def test_the_threshold_follows_the_false_alarm_probability_on_noise():
    """On pure noise the number of outliers tracks the design rate: with false_alarm = 20
    expected per record (a threshold of 3.7 sigma for 10^5 samples) about 5-20 fire
    (the curvature allowance and the guard make the test a little conservative)."""
    rng = np.random.default_rng(52)
    x = rng.standard_normal(100_000)
    sigma, _ = detect.noise_scale(x, 500, 0.0)
    count = int(detect.spike_mask(x, 5, sigma, detect.gaussian_threshold(x.size, 20.0), 500).sum())
    assert 5 <= count <= 30, count
    assert detect.gaussian_threshold(6000, 1e-3) == pytest.approx(5.23, abs=0.01)


def test_a_fixed_threshold_per_sensor_overrides_the_record_length_rule():
    fl = make_flight(seed=53, duration_s=20.0, faults=False)
    raw = fl.raw.copy()
    raw.loc[700, "ay_m_s2"] += 6.5 * NOISE["ay_m_s2"]
    strict = preprocess(raw, PreprocessParams(sensors={"ay_m_s2": {"outlier_threshold_sigma": 4.0}}))
    assert strict.sensors["ay_m_s2"]["threshold_sigma"] == 4.0
    assert flags(strict, "ay_m_s2")[700] & int(F.OUTLIER)
    off = preprocess(raw, PreprocessParams(sensors={"ay_m_s2": {"detect_outliers": False}}))
    assert off.flag_counts_by_channel["ay_m_s2"]["OUTLIER"] == 0


# ---------------------------------------------------------------------------
# Settings: [preprocess] tables and --preprocess KEY=VALUE
# ---------------------------------------------------------------------------

def test_settings_are_parsed_checked_and_merged():
    kwargs, min_seg = parse_settings({"false_alarm": 1e-4, "min_segment_s": 4,
                                      "V_m_s": {"update_interval_s": 0.2, "resolution": 0.05}})
    assert min_seg == 4.0 and kwargs["false_alarm"] == 1e-4
    assert kwargs["sensors"] == {"V_m_s": {"update_interval_s": 0.2, "resolution": 0.05}}
    cli, _ = parse_settings(parse_assignments(["V_m_s.resolution=0.1", "max_interp_gap_s=1", "d1_rad.detect_frozen=no"]))
    merged = merge_settings(kwargs, cli)
    p = PreprocessParams.from_dict(merged)
    assert p.sensor("V_m_s", "resolution") == 0.1 and p.sensor("V_m_s", "update_interval_s") == 0.2
    assert p.sensor("d1_rad", "detect_frozen") is False and p.sensor("d2_rad", "detect_frozen") is True
    assert p.max_interp_gap_s == 1.0 and p.sensor("q_rad_s", "false_alarm") == 1e-4
    assert PreprocessParams.from_dict(p.to_dict()) == p                    # metadata round trip
    for bad, key in (({"false_alarm": 2.0}, "false_alarm"), ({"frozen_min_run": 1}, "frozen_min_run"),
                     ({"nonsense": 1}, "nonsense"), ({"q_deg_s": {"resolution": 1}}, "q_deg_s"),
                     ({"V_m_s": {"resolutoin": 1}}, "V_m_s.resolutoin"), ({"V_m_s": {"resolution": "x"}},
                                                                          "V_m_s.resolution")):
        with pytest.raises(SettingsError) as err:
            parse_settings(bad)
        assert err.value.key == key
    with pytest.raises(SettingsError, match="KEY=VALUE"):
        parse_assignments(["false_alarm"])


def test_vehicle_preprocess_table_is_loaded_and_errors_name_the_key(tmp_path):
    from aerosid.vehicles.vehicle import VehicleError, load_vehicle, resolve_vehicle_path

    text = resolve_vehicle_path("c172x").read_text()
    good = tmp_path / "good.toml"
    good.write_text(text + "\n[preprocess]\nmin_segment_s = 4.0\nfalse_alarm = 1e-4\n\n"
                           "[preprocess.V_m_s]\nupdate_interval_s = 0.2\n")
    veh = load_vehicle(good)
    assert veh.min_segment_s == 4.0
    assert veh.preprocess == {"false_alarm": 1e-4, "sensors": {"V_m_s": {"update_interval_s": 0.2}}}
    assert load_vehicle("c172x").preprocess == {} and load_vehicle("c172x").min_segment_s is None
    bad = tmp_path / "bad.toml"
    bad.write_text(text + "\n[preprocess.V_m_s]\nupdate_interval_s = -1\n")
    with pytest.raises(VehicleError, match=r"\[preprocess.V_m_s.update_interval_s\] must be > 0"):
        load_vehicle(bad)


def test_used_rows_count_faults_not_holds():
    """Rows used = recorded rows where no contract channel holds a fault; a vane's
    fault counts for the vane only."""
    raw = make_flight(seed=61, duration_s=5.0, faults=False).raw
    raw.loc[100:104, "q_rad_s"] = np.nan
    res = preprocess(raw)
    assert res.n_used_rows == len(raw) - 5
    assert res.usable_share["by_channel"]["q_rad_s"]["used"] == len(raw) - 5
    assert res.usable_share["by_channel"]["p_rad_s"]["used"] == len(raw)
    fault = (res.frame["flags"].to_numpy() & np.uint16(int(FAULT))) != 0
    assert int((~fault).sum()) == res.n_used_rows
    assert f"rows used (every channel a measurement or a held value): {len(raw) - 5} of {len(raw)}" in res.summary()
