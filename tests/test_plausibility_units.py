"""The unit check (aerosid/plausibility/units.py): no false alarm on the shipped flights
(simulated seed-rlv, JSBSim's c172x, NASA's real Twin Otter data), and each unit mistake
found, naming the column and the likely unit -- by magnitude against the vehicle's
envelope and, separately, by kinematics alone."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pandas as pd
import pytest

from aerosid.modelling.effects import parse_effect_spec
from aerosid.plausibility import kinematics as K
from aerosid.plausibility.airspeed_scale import airspeed_scale
from aerosid.plausibility.units import check_units, unit_findings
from aerosid.preprocess import TelemetryError
from aerosid.simulation import load_case, simulate
from aerosid.simulation.sensors import with_measured_air_data
from aerosid.vehicles.vehicle import load_vehicle
from tests import twin_otter

DEG = math.pi / 180

# (label, column(s), factor applied to the SI values, likely unit)
MISTAKES = [
    ("q in deg/s", ["q_rad_s"], 1 / DEG, "deg/s"),
    ("p in deg/s", ["p_rad_s"], 1 / DEG, "deg/s"),
    ("h in km", ["h_m"], 1e-3, "km"),
    ("h in ft", ["h_m"], 1 / 0.3048, "ft"),
    ("accelerations in g", ["ax_m_s2", "ay_m_s2", "az_m_s2"], 1 / 9.80665, "g"),
]
SEED_ONLY = [("V in kt", ["V_m_s"], 1 / 0.514444, "kt")]  # the aircraft's 50-70 m/s is plausible in kt too


def with_factor(frame: pd.DataFrame, columns, factor) -> pd.DataFrame:
    out = frame.copy()
    for c in columns:
        out[c] = out[c] * factor
    return out


@pytest.fixture(scope="module")
def flights(reference_flight):
    """The shipped flights with their vehicles: seed-rlv (two seeds, one with a hidden
    effect), JSBSim's c172x (if jsbsim is installed), the two Twin Otter manoeuvres (if
    the data are on this machine)."""
    seed = load_vehicle("seed-rlv")
    damped = simulate(load_case("seed-rlv", duration_s=40.0), (parse_effect_spec("pitch_damping"),), seed=3)
    out = [("seed-rlv seed 0", reference_flight.telemetry, seed),
           ("seed-rlv seed 3, pitch damping", damped.telemetry, seed)]
    try:
        from aerosid.simulation.jsbsim_flight import simulate_jsbsim

        out.append(("JSBSim c172x", simulate_jsbsim("c172x", "3211", seed=0).telemetry, load_vehicle("c172x")))
    except Exception as exc:  # jsbsim is an optional extra
        print(f"JSBSim flight skipped: {exc}")
    if twin_otter.available():
        import tempfile
        from pathlib import Path

        veh = load_vehicle(twin_otter.vehicle_file(Path(tempfile.mkdtemp())))
        out += [(f"Twin Otter {n}", twin_otter.telemetry(n), veh) for n in twin_otter.FLIGHTS]
    return out


def test_no_false_alarm_on_the_shipped_flights(flights):
    assert len(flights) >= 2
    for label, frame, veh in flights:
        assert unit_findings(frame, veh) == [], label
        check_units(frame, veh, label)  # no error


def test_each_unit_mistake_is_found_naming_column_and_unit(flights):
    for label, frame, veh in flights:
        cases = MISTAKES + (SEED_ONLY if veh.vehicle_class == "finned" else [])
        for what, cols, factor, unit in cases:
            if "Twin Otter" in label and what == "p in deg/s":
                continue  # an elevator manoeuvre: |p| stays below 0.4 deg/s, plausible as rad/s (docs)
            found = unit_findings(with_factor(frame, cols, factor), veh)
            assert found, f"{label}: {what} not found"
            assert found[0].columns[0] == cols[0] and found[0].likely.split()[0] == unit, (label, what, found)
            with pytest.raises(TelemetryError) as ei:
                check_units(with_factor(frame, cols, factor), veh, "flight.parquet")
            assert ei.value.column == cols[0] and f"look like {unit}" in str(ei.value)


# (column, factor applied to the SI values, likely unit): measured air data in another unit
AIR_DATA_MISTAKES = [("qbar_pa", 1 / 47.880259, "psf"), ("qbar_pa", 1e-3, "kPa"), ("rho_kg_m3", 1 / 515.378818, "slug/ft^3"),
                     ("rho_kg_m3", 1 / 16.018463, "lb/ft^3"), ("p_static_pa", 1e-2, "hPa"),
                     ("p_static_pa", 1 / 3386.389, "inHg"), ("p_static_pa", 1 / 6894.757, "psi"),
                     ("T_total_K", 1.8, "degR")]


def test_measured_air_data_in_other_units_are_found_naming_column_and_unit(flights):
    """Dynamic pressure in psf or kPa, density in slug/ft^3 or lb/ft^3, static pressure in hPa,
    inHg or psi, total temperature in degR: each passes the schema's range (30 psf is a plausible number of Pa) and, before
    the check, ran to "ok" with every coefficient x47 (c182, qbar_pa in psf) or x515 (rho_kg_m3
    in slug/ft^3).  Measured in SI, nothing is found."""
    for label, frame, veh in flights:
        measured = with_measured_air_data(frame)
        assert unit_findings(measured, veh) == [], label
        for col, factor, unit in AIR_DATA_MISTAKES:
            found = unit_findings(with_factor(measured, [col], factor), veh)
            assert found and found[0].columns == (col,) and found[0].likely == unit, (label, col, unit, found)
            with pytest.raises(TelemetryError) as ei:
                check_units(with_factor(measured, [col], factor), veh, "flight.parquet")
            assert ei.value.column == col and f"look like {unit}" in str(ei.value)


def test_a_vane_noise_the_telemetry_contradicts_is_refused(flights):
    """[air_data] noise_rad sets the errors-in-variables correction of every coefficient: in
    degrees (x57) or ten times off either way it is refused, naming the key and the noise the
    vanes show (c182 with 0.15: C_N,alpha +473 % and "ok"); the declared noise passes (the
    no-false-alarm test)."""
    checked = 0
    for label, frame, veh in flights:
        if veh.air_data_source != "vanes" or not veh.vane_noise_rad > 0:
            continue
        checked += 1
        for factor in (1 / DEG, 10.0, 0.1):
            wrong = dataclasses.replace(veh, vane_noise_rad=veh.vane_noise_rad * factor)
            found = unit_findings(frame, wrong)
            assert found and found[0].kind == "setting" and found[0].declared == "[air_data] noise_rad", (label, factor)
            assert found[0].factor == pytest.approx(1 / factor, rel=0.3)  # the measured noise, about the declared
            with pytest.raises(TelemetryError) as ei:
                check_units(frame, wrong, "flight.parquet")
            assert "[air_data] noise_rad contradicts the telemetry" in str(ei.value)
            assert ("degrees written for radians" in str(ei.value)) == (factor > 50)
        # vanes low-passed before recording hide their noise from the differences: the engineer widens
        wide = dataclasses.replace(veh, vane_noise_rad=veh.vane_noise_rad * 10.0,
                                   plausibility=dataclasses.replace(veh.envelope, vane_noise_factor=30.0))
        assert unit_findings(frame, wide) == [], label
    assert checked >= 1


def test_a_total_temperature_in_celsius_or_fahrenheit_gets_the_conversion_in_the_schema_error():
    """degC and degF fail the schema's 150..8000 K; the error then says how to convert (both fit
    a mild day's values: both are named, not a guess)."""
    from aerosid.plausibility.units import range_unit_hint

    celsius = np.array([6.5, 6.4, 7.1, 5.9])
    hint = range_unit_hint("T_total_K", celsius)
    assert "degC (add 273.15)" in hint and "degF" in hint and "not K" in hint
    only_f = range_unit_hint("T_total_K", np.array([-150.0, -140.0]))  # as degC 123 K, as degF 172 K
    assert "degF" in only_f and "degC" not in only_f
    assert range_unit_hint("T_total_K", np.array([1e5, 2e5])) == ""


