"""The vanes against the IMU (aerosid.identification.vanes): their delay on closed-form
kinematics with a known delay, the shift, the attitude from the gyros, the vehicle keys, the
real Twin Otter flight whose vanes lag; their position against the exact velocity of the vane's
point."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from aerosid.identification.vanes import DELAY_P_MAX, advance, gyro_attitude, vane_delay
from aerosid.vehicles.vehicle import VehicleError, load_vehicle

G = 9.80665


def kinematic_flight(fs_hz=50.0, duration_s=20.0, V=70.0, with_theta=False):
    """A longitudinal flight whose signals obey the kinematics exactly: alpha(t), theta(t)
    chosen, q = theta_dot, a_x = g sin theta, a_z solved from
    alpha_dot = q + (cos a a_z - sin a a_x) / V + g cos(theta - alpha) / V; steady at t = 0."""
    t = np.arange(0.0, duration_s, 1.0 / fs_hz)
    ramp = np.clip(t - 1.0, 0.0, None)  # quiet for 1 s: the initial attitude's quasi-steady start
    w = 2 * np.pi * np.array([0.3, 0.7, 1.3])
    amp = np.array([0.02, 0.012, 0.006])
    env = 1.0 - np.exp(-ramp ** 2)
    alpha = 0.05 + env * (amp[:, None] * np.sin(w[:, None] * ramp)).sum(0)
    theta = 0.05 + env * (0.8 * amp[:, None] * np.sin(w[:, None] * ramp + 0.4)).sum(0)

    def d(x):
        return np.gradient(x, t, edge_order=2)

    q = d(theta)
    ax = G * np.sin(theta)
    az = (V * (d(alpha) - q) + np.sin(alpha) * ax - G * np.cos(theta - alpha)) / np.cos(alpha)
    z = np.zeros_like(t)
    if with_theta:
        return t, theta, q
    return t, alpha, dict(beta_rad=z, p_rad_s=z, q_rad_s=q, r_rad_s=z, ax_cg_m_s2=ax, ay_cg_m_s2=z,
                          az_cg_m_s2=az, V_m_s=np.full_like(t, V))


def late(t, x, delay_s):
    return advance(t, x, -delay_s)


@pytest.mark.parametrize("delay_s", [0.0, 0.03])
def test_a_known_delay_is_recovered_within_its_sigma(delay_s):
    t, alpha, sig = kinematic_flight()
    rng = np.random.default_rng(3)
    vane = late(t, alpha, delay_s) + 2e-4 * rng.standard_normal(t.size)
    vd = vane_delay(t, vane, **sig)
    assert vd is not None
    assert abs(vd.delay_s - delay_s) < 3.0 * vd.sigma_s + 1e-4
    assert vd.sigma_s < 0.005  # the test can tell 30 ms from nothing
    assert abs(vd.gain - 1.0) < 0.02
    assert vd.detected == (delay_s > 0)
    if delay_s == 0.0:
        assert vd.p_value > DELAY_P_MAX
    else:
        assert "lags" in vd.summary() and vd.p_value < DELAY_P_MAX


def test_a_lead_reads_as_negative_and_a_sub_sample_skew_is_not_reported():
    t, alpha, sig = kinematic_flight(fs_hz=100.0)
    lead = vane_delay(t, advance(t, alpha, 0.02), **sig)
    assert lead.delay_s == pytest.approx(-0.02, abs=1e-3) and "leads" in lead.summary() and lead.detected
    small = vane_delay(t, late(t, alpha, 0.004), **sig)  # significant on exact data, but < one sample (10 ms)
    assert small.delay_s == pytest.approx(0.004, abs=5e-4)
    assert small.p_value < DELAY_P_MAX and not small.detected


def test_gaps_split_the_fit_into_runs_and_short_runs_are_left_out():
    t, alpha, sig = kinematic_flight()
    vane = late(t, alpha, 0.03)
    vane[400:410] = np.nan  # a gap: two runs, each with its own intercept and slope
    vd = vane_delay(t, vane, **sig)
    assert vd.delay_s == pytest.approx(0.03, abs=1e-3)
    # advance() NaNs 2 rows at the start; each run drops the rows whose shifted kinematics precede it
    assert t.size - 12 - 2 * 2 <= vd.n < t.size - 12
    short = vane_delay(t[:60], vane[:60], **{k: v[:60] for k, v in sig.items()})  # 1.2 s < MIN_RUN_S
    assert short is None


def test_advance_reads_later_within_each_run():
    t = np.arange(10) * 0.1
    x = 2.0 * t
    x[5] = np.nan
    y = advance(t, x, 0.05)
    inside = [0, 1, 2, 3, 6, 7, 8]
    assert np.allclose(y[inside], 2.0 * (t[inside] + 0.05))
    assert np.isnan(y[[4, 5, 9]]).all()  # past the end of its run, or missing
    assert np.array_equal(advance(t, x, 0.0), x, equal_nan=True)


def test_gyro_attitude_integrates_the_pitch_rate_from_the_steady_start():
    t, truth, q = kinematic_flight(fs_hz=200.0, with_theta=True)
    zero = np.zeros_like(t)
    f0 = (G * math.sin(0.05), 0.0, -G * math.cos(0.05))  # the specific force of steady flight at theta 0.05
    theta, phi = gyro_attitude(t, zero, q, zero, f0)
    assert theta[0] == pytest.approx(0.05, abs=1e-12)
    assert np.max(np.abs(theta - truth)) < 5e-4 and np.max(np.abs(phi)) < 1e-12  # forward Euler, h = 5 ms


def test_the_vehicle_file_key(tmp_path):
    from tests.twin_otter import VEHICLE_TOML

    good = tmp_path / "v.toml"
    good.write_text(VEHICLE_TOML.replace('source = "vanes"', 'source = "vanes"\ndelay_s = 0.025'))
    assert load_vehicle(good).vane_delay_s == 0.025
    bad = tmp_path / "bad.toml"
    bad.write_text(VEHICLE_TOML.replace('source = "vanes"', 'source = "vanes"\ndelay_s = 2.0'))
    with pytest.raises(VehicleError, match="delay_s"):
        load_vehicle(bad)


ROOT = Path(__file__).parents[2]
DATA = next((d for d in (ROOT / "tests" / "data" / "sidpac-twin-otter", ROOT.parent / "shared" / "data" / "sidpac-twin-otter",
                         ROOT.parents[1] / "shared" / "data" / "sidpac-twin-otter") if d.is_dir()),
            ROOT / "tests" / "data" / "sidpac-twin-otter")
F018 = DATA / "lon_020213f1_018.mat"


@pytest.mark.skipif(not F018.is_file(), reason=f"Twin Otter data not found ({DATA})")
def test_the_twin_otters_vanes_lag_and_the_correction_moves_the_fit_toward_output_error():
    """Real data: the vane alpha of manoeuvre 018 lags the IMU by about 25 ms (the raw data with
    the recorded attitude say 20-25 ms); the run reports it, and the vehicle file's delay_s
    takes the C_N fit's C_N,delta from equation error's 0.19 toward SIDPAC's output error (0.409)."""
    from aerosid.ebm import process_telemetry
    from aerosid.vehicles.sidpac import import_sidpac

    flight = import_sidpac(F018)
    vehicle = load_vehicle(flight.write(Path(__import__("tempfile").mkdtemp()))["vehicle"])
    run = process_telemetry(flight.telemetry, vehicle)
    found = [f for f in run.findings if f["kind"] == "airdata_delay"]
    assert len(found) == 1 and "lags" in found[0]["detail"]
    assert "calibrated" not in found[0]["detail"]  # its pitch kinematics say V is the true airspeed
    delay = float(found[0]["detail"].split("`delay_s = ")[1].split("`")[0])
    assert 0.015 <= delay <= 0.035
    fixed = process_telemetry(flight.telemetry, dataclasses.replace(vehicle, vane_delay_s=delay))
    assert not [f for f in fixed.findings if f["kind"] == "airdata_delay"]
    # the estimate is recorded either way (run.json's flight_data.vane_timing, the audit trail)
    (before_t,), (after_t,) = run.flight_data.attrs["vane_timing"], fixed.flight_data.attrs["vane_timing"]
    assert before_t["detected"] and before_t["delay_s"] == pytest.approx(delay, abs=0.0005)
    assert not after_t["detected"] and after_t["applied_s"] == delay and abs(after_t["delay_s"]) < 3 * after_t["sigma_s"]

    def cn(r, name):
        tab = r.identification.table().set_index("coefficient")
        return float(tab.loc[name, "estimate"]), float(tab.loc[name, "std_error"])

    before, after = cn(run, "CN_delta_p"), cn(fixed, "CN_delta_p")
    assert abs(after[0] - 0.409) < abs(before[0] - 0.409) - 2 * before[1]
    assert fixed.identification.fits["CN"].rms_residual < 0.7 * run.identification.fits["CN"].rms_residual


