"""The simulator against closed forms, finite differences and chi-square bands."""
import hashlib
import json

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from aerosid.vehicles.atmosphere import FastAtmosphere, density_kg_m3, speed_of_sound_m_s
from aerosid.modelling.effects import CATALOGUE, parse_effect_spec
from aerosid.simulation import load_case, simulate
from aerosid.simulation.dynamics import R_EARTH_M, quat_to_dcm
from aerosid.simulation.sensors import IMU_COLUMNS, RAW_COLUMNS


def test_accelerometer_model_matches_finite_differences_of_the_trajectory(reference_flight):
    """Second differences of the sensor's position, minus effective gravity, rotated
    to body axes, equal the simulated accelerometer (lever arm included)."""
    from aerosid.vehicles.rigid_body import lever_arm_acceleration  # noqa: F401  (what is being checked)

    case = load_case("seed-rlv", duration_s=6.0, sample_rate_hz=1000.0)
    case = case.__class__(**{**case.__dict__, "faults": case.faults.without_faults()})
    flight = simulate(case, seed=0)
    tr = flight.truth
    # rebuild attitude from Euler angles (truth holds them) -> DCM body->NED
    from aerosid.simulation.dynamics import quat_from_euler
    quats = np.array([quat_from_euler(*e) for e in tr[["phi_rad", "theta_rad", "psi_rad"]].to_numpy()])
    C = quat_to_dcm(*quats.T)  # (3,3,N)
    r_off = np.array(case.vehicle.accel_offset_m)
    pos_cg = np.stack([tr["north_m"], tr["east_m"], -tr["h_m"]], axis=1)
    pos_sensor = pos_cg + np.einsum("ijn,j->ni", C, r_off)
    dt = 1e-3
    acc = (pos_sensor[2:] - 2 * pos_sensor[1:-1] + pos_sensor[:-2]) / dt**2
    atm = FastAtmosphere()
    g = np.array([atm(h)[2] for h in tr["h_m"].to_numpy()[1:-1]])
    # NED velocity from central differences of the CG position (for the centrifugal term)
    v_cg = (pos_cg[2:] - pos_cg[:-2]) / (2 * dt)
    g_eff = g - (v_cg[:, 0] ** 2 + v_cg[:, 1] ** 2) / (R_EARTH_M + tr["h_m"].to_numpy()[1:-1])
    specific_ned = acc - np.stack([np.zeros_like(g), np.zeros_like(g), g_eff], axis=1)
    specific_body = np.einsum("jin,nj->ni", C[:, :, 1:-1], specific_ned)
    sensed = tr[["ax_sensor_m_s2", "ay_sensor_m_s2", "az_sensor_m_s2"]].to_numpy()[1:-1]
    # fins are held per sample: skip the samples next to a control change
    err = np.abs(specific_body - sensed)[5:-5]
    assert np.percentile(err, 99) < 2e-3  # m/s^2 against signals of ~1-10 m/s^2


def test_noise_standard_deviations_inside_chi_square_bounds(reference_flight):
    tr = reference_flight.truth
    sigma = np.array([0.8, 1.0, 2.0, *np.deg2rad([4.0, 2.0, 1.0])])
    n = len(tr)
    lo = np.sqrt(stats.chi2.ppf(0.0005, n - 1) / (n - 1))
    hi = np.sqrt(stats.chi2.ppf(0.9995, n - 1) / (n - 1))
    for col, s in zip(IMU_COLUMNS, sigma):
        ratio = tr[f"noise_{col}"].std(ddof=1) / s
        assert lo < ratio < hi, (col, ratio, lo, hi)


def test_dropouts_hit_all_channels_at_once(reference_flight):
    tel, tr = reference_flight.telemetry, reference_flight.truth
    channels = RAW_COLUMNS[1:]
    nan_rows = tel[channels].isna()
    assert nan_rows.any(axis=1).sum() > 0
    assert (nan_rows.any(axis=1) == nan_rows.all(axis=1)).all()
    # missing rows: every time the truth marks as a missing row is absent from telemetry
    missing_t = tr.loc[tr["fault_dropout_missing_row"], "t_s"].to_numpy()
    assert len(missing_t) > 0
    assert not np.isin(np.round(missing_t, 9), np.round(tel["t_s"].to_numpy(), 9)).any()
    assert len(tel) == len(tr) - len(missing_t)
    # the sync gap is a single block of missing rows of the configured length
    sync = tr.loc[tr["fault_sync_gap"], "t_s"]
    assert sync.max() - sync.min() == pytest.approx(2.0 - 0.01, abs=1e-9)