def test_the_kinematic_tests_alone_find_deg_s_and_km(flights):
    """With an envelope so wide that no magnitude is implausible, the kinematics still
    tell: the pitch rate against the vanes / the alpha range, the altitude against the
    doubly integrated vertical acceleration."""
    for label, frame, veh in flights:
        wide = dataclasses.replace(veh.envelope, rate_rad_s=100.0, h_m=(-1000.0, 1e6), qbar_pa=(0.0, 1e8),
                                   V_m_s=(0.0, 20000.0))
        wide_vehicle = dataclasses.replace(veh, plausibility=wide)
        assert K._pitch_rate_kinematic(frame, wide_vehicle) is None, label
        assert K._altitude_kinematic(frame) is None, label
        q = K._pitch_rate_kinematic(with_factor(frame, ["q_rad_s"], 1 / DEG), wide_vehicle)
        assert q is not None and q.likely == "deg/s", label
        for factor, unit in ((1e-3, "km"), (1 / 0.3048, "ft")):
            h = K._altitude_kinematic(with_factor(frame, ["h_m"], factor))
            assert h is not None and h.likely == unit, (label, unit)


def test_a_wider_envelope_in_the_vehicle_file_accepts_a_fast_vehicle(tmp_path, reference_flight):
    """A vehicle that really turns fast says so in its file: no error then."""
    src = load_vehicle("seed-rlv").source
    text = open(src).read() + "\n[plausibility]\nrate_rad_s = 20.0\n"
    path = tmp_path / "vehicle.toml"
    path.write_text(text)
    (tmp_path / "aerodb.csv").symlink_to(load_vehicle("seed-rlv").database_path)
    fast = load_vehicle(path)
    frame = reference_flight.telemetry.assign(p_rad_s=reference_flight.telemetry["p_rad_s"] * 20)
    assert [f.columns for f in unit_findings(frame, load_vehicle("seed-rlv"))] == [("p_rad_s",)]
    assert unit_findings(frame, fast) == []