def test_many_short_runs_do_not_bias_a_large_delay():
    """Each run drops the rows whose shifted kinematics would start before it (clamping them
    biased a 60 ms delay by about 1 ms on runs of 2.4 s)."""
    t, alpha, sig = kinematic_flight(fs_hz=50.0, duration_s=30.0)
    for delay_s in (0.06, -0.06):
        vane = advance(t, alpha, -delay_s)
        vane[np.arange(t.size) % 125 < 5] = np.nan  # gaps of 0.1 s every 2.5 s
        vd = vane_delay(t, vane, **sig)
        assert vd.delay_s == pytest.approx(delay_s, abs=2e-4)


def test_a_vane_ahead_of_the_cg_looks_like_a_delay_until_it_is_moved_to_the_cg(tmp_path):
    """alpha_vane = alpha - x q / V for a boom x ahead of the CG: in a short period q leads alpha
    as alpha-dot does, so the timing check sees a "delay"; angles_at_cg removes it exactly."""
    import pandas as pd

    from aerosid.identification.flight_data import vane_angles
    from aerosid.identification.vanes import angles_at_cg

    t, alpha, sig = kinematic_flight()
    x = 6.0
    q, V = sig["q_rad_s"], sig["V_m_s"]
    vane = alpha - x * q / V
    fooled = vane_delay(t, vane, **sig)
    assert fooled.detected and fooled.delay_s > 0.01  # a boom reads as a lag
    a, b = angles_at_cg(vane, np.zeros_like(t), sig["p_rad_s"], q, sig["r_rad_s"], V, (x, 0.0, 0.0))
    assert np.allclose(a, alpha, atol=1e-15) and np.allclose(b, 0.0)
    assert not vane_delay(t, a, **sig).detected
    # the flight data's reader: advance by delay_s, then move to the CG with the clean gyros
    from tests.twin_otter import VEHICLE_TOML

    path = tmp_path / "v.toml"
    path.write_text(VEHICLE_TOML.replace('source = "vanes"', f'source = "vanes"\ndelay_s = 0.04\nvane_position_m = [{x}, 0, 0]'))
    veh = load_vehicle(path)
    assert veh.vane_position_m == (x, 0.0, 0.0)
    z = np.zeros_like(t)
    pre = pd.DataFrame({"alpha_vane_rad_clean": late(t, vane, 0.04), "beta_vane_rad_clean": z, "p_rad_s_clean": z,
                        "q_rad_s_clean": q, "r_rad_s_clean": z, "V_m_s_clean": V})
    a3, _ = vane_angles(t, pre, veh)
    inside = np.isfinite(a3)
    assert inside.sum() >= t.size - 4 and np.allclose(a3[inside], alpha[inside], atol=1e-6)


