"""The JSBSim-flown c172x validation flight (aerosid.simulation.jsbsim_flight)."""
from __future__ import annotations

import json
import math
import sys
import tomllib

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("jsbsim")

from aerosid.vehicles.rigid_body import body_rate_derivatives, inertia_constants, lever_arm_acceleration  # noqa: E402
from aerosid.simulation.jsbsim_flight import (  # noqa: E402
    TELEMETRY_COLUMNS,
    JSBSimUnavailable,
    load_jsbsim_config,
    simulate_jsbsim,
)
from aerosid.simulation.jsbsim_truth import linear_prediction  # noqa: E402
from aerosid.vehicles.vehicle import DATA_DIR  # noqa: E402

DEG = math.pi / 180.0


@pytest.fixture(scope="module")
def flight():
    return simulate_jsbsim("c172x", "3211", seed=0)


@pytest.fixture(scope="module")
def config():
    return load_jsbsim_config("c172x")


def _at_rows(flight, column):
    """Truth `column` at the times of the telemetry rows."""
    idx = np.rint(flight.telemetry["t_s"].to_numpy() * flight.info["sample_rate_hz"]).astype(int)
    return flight.truth[column].to_numpy()[idx]


def test_columns_units_and_trim(flight, config):
    tel, truth = flight.telemetry, flight.truth
    assert list(tel.columns) == TELEMETRY_COLUMNS
    assert flight.info["sample_rate_hz"] == 100.0
    assert np.allclose(np.diff(truth["t_s"]), 0.01)
    trim = config[0]["trim"]
    steady = tel[tel["t_s"] < 2.5].dropna()  # before the first 3-2-1-1
    assert len(steady) > 200
    th = truth["theta_rad"].iloc[0]
    g = truth["g_m_s2"].iloc[0]
    # steady (gliding) flight: the accelerometers read -g cos(theta) (the 0.016 m/s^2 centrifugal
    # relief of the rotating Earth at 47 deg latitude is inside the tolerance), rates ~ 0
    assert steady["az_m_s2"].mean() == pytest.approx(-g * math.cos(th), abs=0.04)
    assert steady["ax_m_s2"].mean() == pytest.approx(g * math.sin(th), abs=0.02)
    assert abs(steady["ay_m_s2"].mean()) < 0.02
    assert np.abs(steady[["p_rad_s", "q_rad_s", "r_rad_s"]].mean()).max() < 0.005  # rad/s, not deg/s
    assert abs(steady["V_m_s"].mean() - trim["V_m_s"]) < 1.0
    # a steady glide at gamma: h falls at V sin(gamma)
    sink = trim["V_m_s"] * math.sin(math.radians(trim["gamma_deg"]))
    assert abs(steady["h_m"].mean() - (trim["h_m"] + sink * steady["t_s"].mean())) < 2.0
    assert 0.0 < steady["alpha_vane_rad"].mean() < 0.1  # radians
    assert 0.0 < steady["d1_rad"].mean() < 0.2
    # the whole flight stays in the linear, unstalled, attached range
    assert -2.0 < flight.info["alpha_min_deg"] and flight.info["alpha_max_deg"] < 6.0
    assert abs(truth["phi_rad"]).max() < 20 * DEG
    assert flight.info["trim"]["V_m_s"] == pytest.approx(50.0, abs=0.01)


def test_specific_force_is_exact(flight, config):
    """CG specific force = all non-gravitational forces / mass; the sensor adds the lever arm."""
    tr = flight.truth
    offset = tomllib.loads((DATA_DIR / "c172x" / "vehicle.toml").read_text())["sensors"]["accel_offset_m"]
    lever = lever_arm_acceleration(tr["p_rad_s"], tr["q_rad_s"], tr["r_rad_s"], tr["p_dot_rad_s2"],
                                   tr["q_dot_rad_s2"], tr["r_dot_rad_s2"], offset)
    for axis, lv in zip("xyz", lever):
        assert np.allclose(tr[f"a{axis}_sensor_m_s2"], tr[f"a{axis}_cg_m_s2"] + lv, atol=1e-12)
    # aerodynamic + propulsive force coefficients rebuild the CG specific force
    qS = tr["qbar_pa"] * flight.info["reference"]["S_m2"]
    ax = (-tr["CA"] + tr["CX_prop"]) * qS / tr["mass_kg"]
    az = (-tr["CN"] + tr["CZ_prop"]) * qS / tr["mass_kg"]
    assert np.allclose(ax, tr["ax_cg_m_s2"], atol=1e-9)
    assert np.allclose(az, tr["az_cg_m_s2"], atol=1e-9)