# (label, column, factor, the columns the finding names, its kind, the vehicle needs vanes, attitude)
SIGN_AND_DEGREE_MISTAKES = [
    ("az from a z-up accelerometer", "az_m_s2", -1.0, ("az_m_s2",), "sign", False, False),
    ("pitch gyro flipped", "q_rad_s", -1.0, ("q_rad_s",), "sign", True, False),
    ("alpha vane flipped", "alpha_vane_rad", -1.0, ("alpha_vane_rad",), "sign", True, False),
    ("alpha vane in deg", "alpha_vane_rad", 1 / DEG, ("alpha_vane_rad",), "unit", True, False),
    ("theta flipped", "theta_rad", -1.0, ("theta_rad",), "sign", True, True),
    ("theta in deg", "theta_rad", 1 / DEG, ("theta_rad",), "unit", False, True),
    # the lateral ones need a lateral manoeuvre (JSBSim's flight; the Twin Otter's is longitudinal)
    ("beta vane flipped", "beta_vane_rad", -1.0, ("beta_vane_rad",), "sign", True, False),
    ("yaw gyro flipped", "r_rad_s", -1.0, ("r_rad_s",), "sign", True, False),
    ("lateral accelerometer flipped", "ay_m_s2", -1.0, ("ay_m_s2",), "sign", True, False),
    ("beta vane in deg", "beta_vane_rad", 1 / DEG, ("beta_vane_rad",), "unit", True, False),  # mostly < 90 deg
    # p against phi alone cannot tell which; the sideslip fit's gravity from phi does
    ("roll gyro flipped", "p_rad_s", -1.0, ("p_rad_s",), "sign", True, True),
    ("bank angle flipped", "phi_rad", -1.0, ("phi_rad",), "sign", True, True),
]
LATERAL = {"beta vane flipped", "yaw gyro flipped", "lateral accelerometer flipped", "beta vane in deg",
           "roll gyro flipped", "bank angle flipped"}