def test_the_position_correction_against_the_exact_velocity_of_the_vanes_point():
    """Independent of the formula: the air's velocity at r = (x, y, z) from the CG is v + w x r
    (body axes, x forward, y right, z down); the vane reads atan2(w_p, u_p) and asin(v_p / V_p).
    angles_at_cg must return the CG's alpha, beta to second order in the rate terms."""
    from aerosid.identification.vanes import angles_at_cg

    rng = np.random.default_rng(7)
    n, V = 200, 60.0
    alpha, beta = rng.uniform(-0.1, 0.15, n), rng.uniform(-0.05, 0.05, n)
    w_body = rng.uniform(-0.3, 0.3, (n, 3))  # p, q, r [rad/s]
    r_vane = np.array([4.0, 0.3, -0.5])
    vel = V * np.column_stack([np.cos(alpha) * np.cos(beta), np.sin(beta), np.sin(alpha) * np.cos(beta)])
    vp = vel + np.cross(w_body, r_vane)
    Vp = np.linalg.norm(vp, axis=1)
    a_vane, b_vane = np.arctan2(vp[:, 2], vp[:, 0]), np.arcsin(vp[:, 1] / Vp)
    a, b = angles_at_cg(a_vane, b_vane, *w_body.T, np.full(n, V), r_vane)
    shift = np.abs(np.cross(w_body, r_vane)).max(axis=1) / V  # the first-order correction's size
    second_order = shift * (np.abs(alpha) + np.abs(beta) + shift)  # a sign error would leave ~2 x shift
    assert np.all(np.abs(a - alpha) <= 0.5 * second_order) and np.all(np.abs(b - beta) <= 0.5 * second_order)
    # and the correction matters: without it the error is first order
    assert np.max(np.abs(a_vane - alpha)) > 10 * np.max(np.abs(a - alpha))