def test_same_seed_same_telemetry(flight):
    again = simulate_jsbsim("c172x", "3211", seed=0)
    pd.testing.assert_frame_equal(again.telemetry, flight.telemetry)
    pd.testing.assert_frame_equal(again.truth, flight.truth)
    other = simulate_jsbsim("c172x", "3211", seed=1, faults=False)
    assert len(other.telemetry) == flight.info["n_samples"]
    assert not other.telemetry.isna().any().any()
    assert not np.allclose(other.truth["noise_q_rad_s"], flight.truth["noise_q_rad_s"])
    pd.testing.assert_frame_equal(other.truth[["t_s", "q_rad_s", "Cm"]], flight.truth[["t_s", "q_rad_s", "Cm"]])


def test_surface_positions_follow_the_3211_through_the_hysteresis(flight, config):
    tr = flight.truth.set_index(np.rint(flight.truth["t_s"] * 100).astype(int))
    m = config[0]["manoeuvres"]["3211"]
    unit = m["elevator_unit_s"]
    de0 = tr["delta_p_rad"].iloc[0]
    for start, sign in zip(m["elevator_starts_s"], m["elevator_signs"]):
        t = start
        for units, amp in zip(m["elevator_units"], m["elevator_amplitudes_norm"]):
            t += units * unit
            k = int(round((t - 0.01) * 100))  # end of the hold
            d = tr.loc[k, "delta_p_rad"] - de0
            assert np.sign(d) == np.sign(sign * amp)
            assert 0.5 * DEG < abs(d) < 5 * DEG
            # the position lags the commanded deflection by half the 0.05 rad hysteresis width
            lag = tr.loc[k, "elevator_control_rad"] + 0.002 - tr.loc[k, "delta_p_rad"]
            assert lag == pytest.approx(math.copysign(0.025, sign * amp), abs=2e-4)
    # quiet before the manoeuvre, and back at the trim position after the hysteresis take-up
    assert np.ptp(tr.loc[: int(m["elevator_starts_s"][0] * 100) - 1, "delta_p_rad"]) < 1e-9
    # (the take-up starts when the last ramp of the command has ended: elevator_rise_s)
    t_after = (m["elevator_starts_s"][1] + sum(m["elevator_units"]) * unit + m.get("elevator_rise_s", 0.0)
               + m["hysteresis_takeup_s"] + 0.5)
    after = tr.loc[int(round(t_after * 100)), "delta_p_rad"]
    assert after == pytest.approx(de0, abs=1e-4)
    a0 = int(m["aileron_start_s"] * 100)
    assert tr.loc[a0 + 50, "delta_r_rad"] > tr.loc[0, "delta_r_rad"] + 1 * DEG
    assert tr.loc[a0 + 150, "delta_r_rad"] < tr.loc[0, "delta_r_rad"] - 1 * DEG
    # back at trim after the take-up (to 0.03 deg: the two ailerons' hysteresis is taken up by one
    # shared command with different gains)
    assert tr.loc[a0 + 400, "delta_r_rad"] == pytest.approx(tr.loc[0, "delta_r_rad"], abs=5e-4)
    # the recorded d1..d4 are the positions (+ noise), the mixing row 0 gives delta_r
    d2, d3 = _at_rows(flight, "d2_rad"), _at_rows(flight, "d3_rad")
    ok = ~flight.telemetry["d2_rad"].isna().to_numpy()
    resid = (flight.telemetry["d2_rad"].to_numpy() - d2)[ok]
    assert abs(resid.std() - 0.05 * DEG) < 0.1 * 0.05 * DEG
    assert np.allclose(0.5 * (d2 - d3), _at_rows(flight, "delta_r_rad"))