def test_sign_and_degree_mistakes_are_found_naming_the_column(flights):
    """A z-up accelerometer (aircraft), a flipped pitch gyro, vane, yaw gyro or lateral
    accelerometer, vanes or attitude in degrees: each refused naming the column (on 25 JSBSim
    aircraft x 2 seeds: none on the clean flights, never the wrong column). Before, a flipped q turned C_m,alpha and
    C_m,delta positive on c182 and the run blamed the vane; a z-up az flipped C_N,alpha."""
    checked = 0
    for label, frame, veh in flights:
        vanes = veh.air_data_source == "vanes" and veh.alpha_column in frame.columns
        attitude = {"phi_rad", "theta_rad"} <= set(frame.columns)
        for what, col, factor, named, kind, needs_vanes, needs_attitude in SIGN_AND_DEGREE_MISTAKES:
            if (needs_vanes and not vanes) or (needs_attitude and not attitude) or col not in frame.columns:
                continue
            if col == "az_m_s2" and veh.vehicle_class != "aircraft":
                continue  # a finned vehicle's az may have either sign
            if what in LATERAL and not label.startswith("JSBSim"):
                continue
            found = unit_findings(with_factor(frame, [col], factor), veh)
            assert found and found[0].columns == named and found[0].kind == kind, (label, what, found)
            with pytest.raises(TelemetryError) as ei:
                check_units(with_factor(frame, [col], factor), veh, "flight.parquet")
            assert ei.value.column == named[0]
            assert ("sign looks flipped" if kind == "sign" else "look like deg") in str(ei.value)
            checked += 1
    assert checked >= 12


@pytest.mark.skipif(not twin_otter.available(), reason="the Twin Otter data are not on this machine")
def test_real_flights_with_their_attitude_raise_nothing_and_their_flips_are_named(tmp_path):
    """NASA's Twin Otter as `aerosid import sidpac` writes it (with phi_rad, theta_rad, so the
    attitude and sideslip tests run): nothing on the recorded data; the pitch gyro, the pitch
    attitude, the alpha vane and the accelerometer's z axis flipped, each named."""
    from aerosid.vehicles.sidpac import import_sidpac

    for name in twin_otter.FLIGHTS:
        imported = import_sidpac(twin_otter.DATA / name)
        frame = imported.telemetry
        path = tmp_path / f"{name}.toml"
        path.write_text(imported.vehicle_toml)
        veh = load_vehicle(path)
        assert {"phi_rad", "theta_rad"} <= set(frame.columns)
        assert unit_findings(frame, veh) == [], name
        for col in ("q_rad_s", "theta_rad", "alpha_vane_rad", "az_m_s2"):
            found = unit_findings(with_factor(frame, [col], -1.0), veh)
            assert found and found[0].columns == (col,) and found[0].kind == "sign", (name, col, found)


def test_in_turbulence_the_sideslip_fit_names_no_wrong_column(tmp_path):
    """In moderate turbulence the vane reads the air's sideslip and the lateral kinematics do not
    fit it (c182: its a_y coefficient -3.4): a flipped beta vane was blamed on the yaw gyro and a
    flipped yaw gyro on the vane. The sideslip fit now attributes a sign only where it fits."""
    try:
        from aerosid.simulation.jsbsim_aircraft import simulate_aircraft
        fl = simulate_aircraft("c182", 0, turbulence="moderate")
    except ImportError as exc:  # jsbsim is an optional extra
        pytest.skip(f"jsbsim: {exc}")
    path = tmp_path / "c182.toml"
    path.write_text(fl.files["vehicle.toml"])
    veh, frame = load_vehicle(path), fl.telemetry
    assert unit_findings(frame, veh) == []
    for col in ("beta_vane_rad", "r_rad_s", "p_rad_s", "phi_rad"):
        found = unit_findings(with_factor(frame, [col], -1.0), veh)
        assert not found or col in found[0].columns, (col, found[0].columns)


def _jsbsim_flight(tmp_path, aircraft: str, seed: int, **kwargs):
    try:
        from aerosid.simulation.jsbsim_aircraft import simulate_aircraft
        fl = simulate_aircraft(aircraft, seed, **kwargs)
    except ImportError as exc:  # jsbsim is an optional extra
        pytest.skip(f"jsbsim: {exc}")
    path = tmp_path / f"{aircraft}.toml"
    path.write_text(fl.files["vehicle.toml"])
    return load_vehicle(path), fl.telemetry