def test_outliers_are_large_spikes_on_single_channels(reference_flight):
    tr = reference_flight.truth
    sigma = dict(zip(IMU_COLUMNS, [0.8, 1.0, 2.0, *np.deg2rad([4.0, 2.0, 1.0])]))
    n_total = 0
    for col in IMU_COLUMNS:
        hit = tr[f"fault_outlier_{col}"].to_numpy()
        n_total += hit.sum()
    assert n_total > 10
    tel = reference_flight.telemetry.set_index(np.round(reference_flight.telemetry["t_s"], 6))
    for col in IMU_COLUMNS:
        t_hit = np.round(tr.loc[tr[f"fault_outlier_{col}"], "t_s"], 6)
        clean = tr.set_index(np.round(tr["t_s"], 6)).loc[t_hit]
        truth_col = {"ax_m_s2": "ax_sensor_m_s2", "ay_m_s2": "ay_sensor_m_s2", "az_m_s2": "az_sensor_m_s2",
                     "p_rad_s": "p_rad_s", "q_rad_s": "q_rad_s", "r_rad_s": "r_rad_s"}[col]
        dev = np.abs(tel.loc[t_hit, col].to_numpy() - clean[truth_col].to_numpy()) / sigma[col]
        assert np.all(dev > 5.0 - 3.0)  # >= 6 sigma spike, minus at most ~3 sigma of opposing noise


def test_same_seed_gives_identical_files(tmp_path):
    case = load_case("seed-rlv", duration_s=20.0)
    digests = []
    for run in ("a", "b"):
        simulate(case, seed=7).write(tmp_path / run)
        digests.append({f: hashlib.sha256((tmp_path / run / f).read_bytes()).hexdigest()
                        for f in ("telemetry.parquet", "truth.parquet", "truth.json")})
    assert digests[0] == digests[1]
    other = simulate(case, seed=8).telemetry
    assert not other.equals(pd.read_parquet(tmp_path / "a" / "telemetry.parquet"))


def test_reference_flight_passes_mach_12_4_with_seed_table_3_preflight(reference_flight):
    info = reference_flight.info
    assert info["mach_min"] < 12.4 < info["mach_max"]
    c = reference_flight.coefficients
    deg = np.pi / 180
    veh = load_case("seed-rlv").vehicle
    assert veh.preflight.CN_alpha * deg == pytest.approx(0.0305, rel=1e-9)
    assert veh.preflight.Cm_alpha_nose * deg == pytest.approx(-0.0578, rel=1e-9)
    # moment transfer nose -> CG with the preflight values gives the seed's -0.0067 /deg
    assert (veh.preflight.Cm_alpha_nose + veh.preflight.CN_alpha * veh.xcg_over_d) * deg == pytest.approx(-0.0067, abs=5e-5)
    # flight deviations: lower control effectiveness than preflight, as the seed found
    pre_cm_delta = veh.preflight.Cm_delta_p_nose + veh.preflight.CN_delta_p * veh.xcg_over_d
    assert 0 < c["Cm_delta_p"] < pre_cm_delta
    assert set(c) >= {"CN_alpha", "CN_delta_p", "Cm_alpha", "Cm_delta_p", "Cm_0", "CN_0", "Cl_0",
                      "Cl_alpha_r", "Cl_cos4phi", "Cl_delta_r"}


def test_truth_coefficients_reproduce_the_simulated_moment(reference_flight):
    """Cm per sample equals the linear truth model in alpha and delta_p/2 (no hidden effect)."""
    tr, c = reference_flight.truth, reference_flight.coefficients
    near = (tr["mach"] - 12.4).abs() < 0.5
    model = c["Cm_0"] + c["Cm_alpha"] * tr["alpha_rad"] + c["Cm_delta_p"] * tr["delta_p_rad"] / 2
    assert np.max(np.abs(model - tr["Cm"])[near]) < 2e-5  # tan/atan differences only