def test_truth_moment_closed_form_at_every_step(flight):
    """JSBSim's aerodynamic coefficients about the CG equal c172x's XML model evaluated
    independently at every sample; about the AERORP they are exactly JSBSim's linear
    Cm model; about the CG the transferred linear truth holds in the linear range."""
    tr, c = flight.truth, flight.coefficients
    for k in ("CA", "CY", "CN", "Cl", "Cm", "Cn"):
        assert np.max(np.abs(tr[k] - tr[f"{k}_xml"])) < 1e-9, k
    # back to the AERORP with JSBSim's own forces: Cm_rp = Cm - (dz cx - dx cz)/cbar
    ref = flight.info["reference"]
    dx, _, dz = ref["aerorp_from_cg_body_m"]
    cm_rp = tr["Cm"] - (dz * (-tr["CA"]) - dx * (-tr["CN"])) / ref["chord_m"]
    closed = 0.1 - 1.8 * tr["alpha_rad"] - 12.4 * tr["q_hat"] - 1.28 * tr["delta_p_rad"] - 5.2 * tr["alpha_dot_hat"]
    assert np.max(np.abs(cm_rp - closed)) < 2e-5  # the CG moves 0.01 in as fuel burns
    # the linear truth about the CG in the longitudinal part of the flight
    lon = (tr["t_s"] < flight.info["manoeuvre_windows_s"]["aileron_doublet"][0]).to_numpy()
    res = (tr["Cm"] - linear_prediction(tr, c, "Cm")).to_numpy()[lon]
    # (the 3-2-1-1 at command 0.2 swings alpha -0.7..2.9 deg: the CG moment's curvature
    # leaves up to ~3e-3 on the linear truth; simulation.toml, docs/jsbsim.md)
    assert np.max(np.abs(res)) < 4e-3
    assert np.max(np.abs(res)) < 0.05 * np.ptp(tr["Cm"].to_numpy()[lon])
    res_n = (tr["CN"] - linear_prediction(tr, c, "CN")).to_numpy()[lon]
    assert np.max(np.abs(res_n)) < 0.01 * np.ptp(tr["CN"].to_numpy()[lon])
    for k in ("Cl", "Cn"):
        res_l = tr[k] - linear_prediction(tr, c, k)
        assert np.max(np.abs(res_l)) < 0.02 * np.ptp(tr[k]), k


def test_reference_point_transfer(flight):
    c, rp = flight.coefficients, flight.info["coefficients_aerorp"]
    # c172x's table values about the AERORP
    assert rp["Cm_alpha"] == pytest.approx(-1.8, abs=1e-6)
    assert rp["Cm_q"] == pytest.approx(-12.4, abs=1e-6)
    assert rp["Cm_delta_p"] == pytest.approx(-1.28, abs=1e-6)
    assert rp["Cm_alpha_dot"] == pytest.approx(-5.2, abs=1e-6)
    assert rp["Cl_delta_r"] == pytest.approx(0.23, abs=1e-6)
    assert rp["Cn_delta_y"] == pytest.approx(-0.043, abs=1e-6)
    # about the CG: Cm_x,cg = Cm_x,rp + (dx CN_x - dz CA_x)/cbar (dx, dz: AERORP from the CG, body axes)
    ref = flight.info["reference"]
    dx, _, dz = ref["aerorp_from_cg_body_m"]
    assert dz < -0.5 and abs(dx) < 0.05  # the AERORP sits 0.59 m above the CG
    for x in ("alpha", "delta_p"):
        expect = rp[f"Cm_{x}"] + (dx * c[f"CN_{x}"] - dz * c[f"CA_{x}"]) / ref["chord_m"]
        assert c[f"Cm_{x}"] == pytest.approx(expect, rel=1e-4)
    assert c["Cm_q_plus_alpha_dot"] == pytest.approx(c["Cm_q"] + c["Cm_alpha_dot"])
    # Cl_cg = Cl_rp - dz CY / b
    assert c["Cl_beta"] == pytest.approx(rp["Cl_beta"] - dz * c["CY_beta"] / ref["span_m"], rel=1e-4)
    assert c["Cn_beta"] == pytest.approx(rp["Cn_beta"] + dx * c["CY_beta"] / ref["span_m"], rel=1e-4)
    for name in ("CN_0", "CN_alpha", "CN_delta_p", "Cm_0", "Cm_alpha", "Cm_delta_p", "Cm_q", "Cm_alpha_dot",
                 "Cm_q_plus_alpha_dot", "CY_0", "CY_beta", "CY_delta_y", "Cl_0", "Cl_beta", "Cl_p", "Cl_r",
                 "Cl_delta_r", "Cl_delta_y", "Cn_0", "Cn_beta", "Cn_p", "Cn_r", "Cn_delta_r", "Cn_delta_y"):
        assert math.isfinite(c[name]), name