def test_a_vane_that_does_not_follow_the_kinematics_gives_no_delay():
    """A vane column unrelated to the flight (noise, a wrong channel): no delay reported, never an
    exception or a wild delay, and the result says the vane does not follow (a dead vane on c182
    gave C_N,alpha 1.5 against 5.5 with the run saying "ok"); a healthy one follows."""
    t, alpha, sig = kinematic_flight()
    rng = np.random.default_rng(11)
    for vane in (0.05 + 1e-3 * rng.standard_normal(t.size), 0.05 + 0.02 * np.sin(5.0 * t) ** 3):
        vd = vane_delay(t, vane, **sig)
        assert not vd.detected and not vd.follows
        assert not math.isfinite(vd.delay_s) or abs(vd.delay_s) <= 0.5
    healthy = vane_delay(t, alpha, **sig)
    assert healthy.follows and abs(healthy.gain - 1.0) < 0.05
    assert not vane_delay(t, 0.4 * alpha, **sig).follows  # a vane reading 0.4 of the angle: miscalibrated


@pytest.mark.skipif(not F018.is_file(), reason=f"Twin Otter data not found ({DATA})")
def test_a_dead_vane_on_the_twin_otter_is_a_finding_and_the_healthy_one_is_not():
    """Real data: the healthy vane follows the kinematics (gain ~1, no vane_mismatch); the same
    flight with the alpha vane replaced by noise about its mean says so (before: "ok", with
    C_N,alpha a third of its value on a JSBSim c182)."""
    from aerosid.ebm import process_telemetry
    from aerosid.vehicles.sidpac import import_sidpac

    flight = import_sidpac(F018)
    vehicle = load_vehicle(flight.write(Path(__import__("tempfile").mkdtemp()))["vehicle"])
    healthy = process_telemetry(flight.telemetry, vehicle)
    assert not [f for f in healthy.findings if f["kind"] == "vane_mismatch"]
    (rec,) = healthy.flight_data.attrs["vane_timing"]
    assert rec["follows"] and 0.9 < rec["gain"] < 1.1
    tel = flight.telemetry.copy()
    a = tel["alpha_vane_rad"].to_numpy()
    tel["alpha_vane_rad"] = np.nanmean(a) + 0.005 * np.random.default_rng(2).standard_normal(a.size)
    dead = process_telemetry(tel, vehicle)
    (f,) = [f for f in dead.findings if f["kind"] == "vane_mismatch"]
    assert f["channel"] == "alpha_vane_rad" and not f["cut"] and "does not follow" in f["detail"]
    assert "airspeed V_m_s in other units" in f["detail"] and "turbulent_air" in f["detail"]  # the other causes


def _vehicle_from_text(text: str, where: Path):
    path = where / "vehicle.toml"
    path.write_text(text)
    return load_vehicle(path)


def test_a_delay_finding_names_a_calibrated_airspeed_where_the_kinematics_cannot_exclude_it(tmp_path):
    """A calibrated airspeed at 1100-1450 m made the timing fit report a lag (c182 27.7 ms, OV10
    50.6 ms) whose cure, a delay_s, is the wrong one: the finding names the look-alike there, and
    not where the pitch kinematics put V at the true airspeed (the real Twin Otter)."""
    from aerosid.identification.airdata_findings import _airspeed_scale, _calibrated_airspeed_hint
    from aerosid.vehicles.airspeed import calibrated_from_true_m_s
    try:
        from aerosid.simulation.jsbsim_aircraft import simulate_aircraft
        fl = simulate_aircraft("c182", 0)
    except ImportError as exc:  # jsbsim is an optional extra
        pytest.skip(f"jsbsim: {exc}")
    vehicle = _vehicle_from_text(fl.files["vehicle.toml"], tmp_path)
    cols = ("q_rad_s", "az_m_s2", "V_m_s", "h_m", vehicle.alpha_column)
    frame = fl.telemetry
    ok = np.isfinite(frame[list(cols)].to_numpy(float)).all(axis=1)
    clean = {c: frame[c].to_numpy(float) for c in cols}
    t = frame["t_s"].to_numpy(float)[ok]
    clean["V_m_s"] = calibrated_from_true_m_s(clean["V_m_s"], np.nan_to_num(clean["h_m"]))
    hint = _calibrated_airspeed_hint(_airspeed_scale(t, clean, ok, vehicle), clean, ok)
    assert "calibrated (or indicated) airspeed looks alike" in hint and "high by 1.14" in hint, hint
    if F018.is_file():
        from aerosid.vehicles.sidpac import import_sidpac

        flight = import_sidpac(F018)
        to = flight.telemetry
        to_vehicle = _vehicle_from_text(flight.vehicle_toml, tmp_path)
        ok = np.isfinite(to[list(cols)].to_numpy(float)).all(axis=1)
        clean = {c: to[c].to_numpy(float) for c in cols}
        scale = _airspeed_scale(to["t_s"].to_numpy(float)[ok], clean, ok, to_vehicle)
        assert _calibrated_airspeed_hint(scale, clean, ok) == ""


