"""The conventional-aircraft vehicle class: chord and span reference lengths, control
mixing from the vehicle file, alpha/beta from air-data vanes (issue: second vehicle
class).  Independent of JSBSim: a small aircraft file written here."""
from __future__ import annotations

import numpy as np

from aerosid.identification.band import low_pass_runs
import pandas as pd
import pytest

from aerosid.identification.flight_coefficients import flight_coefficients
from aerosid.identification.flight_data import build_flight_data, load_database
from aerosid.modelling.models import default_models, signals_from_flight_data, vehicle_signals
from aerosid.preprocess import preprocess
from aerosid.vehicles.vehicle import VehicleError, load_vehicle

AIRCRAFT = """
name = "test-aircraft"
class = "aircraft"
description = "a light aircraft for tests"
[mass]
mass_kg = 1000.0
Ixx_kg_m2 = 1300.0
Iyy_kg_m2 = 1800.0
Izz_kg_m2 = 2700.0
Ixz_kg_m2 = 0.0
[reference]
S_m2 = 16.2
chord_m = 1.5
span_m = 11.0
x_cg_m = 1.0
[sensors]
accel_offset_m = [0.3, 0.0, -0.1]
[air_data]
source = "vanes"
alpha_bias_rad = 0.01
beta_bias_rad = -0.005
noise_rad = 0.0026
[controls]
surfaces = ["elevator", "left aileron", "right aileron", "rudder"]
mixing = [[0.0, 0.5, -0.5, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
surface_limit_rad = 0.5
[aero]
mach_reference = 0.15
[models]
Cm = ["Cm_0 = 1", "Cm_alpha = alpha", "Cm_delta_p = delta_p", "pitch_damping"]
Cl = ["Cl_0 = 1", "Cl_beta = beta", "Cl_p = p_hat", "Cl_delta_r = delta_r"]
"""


@pytest.fixture()
def aircraft(tmp_path):
    path = tmp_path / "vehicle.toml"
    path.write_text(AIRCRAFT)
    return load_vehicle(path)


def test_aircraft_file_loads_with_its_lengths_mixing_and_models(aircraft):
    assert aircraft.vehicle_class == "aircraft" and aircraft.air_data_source == "vanes"
    assert aircraft.length_pitch_m == 1.5 and aircraft.length_lateral_m == 11.0
    assert aircraft.preflight is None and load_database(aircraft) is None
    # mixing is data: elevator -> delta_p, (left - right)/2 -> delta_r, rudder -> delta_y
    dr, dp, dy = aircraft.mix(0.1, 0.04, -0.04, -0.02)
    assert (dr, dp, dy) == pytest.approx((0.04, 0.1, -0.02))
    models = default_models(aircraft)
    assert models["Cm"].names == ("Cm_0", "Cm_alpha", "Cm_delta_p", "Cm_q")
    assert "Cl_p" in models["Cl"].names and set(models) == {"Cm", "Cl"}
    assert "chord 1.5 m" in aircraft.summary()


def test_a_finned_vehicle_keeps_one_reference_length():
    rlv = load_vehicle("seed-rlv")
    assert rlv.length_pitch_m == rlv.length_lateral_m == rlv.d_m
    assert default_models(rlv)["Cm"].names == ("Cm_0", "Cm_alpha", "Cm_delta_p")


@pytest.mark.parametrize("edit, key", [
    ('source = "vanes"', "air_data.source"),
    ("chord_m = 1.5", "reference.d_m"),
    ('Cm = ["Cm_0 = 1"', "models"),
])
def test_bad_aircraft_file_names_the_key(tmp_path, edit, key):
    text = {"air_data.source": AIRCRAFT.replace(edit, 'source = "pitot"'),
            "reference.d_m": AIRCRAFT.replace(edit, ""),
            "models": AIRCRAFT.replace(edit, 'Xm = ["Cm_0 = 1"')}[key]
    path = tmp_path / "vehicle.toml"
    path.write_text(text)
    with pytest.raises(VehicleError) as exc:
        load_vehicle(path)
    assert str(path) in str(exc.value) and key in str(exc.value)