def test_truth_fit_agrees_with_the_transferred_table(flight):
    check = flight.info["truth_check"]
    cm = check["Cm"]["rel_diff"]
    # command 0.2 (alpha -0.7..2.9 deg): the curvature of Cm about the CG puts a linear
    # fit of the noise-free truth ~3 % off the local slope at trim (1 % at command 0.12)
    assert abs(cm["Cm_alpha"]) < 0.04
    assert abs(cm["Cm_delta_p"]) < 0.02
    assert abs(check["CN"]["rel_diff"]["CN_alpha"]) < 0.02
    assert abs(check["CN"]["rel_diff"]["CN_delta_p"]) < 0.03
    assert abs(check["Cm_whole_flight_abs_beta"]["rel_diff"]["Cm_alpha"]) < 0.04
    for coef in ("Cl", "Cn"):
        for name, rel in check[coef]["rel_diff"].items():
            assert abs(rel) < 0.02, name


def test_rigid_body_convention_matches_jsbsim(flight):
    """aerosid's rotational equations with vehicle.toml's inertias (Ixz sign!) give JSBSim's
    angular accelerations from the aerodynamic + propulsive moments."""
    veh = tomllib.loads((DATA_DIR / "c172x" / "vehicle.toml").read_text())
    m, ref = veh["mass"], veh["reference"]
    c = inertia_constants(m["Ixx_kg_m2"], m["Iyy_kg_m2"], m["Izz_kg_m2"], m["Ixz_kg_m2"])
    tr = flight.truth
    qS = tr["qbar_pa"] * ref["S_m2"]
    L = (tr["Cl"] + tr["Cl_prop"]) * qS * ref["span_m"]
    M = (tr["Cm"] + tr["Cm_prop"]) * qS * ref["chord_m"]
    N = (tr["Cn"] + tr["Cn_prop"]) * qS * ref["span_m"]
    pd_, qd_, rd_ = body_rate_derivatives(tr["p_rad_s"], tr["q_rad_s"], tr["r_rad_s"], L / c.Ixx, M / c.Iyy,
                                          N / c.Izz, c)
    for mine, theirs in ((pd_, "p_dot_rad_s2"), (qd_, "q_dot_rad_s2"), (rd_, "r_dot_rad_s2")):
        assert np.max(np.abs(mine - tr[theirs])) < 2e-3 * np.max(np.abs(tr[theirs])) + 1e-4, theirs
    # vehicle.toml holds JSBSim's numbers at the trim
    info = flight.info
    for key in ("mass_kg", "Ixx_kg_m2", "Iyy_kg_m2", "Izz_kg_m2", "Ixz_kg_m2"):
        assert m[key] == pytest.approx(info["mass"][key], rel=1e-3), key
    for key, mine in (("S_m2", "S_m2"), ("chord_m", "chord_m"), ("span_m", "span_m"), ("x_cg_m", "x_cg_m")):
        assert ref[key] == pytest.approx(info["reference"][mine], rel=1e-4), key
    assert veh["aero"]["mach_reference"] == pytest.approx(info["trim"]["mach"], abs=5e-4)


def test_vanes_have_the_configured_bias(flight, config):
    air = config[0]["air_data"]
    tel = flight.telemetry
    ok = ~tel["alpha_vane_rad"].isna().to_numpy()
    da = (tel["alpha_vane_rad"].to_numpy() - _at_rows(flight, "alpha_rad"))[ok]
    db = (tel["beta_vane_rad"].to_numpy() - _at_rows(flight, "beta_rad"))[ok]
    assert np.mean(da) == pytest.approx(air["alpha_bias_deg"] * DEG, abs=0.01 * DEG)
    assert np.mean(db) == pytest.approx(air["beta_bias_deg"] * DEG, abs=0.01 * DEG)
    assert np.std(da) == pytest.approx(0.15 * DEG, rel=0.05)