def test_hidden_effect_enters_truth_and_coefficients():
    case = load_case("seed-rlv", duration_s=30.0)
    base = simulate(case, seed=1)
    eff = simulate(case, (parse_effect_spec("pitch_damping"),), seed=1)
    assert eff.coefficients["Cm_q"] == CATALOGUE["pitch_damping"].value
    assert "Cm_q" not in base.coefficients
    assert not np.allclose(eff.truth["Cm"], base.truth["Cm"])
    doc = json.loads(json.dumps(eff.truth_document()))
    assert doc["effects"] == [{"name": "pitch_damping", "scale": 1.0}]


def test_fast_atmosphere_matches_ambiance():
    atm = FastAtmosphere()
    h = np.linspace(0, 80000, 997)
    rho = np.array([atm(x)[0] for x in h])
    a = np.array([atm(x)[1] for x in h])
    np.testing.assert_allclose(rho, density_kg_m3(h), rtol=1e-5)
    np.testing.assert_allclose(a, speed_of_sound_m_s(h), rtol=1e-6)
    assert density_kg_m3(20000.0) == pytest.approx(0.08891, rel=1e-3)  # the US-1976 table value


def test_unknown_effect_is_a_clear_error():
    with pytest.raises(KeyError, match="unknown effect 'pitch_dampin'"):
        parse_effect_spec("pitch_dampin")


def test_sensor_noise_scaling_multiplies_every_sigma():
    """SensorSpec.scaled (the modelling-loop bench's --noise-scale): every field, tuples element-wise,
    so a sensor added later cannot be left at full noise."""
    from dataclasses import astuple, fields

    s = load_case("seed-rlv").sensors
    half = s.scaled(0.5)
    for f in fields(s):
        assert np.allclose(np.asarray(getattr(half, f.name)), 0.5 * np.asarray(getattr(s, f.name))), f.name
        assert type(getattr(half, f.name)) is type(getattr(s, f.name))
    assert s.scaled(1.0) == s
    assert not any(np.any(np.asarray(v)) for v in astuple(s.scaled(0.0)))


def test_the_ins_attitude_has_its_noise_the_dropouts_and_leaves_the_other_channels_alone(reference_flight):
    """phi_rad, theta_rad: the true attitude + the configured white noise (chi-square band), NaN on
    exactly the rows where every other channel is NaN; without attitude noise every other column
    is bit-identical (the attitude draws from its own child of the seed)."""
    from dataclasses import replace

    from aerosid.simulation.sensors import ATTITUDE_COLUMNS

    tel, case = reference_flight.telemetry, load_case("seed-rlv")
    truth = reference_flight.truth.set_index(np.round(reference_flight.truth["t_s"], 9))
    nan_rows = tel[RAW_COLUMNS[1:]].isna().all(axis=1).to_numpy()
    errors = []
    for col in ATTITUDE_COLUMNS:
        assert (tel[col].isna().to_numpy() == nan_rows).all()
        errors.append(tel[col].to_numpy() - truth.loc[np.round(tel["t_s"], 9), col].to_numpy())
    e = np.concatenate(errors)
    e = e[np.isfinite(e)]
    n = e.size
    lo = np.sqrt(stats.chi2.ppf(0.0005, n - 1) / (n - 1))
    hi = np.sqrt(stats.chi2.ppf(0.9995, n - 1) / (n - 1))
    assert lo < e.std(ddof=1) / case.sensors.attitude_noise_rad < hi
    assert case.sensors.attitude_noise_rad == pytest.approx(np.deg2rad(0.1))
    quiet = replace(case, sensors=replace(case.sensors, attitude_noise_rad=0.0))
    other = simulate(quiet, seed=0).telemetry
    assert other[RAW_COLUMNS].equals(tel[RAW_COLUMNS])
    assert not other[ATTITUDE_COLUMNS].equals(tel[ATTITUDE_COLUMNS])