def test_an_airspeed_the_kinematics_put_far_from_the_true_one_is_reported():
    """A ground speed with a 15 m/s tailwind on a 60 m/s aircraft (V_m_s x1.25) is no unit and no
    calibrated airspeed: the pre-flight has nothing to refuse, and the run reports it
    (airspeed_scale) with what it does to every coefficient; the true airspeed gives nothing."""
    from aerosid.identification.airdata_findings import _airspeed_finding, _airspeed_scale
    try:
        from aerosid.simulation.jsbsim_aircraft import simulate_aircraft
        fl = simulate_aircraft("c182", 0)
    except ImportError as exc:  # jsbsim is an optional extra
        pytest.skip(f"jsbsim: {exc}")
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        vehicle = _vehicle_from_text(fl.files["vehicle.toml"], Path(d))
    cols = ("q_rad_s", "az_m_s2", "V_m_s", "h_m", vehicle.alpha_column)
    frame = fl.telemetry
    ok = np.isfinite(frame[list(cols)].to_numpy(float)).all(axis=1)
    t = frame["t_s"].to_numpy(float)[ok]
    clean = {c: frame[c].to_numpy(float) for c in cols}
    assert _airspeed_finding(_airspeed_scale(t, clean, ok, vehicle), t, vehicle, "seg00") is None
    fast = {**clean, "V_m_s": clean["V_m_s"] * 1.25}
    found = _airspeed_finding(_airspeed_scale(t, fast, ok, vehicle), t, vehicle, "seg00")
    assert found is not None and found.kind == "airspeed_scale" and found.channel == "V_m_s"
    assert "ground speed" in found.detail and "every coefficient 0.6" in found.detail, found.detail


def test_a_pitch_gyro_step_the_vane_does_not_follow_stands_out_of_the_kinematic_mismatch():
    """On exact kinematics plus vane noise, a 1.5 s step of 0.03 rad/s on q (what the filter
    follows as a manoeuvre) stands out of kinematic_mismatch_z over its span, above the finding's
    threshold, and nothing else reaches it; a delayed vane with its delay given is as clean."""
    from aerosid.identification.airdata_findings import KINEMATIC_MISMATCH_Z
    from aerosid.identification.derivatives import zero_phase_low_pass
    from aerosid.identification.vanes import kinematic_alpha_rate, kinematic_mismatch_z

    t, alpha, sig = kinematic_flight(fs_hz=100.0, duration_s=30.0)
    rng = np.random.default_rng(4)
    band = 2.0
    vane = zero_phase_low_pass(alpha + rng.normal(0.0, 0.0015, t.size), 100.0, band)
    step = (t > 14.0) & (t < 15.5)
    for q_shift, delay in ((0.0, 0.0), (0.03, 0.0), (0.0, 0.025)):
        s = {k: zero_phase_low_pass(v, 100.0, band) if k != "V_m_s" else v  # the band path filters all alike
             for k, v in {**sig, "q_rad_s": sig["q_rad_s"] + q_shift * step}.items()}
        a = late(t, vane, delay) if delay else vane
        rate, usable = kinematic_alpha_rate(t, a, **s)
        z = kinematic_mismatch_z(t, a, rate, usable, band, delay_s=delay)
        inside = (t > 14.3) & (t < 15.2)
        outside = (t < 13.0) | (t > 16.5)
        if q_shift:
            assert np.nanmin(z[inside]) > 1.5 * KINEMATIC_MISMATCH_Z
        else:
            assert np.nanmax(z[inside]) < KINEMATIC_MISMATCH_Z / 2
        assert np.nanmax(z[outside & (t > 1.5) & (t < 28.5)]) < KINEMATIC_MISMATCH_Z