def test_faults_and_vane_nans(flight):
    tel, tr = flight.telemetry, flight.truth
    assert flight.info["n_dropout"] > 0 and flight.info["n_outliers"] > 0
    assert len(tel) == flight.info["n_samples"] - int(tr["fault_dropout_missing_row"].sum())
    nan_rows = tel["ax_m_s2"].isna()
    assert nan_rows.any()
    assert (tel.loc[nan_rows, TELEMETRY_COLUMNS[1:]].isna().all(axis=1)).all()
    assert not tel.loc[~nan_rows, TELEMETRY_COLUMNS[1:]].isna().any().any()
    assert tel["t_s"].is_monotonic_increasing


def test_summary_and_write(flight, tmp_path):
    text = flight.summary()
    assert "c172x" in text and "4501 samples" in text
    paths = flight.write(tmp_path)
    doc = json.loads(paths["truth_json"].read_text())
    assert doc["moment_reference"] == "cg"
    assert doc["coefficients"]["Cm_alpha"] == pytest.approx(flight.coefficients["Cm_alpha"])
    assert pd.read_parquet(paths["telemetry"]).columns.tolist() == TELEMETRY_COLUMNS


def test_bad_names_and_missing_jsbsim(monkeypatch):
    with pytest.raises(ValueError, match="c172x"):  # the error lists the aircraft jsbsim ships
        simulate_jsbsim("no-such-aircraft")
    with pytest.raises(ValueError, match="3211"):
        simulate_jsbsim("c172x", "doublet")
    monkeypatch.setitem(sys.modules, "jsbsim", None)
    with pytest.raises(JSBSimUnavailable, match=r'pip install "aerosid\[jsbsim\]"'):
        simulate_jsbsim()
    assert issubclass(JSBSimUnavailable, ImportError)


def test_turbulence_levels_seeds_and_rotational_gusts():
    """start_turbulence: calm air stays calm; a level turns JSBSim's gusts on (the rates relative to
    the air part from the gyros' rates), moderate is stronger than light, the seed sets the sequence,
    and an unknown level is refused by name."""
    from aerosid.simulation.jsbsim_flight import _import_jsbsim, _trimmed_fdm
    from aerosid.simulation.jsbsim_turbulence import start_turbulence

    jsbsim = _import_jsbsim()
    cfg, _ = load_jsbsim_config("c172x")

    def fly(level: str, seed: int) -> np.ndarray:
        fdm = _trimmed_fdm(jsbsim, cfg)
        start_turbulence(fdm, level, seed)
        out = []
        for _ in range(400):
            fdm.run()
            out.append((fdm["atmosphere/total-wind-down-fps"], fdm["velocities/p-rad_sec"] - fdm["velocities/p-aero-rad_sec"]))
        return np.array(out)

    calm = fly("none", 0)
    np.testing.assert_allclose(calm, 0.0, atol=1e-12)
    light, again, other, moderate = fly("light", 0), fly("light", 0), fly("light", 1), fly("moderate", 0)
    assert light[:, 0].std() > 0.1 and light[:, 1].std() > 1e-3  # ft/s of vertical gust, rad/s of rolling gust
    np.testing.assert_array_equal(light, again)
    assert not np.allclose(light, other)
    assert moderate[:, 0].std() > 1.5 * light[:, 0].std()
    with pytest.raises(ValueError, match="turbulence level 'severe'"):
        start_turbulence(_trimmed_fdm(jsbsim, cfg), "severe", 0)
    with pytest.raises(ValueError, match="turbulence level"):
        simulate_jsbsim("c172x", "3211", seed=0, turbulence="gusty")


def test_turbulence_is_for_jsbsim_flights(tmp_path):
    from click.testing import CliRunner

    from aerosid.cli.simulate import simulate

    res = CliRunner().invoke(simulate, ["--case", "seed-rlv", "--turbulence", "light", "--out", str(tmp_path)])
    assert res.exit_code != 0 and "--turbulence applies to --jsbsim flights" in res.output