def _as_calibrated(frame: pd.DataFrame) -> pd.DataFrame:
    from aerosid.vehicles.airspeed import calibrated_from_true_m_s

    out = frame.copy()
    ok = out["V_m_s"].notna() & out["h_m"].notna()
    out.loc[ok, "V_m_s"] = calibrated_from_true_m_s(out.loc[ok, "V_m_s"].to_numpy(), out.loc[ok, "h_m"].to_numpy())
    return out


def test_a_calibrated_airspeed_taken_for_the_true_one_is_refused_at_altitude(tmp_path):
    """A4 at 6 km: a calibrated airspeed in V_m_s (0.75 x the true one) made every coefficient x1.8
    with no finding. The pitch kinematics put the column at the calibrated airspeed's share of the
    true one; the true airspeed passes, and the real Twin Otter's true airspeeds pass."""
    veh, frame = _jsbsim_flight(tmp_path, "A4", 0)
    s_true, se = airspeed_scale(frame, veh)
    assert abs(s_true - 1.0) < 0.06 and se < 0.02
    assert unit_findings(frame, veh) == []
    cas = _as_calibrated(frame)
    found = unit_findings(cas, veh)
    assert len(found) == 1 and found[0].columns == ("V_m_s",) and found[0].kind == "airspeed"
    s_cas, _ = airspeed_scale(cas, veh)
    share = float(np.nanmedian(cas["V_m_s"] / frame["V_m_s"]))
    assert abs(s_cas / s_true - share) < 0.02  # the scale reads the column's share of the true airspeed
    with pytest.raises(TelemetryError, match=r"calibrated .*V_m_s at 0\.7\d"):
        check_units(cas, veh, "a4.parquet")
    wide = dataclasses.replace(veh, plausibility=dataclasses.replace(veh.envelope, airspeed_scale_min=0.5))
    assert unit_findings(cas, wide) == []  # [plausibility] airspeed_scale_min accepts it
    # the same scale names an airspeed in knots or ft/s, which the magnitude alone cannot tell
    for factor, unit in ((1 / 0.514444, "kt"), (1 / 0.3048, "ft/s")):
        (found,) = unit_findings(with_factor(frame, ["V_m_s"], factor), veh)
        assert found.columns == ("V_m_s",) and found.likely == unit and found.kind == "unit", (unit, found)
    if twin_otter.available():
        to_veh = load_vehicle(twin_otter.vehicle_file(tmp_path))
        for n in twin_otter.FLIGHTS:
            s, _ = airspeed_scale(twin_otter.telemetry(n), to_veh)
            assert 0.93 < s < 1.03, (n, s)


def test_in_turbulence_the_airspeed_scale_gives_no_verdict(tmp_path):
    """Moderate turbulence: the vane reads gusts the kinematics do not (true airspeeds' scale
    0.14-0.68 on T37, c182, global5000; in light turbulence at 1.4 km c182 reads 0.39): the
    low-passed residual, large against the fitted part, withholds the verdict."""
    for aircraft, level in (("global5000", "moderate"), ("c182", "light")):
        veh, frame = _jsbsim_flight(tmp_path, aircraft, 3 if level == "moderate" else 0, turbulence=level)
        assert math.isnan(airspeed_scale(frame, veh)[0]), aircraft
        assert unit_findings(frame, veh) == []