def test_moment_coefficients_use_chord_for_pitch_and_span_for_roll_and_yaw(aircraft):
    n = 5
    V, h = np.full(n, 50.0), np.full(n, 1500.0)
    ang = np.column_stack([np.full(n, 0.3), np.full(n, -0.2), np.full(n, 0.1)])  # L, M, N / I [rad/s^2]
    fc = flight_coefficients(aircraft, V, h, np.zeros((n, 3)), ang)
    qs = fc.air.qbar_pa * aircraft.S_m2
    np.testing.assert_allclose(fc.Cm, aircraft.Iyy_kg_m2 * -0.2 / (qs * 1.5), rtol=1e-12)
    np.testing.assert_allclose(fc.Cl, aircraft.Ixx_kg_m2 * 0.3 / (qs * 11.0), rtol=1e-12)
    np.testing.assert_allclose(fc.Cn, aircraft.Izz_kg_m2 * 0.1 / (qs * 11.0), rtol=1e-12)


def test_rate_signals_use_the_axis_reference_lengths(aircraft):
    fd = pd.DataFrame({"t_s": [0.0], "V_m_s": [50.0], "alpha_rad": [0.05], "beta_rad": [0.0], "alpha_r_rad": [0.05],
                       "phi_r_rad": [0.0], "mach": [0.15], "qbar_pa": [1500.0], "delta_p_rad": [0.0],
                       "delta_y_rad": [0.0], "delta_r_rad": [0.0], "p_rad_s": [0.2], "q_rad_s": [0.1],
                       "r_rad_s": [-0.1]})
    s = vehicle_signals(fd, aircraft)
    assert s["q_hat"][0] == pytest.approx(0.1 * 1.5 / 100.0)
    assert s["p_hat"][0] == pytest.approx(0.2 * 11.0 / 100.0)
    assert s["r_hat"][0] == pytest.approx(-0.1 * 11.0 / 100.0)
    # the finned default (one length) is unchanged
    assert signals_from_flight_data(fd, 1.0)["p_hat"][0] == pytest.approx(0.2 / 100.0)