def test_a_vehicle_file_that_states_a_calibrated_airspeed_has_it_converted(tmp_path):
    """[air_data] airspeed = "calibrated": the check reads V_m_s as the preprocessing will (the
    true airspeed: nothing refused) and the preprocessing's V_m_s is the true airspeed again."""
    from aerosid.cli.run import _preflight
    from aerosid.ebm import preprocess_and_plan
    from aerosid.vehicles.airspeed import as_true_airspeed

    veh, frame = _jsbsim_flight(tmp_path, "A4", 0)
    cas = _as_calibrated(frame)
    text = (tmp_path / "A4.toml").read_text()
    assert text.count('source = "vanes"') == 1
    (tmp_path / "cas.toml").write_text(text.replace('source = "vanes"', 'source = "vanes"\nairspeed = "calibrated"'))
    stated = load_vehicle(tmp_path / "cas.toml")
    assert stated.airspeed_kind == "calibrated"
    back, note = as_true_airspeed(cas, stated.airspeed_kind)
    ok = frame["V_m_s"].notna() & frame["h_m"].notna()
    np.testing.assert_allclose(back.loc[ok, "V_m_s"], frame.loc[ok, "V_m_s"], rtol=1e-6)
    assert "calibrated" in note and as_true_airspeed(frame, "true") == (frame, "")
    assert unit_findings(back, stated) == []
    path = tmp_path / "cas.parquet"
    cas.to_parquet(path)
    _preflight(path, str(tmp_path / "cas.toml"), None)  # raises on anything aerosid run would refuse
    with pytest.raises(TelemetryError, match=r'\[air_data\] airspeed = "calibrated"'):
        _preflight(path, str(tmp_path / "A4.toml"), None)
    pre, _ = preprocess_and_plan(cas, stated)
    true = frame.dropna(subset=["t_s", "V_m_s"])
    V_true = np.interp(pre.frame["t_s"], true["t_s"], true["V_m_s"])
    assert np.nanmedian(pre.frame["V_m_s_clean"] / V_true) == pytest.approx(1.0, abs=1e-3)
    # the flows' preprocess stage: converted, and the preprocessed file says so
    from aerosid.io import read_parquet_metadata
    from tasks.runner import StageContext
    from tasks.stages import preprocess_task

    run_dir = tmp_path / "run"
    done = preprocess_task.fn(str(path), str(run_dir), StageContext(str(run_dir / "ledger.jsonl"), "local", "f"), {},
                              str(tmp_path / "cas.toml"))
    staged = pd.read_parquet(done["path"])
    assert np.nanmedian(staged["V_m_s_clean"] / np.interp(staged["t_s"], true["t_s"], true["V_m_s"])) == \
        pytest.approx(1.0, abs=1e-3)
    assert "calibrated" in read_parquet_metadata(done["path"])["aerosid.airspeed"]


def test_an_impact_pressure_in_qbar_pa_is_refused_where_the_air_is_measured(tmp_path):
    """A pitot-static system's q_c recorded as qbar_pa: at Mach 0.62 (global5000) and 1.59 (F4N)
    it is 1.10 and 1.56 x the dynamic pressure the measured density gives, and every coefficient
    would be low by that; the dynamic pressure itself passes, and so does a real day's."""
    from aerosid.vehicles.airspeed import _qc_over_p
    from aerosid.vehicles.atmosphere import CP_AIR_J_KG_K, density_kg_m3, pressure_pa, speed_of_sound_m_s, temperature_K

    for aircraft in ("global5000", "F4N"):
        veh, frame = _jsbsim_flight(tmp_path, aircraft, 0)
        h, V = frame["h_m"].to_numpy(float), frame["V_m_s"].to_numpy(float)
        air = frame.assign(rho_kg_m3=density_kg_m3(np.nan_to_num(h, nan=6000.0)),
                           p_static_pa=pressure_pa(np.nan_to_num(h, nan=6000.0)))
        air["T_total_K"] = temperature_K(np.nan_to_num(h, nan=6000.0)) + V**2 / (2.0 * CP_AIR_J_KG_K)
        air["qbar_pa"] = 0.5 * air["rho_kg_m3"] * V**2
        assert unit_findings(air, veh) == [], aircraft
        mach = V / speed_of_sound_m_s(np.nan_to_num(h, nan=6000.0))
        qc = air.assign(qbar_pa=air["p_static_pa"] * _qc_over_p(mach))
        (found,) = unit_findings(qc, veh)
        assert found.columns == ("qbar_pa",) and found.kind == "pressure", found
        assert "impact pressure" in found.message() and "dynamic_from_impact_pressure_pa" in found.message()
        # without the density, the static pressure and total temperature tell it too
        (found,) = unit_findings(qc.drop(columns=["rho_kg_m3"]), veh)
        assert found.kind == "pressure"
    assert unit_findings(with_measured_air_data(frame), veh) == []  # a cold high-pressure day