def _raw(n=400, with_vanes=True, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    alpha = 0.05 + 0.02 * np.sin(2 * np.pi * 0.5 * t)
    beta = 0.01 * np.sin(2 * np.pi * 0.3 * t)
    raw = pd.DataFrame({"t_s": t, "ax_m_s2": 0.1 * rng.standard_normal(n), "ay_m_s2": 0.1 * rng.standard_normal(n),
                        "az_m_s2": -9.8 + 0.1 * rng.standard_normal(n), "p_rad_s": 0.01 * rng.standard_normal(n),
                        "q_rad_s": 0.01 * rng.standard_normal(n), "r_rad_s": 0.01 * rng.standard_normal(n),
                        "d1_rad": -0.02 + 1e-4 * rng.standard_normal(n), "d2_rad": 0.01 + 1e-4 * rng.standard_normal(n),
                        "d3_rad": -0.01 + 1e-4 * rng.standard_normal(n), "d4_rad": 1e-4 * rng.standard_normal(n),
                        "V_m_s": 50.0 + 0.1 * rng.standard_normal(n), "h_m": 1500.0 + rng.standard_normal(n)})
    if with_vanes:
        raw["alpha_vane_rad"] = alpha + 0.01
        raw["beta_vane_rad"] = beta - 0.005
    return raw, alpha, beta


def test_preprocess_carries_the_vane_channels_and_cleans_them():
    raw, alpha, _ = _raw()
    raw.loc[100, "alpha_vane_rad"] = 0.9  # a spike
    raw.loc[200:204, "alpha_vane_rad"] = np.nan  # a short dropout of the vane only
    res = preprocess(raw)
    f = res.frame
    assert "alpha_vane_rad_clean" in f and "flags_beta_vane_rad" in f
    assert res.ignored_columns == ()
    assert f.loc[100, "flags_alpha_vane_rad"] != 0 and abs(f.loc[100, "alpha_vane_rad_clean"] - 0.9) > 0.5
    assert np.isfinite(f.loc[200:204, "alpha_vane_rad_clean"]).all()
    # vane flags stay out of the contract channels' OR (the vane spike is no outlier of the IMU row)
    from aerosid.preprocess.flags import QualityFlag

    assert f.loc[100, "flags_alpha_vane_rad"] & int(QualityFlag.OUTLIER)
    assert not f.loc[100, "flags"] & int(QualityFlag.OUTLIER)


def _smoothed_like(pre: pd.DataFrame) -> pd.DataFrame:
    n = len(pre)
    cols = {"t_s": pre["t_s"].to_numpy(), "segment": "s000"}
    for c in ("X1_m_s2", "Y1_m_s2", "L1_rad_s2", "M1_rad_s2", "N1_rad_s2", "p_rad_s", "q_rad_s", "r_rad_s"):
        cols[c] = np.zeros(n)
    cols["Z1_m_s2"] = np.full(n, -9.8)
    for c in ("X1_m_s2", "Y1_m_s2", "Z1_m_s2", "L1_rad_s2", "M1_rad_s2", "N1_rad_s2"):
        cols[f"sigma_{c}"] = np.full(n, 0.01)
    return pd.DataFrame(cols)


def test_flight_data_reads_alpha_beta_from_the_vanes_minus_their_bias(aircraft):
    raw, alpha, beta = _raw()
    pre = preprocess(raw).frame
    # the smoother's states as the seed has them: the vanes minus their bias, as read
    fd = build_flight_data(_smoothed_like(pre), pre, aircraft, load_database(aircraft), "f1", signals="smoother")
    np.testing.assert_allclose(fd["alpha_rad"], alpha, atol=1e-12)
    np.testing.assert_allclose(fd["beta_rad"], beta, atol=1e-12)
    ta, tb = np.tan(alpha), np.tan(beta)
    np.testing.assert_allclose(fd["alpha_r_rad"], np.arctan(np.hypot(ta, tb)), atol=1e-12)
    assert fd["delta_p_rad"].mean() == pytest.approx(-0.02, abs=1e-4)
    assert fd["delta_r_rad"].mean() == pytest.approx(0.01, abs=1e-4)
    # the common band (default): the same, through the band's low-pass like every signal
    fd = build_flight_data(_smoothed_like(pre), pre, aircraft, load_database(aircraft), "f1")
    band = float(fd["band_hz"].iloc[0])
    expect = low_pass_runs(alpha, 100.0, band, [slice(0, len(alpha))])
    rows = np.rint(fd["t_s"].to_numpy() / 0.01).astype(int)  # the band's edges are left out
    assert 0 < len(fd) < len(alpha) and rows[0] > 0
    np.testing.assert_allclose(fd["alpha_rad"], expect[rows], atol=1e-12)
    assert fd["delta_p_rad"].mean() == pytest.approx(-0.02, abs=1e-4)


def test_missing_vane_column_is_a_clear_error(aircraft):
    raw, _, _ = _raw(with_vanes=False)
    pre = preprocess(raw).frame
    with pytest.raises(ValueError, match="alpha_vane_rad_clean"):
        build_flight_data(_smoothed_like(pre), pre, aircraft, None, "f1")


def test_a_bad_term_in_the_vehicle_models_table_fails_at_load(tmp_path):
    path = tmp_path / "vehicle.toml"
    path.write_text(AIRCRAFT.replace('"Cm_alpha = alpha"', '"Cm_alpha = __import__(1)"'))
    with pytest.raises(VehicleError) as exc:
        load_vehicle(path)
    assert "models.Cm" in str(exc.value) and str(path) in str(exc.value)


def test_aircraft_diagnosis_leaves_out_cruciform_effects_and_uses_its_own_mach_reference(aircraft):
    from aerosid.diagnosis import default_candidates

    cands = {c.name: c for c in default_candidates(aircraft.mach_reference, aircraft.vehicle_class)}
    assert "roll_orientation" not in cands and "fin_misalignment" not in cands
    assert cands["mach_cm_alpha"].term == "alpha*(mach - 0.15)"
    finned = {c.name for c in default_candidates()}
    assert {"roll_orientation", "fin_misalignment"} <= finned
