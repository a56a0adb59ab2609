"""JSBSim aircraft flown with a generated flight design and vehicle file
(aerosid.simulation.jsbsim_aircraft / jsbsim_design / jsbsim_trim / jsbsim_tables)."""
from __future__ import annotations

import math
import tomllib
import xml.etree.ElementTree as ET

import numpy as np
import pytest

pytest.importorskip("jsbsim")

from aerosid.io import read_parquet_metadata, telemetry_vehicle  # noqa: E402
from aerosid.vehicles.rigid_body import body_rate_derivatives, inertia_constants  # noqa: E402
from aerosid.simulation.jsbsim_aircraft import XML_TOLERANCE, simulate_aircraft  # noqa: E402
from aerosid.simulation.jsbsim_design import BETA_STEP_DEG, UnsupportedAircraft, flight_design  # noqa: E402
from aerosid.simulation.jsbsim_fcs import closed_loop_derivatives  # noqa: E402
from aerosid.simulation.jsbsim_modes import mode_frequencies  # noqa: E402
from aerosid.simulation.jsbsim_flight import (  # noqa: E402
    TELEMETRY_COLUMNS,
    _import_jsbsim,
    _trimmed_fdm,
    load_jsbsim_config,
    simulate_jsbsim,
)
from aerosid.simulation.jsbsim_tables import AeroTables  # noqa: E402
from aerosid.simulation.jsbsim_trim import open_fdm, start_engines, trim  # noqa: E402
from aerosid.vehicles.vehicle import load_vehicle  # noqa: E402

AIRCRAFT = "pa28"   # a light single: ~36 s of flight, ~1 s to simulate


@pytest.fixture(scope="module")
def flight():
    return simulate_aircraft(AIRCRAFT, seed=0)


@pytest.fixture(scope="module")
def written(flight, tmp_path_factory):
    out = tmp_path_factory.mktemp("pa28")
    return flight.write(out)


def test_generated_vehicle_file_loads_and_holds_jsbsims_numbers(flight, written):
    doc = tomllib.loads(written["vehicle"].read_text())
    assert "estimation" not in doc  # the estimation settings come from the data (issue 16)
    veh = load_vehicle(written["vehicle"])
    info = flight.info
    assert veh.name == AIRCRAFT and veh.vehicle_class == "aircraft" and veh.air_data_source == "vanes"
    for key in ("mass_kg", "Ixx_kg_m2", "Iyy_kg_m2", "Izz_kg_m2"):
        assert getattr(veh, key) == pytest.approx(info["mass"][key], rel=1e-5), key
    # Ixz: aerosid's convention is minus JSBSim's property
    assert veh.Ixz_kg_m2 == pytest.approx(-info["mass"]["Ixz_jsbsim_property_kg_m2"], abs=1e-6)
    ref = info["reference"]
    assert (veh.S_m2, veh.chord_m, veh.span_m) == pytest.approx((ref["S_m2"], ref["chord_m"], ref["span_m"]), rel=1e-5)
    assert veh.mach_reference == pytest.approx(info["trim"]["mach"], rel=1e-5)
    assert veh.accel_offset_m == pytest.approx(tuple(info["accel_offset_m"]))
    # the mixing rebuilds the deflections the aircraft's aerodynamics read from d1..d4
    tr = flight.truth
    d_r, d_p, d_y = veh.mix(*(tr[f"d{i}_rad"].to_numpy() for i in range(1, 5)))
    assert np.allclose(d_r, tr["delta_r_rad"]) and np.allclose(d_p, tr["delta_p_rad"])
    assert np.allclose(d_y, tr["delta_y_rad"])
    assert np.ptp(tr["delta_r_rad"]) > 1e-2  # the aileron doublet moved it
    lo, hi = np.array(doc["controls"]["surface_limits_rad"]).T
    for i in range(4):
        assert lo[i] - 1e-9 <= tr[f"d{i + 1}_rad"].min() and tr[f"d{i + 1}_rad"].max() <= hi[i] + 1e-9


def test_truth_equals_the_xml_model_at_every_sample(flight):
    """JSBSim's own aerodynamic coefficients about the CG = the aircraft's XML model
    re-evaluated independently from the recorded properties, at every sample."""
    tr = flight.truth
    for k in ("CA", "CY", "CN", "Cl", "Cm", "Cn"):
        assert np.max(np.abs(tr[k] - tr[f"{k}_xml"])) < 1e-9, k
        assert flight.info["truth_check"]["xml_vs_jsbsim_max_abs"][k] < XML_TOLERANCE
    assert np.ptp(tr["Cm"]) > 0.02 and np.ptp(tr["Cl"]) > 0.005  # a manoeuvre, not a steady state


def test_linear_truth_agrees_with_a_fit_of_the_noise_free_truth(flight):
    check = flight.info["truth_check"]
    rel = check["Cm"]["rel_diff"]
    assert abs(rel["Cm_alpha"]) < 0.03 and abs(rel["Cm_delta_p"]) < 0.02
    assert abs(check["CN"]["rel_diff"]["CN_alpha"]) < 0.03
    for coef, names in (("Cl", ("Cl_beta", "Cl_p", "Cl_delta_r")), ("Cn", ("Cn_beta", "Cn_r", "Cn_delta_y"))):
        for name in names:
            assert abs(check[coef]["rel_diff"][name]) < 0.03, name
    c = flight.coefficients
    assert c["Cm_alpha"] < 0 and c["Cm_delta_p"] < 0 and c["Cl_p"] < 0 and c["Cn_beta"] > 0 and c["Cn_r"] < 0
    assert c["Cm_q_plus_alpha_dot"] == pytest.approx(c["Cm_q"] + c["Cm_alpha_dot"])


def test_rigid_body_with_the_vehicle_file_gives_jsbsims_angular_accelerations(flight):
    veh = tomllib.loads(flight.files["vehicle.toml"])
    m, ref = veh["mass"], veh["reference"]
    c = inertia_constants(m["Ixx_kg_m2"], m["Iyy_kg_m2"], m["Izz_kg_m2"], m["Ixz_kg_m2"])
    tr = flight.truth
    qS = tr["qbar_pa"] * ref["S_m2"]
    L = (tr["Cl"] + tr["Cl_prop"]) * qS * ref["span_m"]
    M = (tr["Cm"] + tr["Cm_prop"]) * qS * ref["chord_m"]
    N = (tr["Cn"] + tr["Cn_prop"]) * qS * ref["span_m"]
    rates = [tr[f"{a}_state_rad_s"] for a in "pqr"]
    for mine, theirs in zip(body_rate_derivatives(*rates, L / c.Ixx, M / c.Iyy, N / c.Izz, c),
                            ("p_dot_rad_s2", "q_dot_rad_s2", "r_dot_rad_s2")):
        assert np.max(np.abs(mine - tr[theirs])) < 1e-3 * np.max(np.abs(tr[theirs])), theirs


def test_gyro_rates_are_the_aerodynamics_state_and_centred_on_the_moments(flight):
    """JSBSim steps the body rates with Adams-Bashforth 2 (jsbsim_flight.ROTATIONAL_INTEGRATOR):
    the gyros read the state JSBSim's aerodynamics used, and its central difference is the
    angular acceleration of the same sample.  (Rectangular Euler could have only one of the
    two: its re-timed rates sat dt/2 = 5 ms off the aerodynamics' state, which inflated F4N's
    C_m_delta and damping by ~2.5 %, bench/results/attribution.md; its own state's central
    difference lags the moments by dt/2: 4.5 % RMS of q-dot on this flight.)"""
    tr, dt = flight.truth, 1.0 / flight.info["sample_rate_hz"]
    for a in "pqr":
        x, xd, rate = tr[f"{a}_state_rad_s"].to_numpy(), tr[f"{a}_dot_rad_s2"].to_numpy(), tr[f"{a}_rad_s"].to_numpy()
        assert np.array_equal(rate, x), a
        cd = (rate[2:] - rate[:-2]) / (2 * dt)
        assert np.sqrt(np.mean((cd - xd[1:-1]) ** 2)) < 0.015 * np.sqrt(np.mean(xd ** 2)), a
        assert abs(np.polyfit(xd[1:-1], cd, 1)[0] - 1.0) < 0.005, a


def test_trimmed_before_the_manoeuvre_and_telemetry_layout(flight):
    tel, tr = flight.telemetry, flight.truth
    assert list(tel.columns) == TELEMETRY_COLUMNS
    quiet = tr[tr["t_s"] < flight.info["manoeuvre_settings"]["elevator_starts_s"][0] - 0.1]
    assert len(quiet) > 250
    assert np.abs(quiet[["p_rad_s", "q_rad_s", "r_rad_s"]]).to_numpy().max() < 1e-3
    assert np.ptp(quiet["alpha_rad"]) < 2e-4 and np.ptp(quiet["V_m_s"]) < 0.05
    trim = flight.info["trim"]
    assert trim["mode"] == "glide" and trim["throttle"] == 0.0 and -10.0 < trim["gamma_deg"] < 0.0
    assert quiet["alpha_rad"].iloc[0] == pytest.approx(math.radians(trim["alpha_deg"]), abs=1e-6)
    # the manoeuvre stays in the linear range: alpha within a few degrees of trim
    assert flight.info["alpha_max_deg"] - flight.info["alpha_min_deg"] < 8.0
    assert abs(flight.info["phi_max_deg"]) < 30 and abs(flight.info["phi_min_deg"]) < 30


def test_written_telemetry_names_its_vehicle_file(written):
    tel = written["telemetry"]
    assert read_parquet_metadata(tel)["aerosid.vehicle"] == "vehicle.toml"
    assert telemetry_vehicle(tel) == str(written["vehicle"])
    assert load_vehicle(telemetry_vehicle(tel)).name == AIRCRAFT


def test_own_trim_reproduces_jsbsims_trim_of_c172x():
    """aerosid's Newton trim, at c172x's configured glide angle, finds JSBSim's own
    do_simple_trim solution (alpha, throttle, elevator position)."""
    jsbsim = _import_jsbsim()
    sim_cfg, _ = load_jsbsim_config("c172x")
    ref = _trimmed_fdm(jsbsim, sim_cfg)
    tr = sim_cfg["trim"]
    fdm = open_fdm(jsbsim, "c172x", sim_cfg["jsbsim"]["dt_s"])
    fdm["propulsion/fuel_freeze"] = 0
    for i, w in enumerate(sim_cfg["loading"]["pointmass_weights_lbs"]):
        fdm[f"inertia/pointmass-weight-lbs[{i}]"] = float(w)
    start_engines(fdm, tr["h_m"], tr["V_m_s"])
    point = trim(fdm, tr["h_m"], tr["V_m_s"], "level", gamma_deg=tr["gamma_deg"])
    # (two trims within their tolerances: JSBSim stops at |w-dot| ~ 2e-4 ft/s^2 and a different
    # bank angle; 0.02 deg of alpha is ~1e-3 of the 1.06 deg trim)
    assert point.alpha_deg == pytest.approx(ref["aero/alpha-deg"], abs=0.02)
    assert point.throttle == pytest.approx(ref["fcs/throttle-cmd-norm"], abs=0.005)
    assert fdm["fcs/elevator-pos-rad"] == pytest.approx(ref["fcs/elevator-pos-rad"], abs=5e-4)
    assert max(point.max_residual) < 1e-3


def test_design_rules_by_class():
    jsbsim = _import_jsbsim()
    jet = flight_design(jsbsim, "T37")
    assert jet.propulsion == "jet" and jet.trim.mode == "level" and 0.0 < jet.trim.throttle < 1.0
    prop = flight_design(jsbsim, "pa28")
    assert prop.propulsion == "propeller" and prop.trim.mode == "glide" and prop.trim.throttle == 0.0
    for d in (jet, prop):
        m = d.manoeuvre
        # the 3-2-1-1's first step raises C_m (nose up); sized by the aircraft's own derivatives
        assert np.sign(m["elevator_amplitudes_norm"][0] * d.gains["pitch"] * d.derivatives["Cm_delta_p"]) > 0
        w = d.modes["omega_pitch_design_rad_s"]
        assert m["elevator_unit_s"] == pytest.approx(min(max(2.0 / w, 0.1), 1.0), abs=0.006)
        assert m["aileron_start_s"] > m["elevator_starts_s"][1] > m["elevator_starts_s"][0]
        assert m["rudder_start_s"] > m["aileron_start_s"] and d.duration_s > m["rudder_start_s"]


def test_fcs_feedback_probe_and_closed_loop_sizing():
    """A320's FCS adds -5 beta [rad] and 2 r [rad/s] to the normalised rudder (25 deg of travel
    per unit): the probe must find -5 x 25 deg = -2.18 rad per rad and 0.87 rad per rad/s,
    and the rudder step is sized for a 1.5 deg sideslip of the CLOSED loop (its Cn_beta
    stiffened by Cn_delta_y x the feedback), about six times the open-loop step."""
    jsbsim = _import_jsbsim()
    a320 = flight_design(jsbsim, "A320")
    root = ET.parse(a320.xml_path).getroot()
    gains = {el.get("name"): float(el.find("gain").text) for el in root.iter("pure_gain") if el.find("gain") is not None}
    per_unit = math.radians(25.0)
    k_beta = gains["Yaw Damper Beta"] * per_unit
    k_r = gains["Yaw Damper Rate"] * per_unit
    fb = a320.feedback
    assert fb["beta"]["yaw"] == pytest.approx(k_beta, rel=0.02)
    assert fb["r"]["yaw"] == pytest.approx(k_r, rel=0.02)
    d = a320.derivatives
    closed = d["Cn_beta"] + d["Cn_delta_y"] * k_beta
    assert closed > 3 * d["Cn_beta"] > 0  # the feedback holds the sideslip to a fraction of the open loop's
    step = a320.manoeuvre["surface_steps_rad"]["rudder"]
    # sized on the closed loop's steady sideslip, then scaled for its yaw damper (next test)
    steady = math.radians(BETA_STEP_DEG) * closed / abs(d["Cn_delta_y"])
    scaled = [n for n in a320.notes if n.startswith("yaw damper")]
    assert len(scaled) == 1 and f"rudder step {math.degrees(steady):.2f} -> {math.degrees(step):.2f} deg" in scaled[0]
    assert any("closed loop's Cn_beta" in n for n in a320.notes)
    # the flown command: the step through the rudder's static gain (within 40 % of its travel)
    norm = a320.manoeuvre["rudder_amplitude_norm"]
    assert abs(norm * a320.gains["yaw"]) == pytest.approx(step, abs=0.01 * abs(a320.gains["yaw"]))
    # the doublets stay timed on the open loop's Dutch roll (measured better than the closed loop's)
    assert a320.modes == mode_frequencies(d, a320.state)
    # no angle or roll-rate feedback: the closed loop is the open loop, and so is the sizing
    pa28 = flight_design(jsbsim, "pa28")
    assert all(v == 0.0 for row in ("alpha", "beta", "p") for v in pa28.feedback[row].values())
    span_m = pa28.state["metrics/bw-ft"] * 0.3048
    same = closed_loop_derivatives(pa28.derivatives, pa28.feedback, pa28.trim.V_m_s, span_m)
    assert same == {name: pa28.derivatives[name] for name in ("Cm_alpha", "Cl_p", "Cn_beta")}
    assert pa28.manoeuvre["surface_steps_rad"]["rudder"] == pytest.approx(
        math.radians(BETA_STEP_DEG) * abs(pa28.derivatives["Cn_beta"] / pa28.derivatives["Cn_delta_y"]), rel=1e-9)


@pytest.mark.parametrize("aircraft", ["pa28", "global5000"])
def test_dutch_roll_approximation_gives_jsbsims_doublet_sideslip(aircraft):
    """The rudder doublet's peak sideslip from the Dutch-roll approximation (with the yaw damper's
    static gain in the loop) against the same doublet flown in JSBSim at half the design's
    command: within 10 % on an undamped aircraft (pa28) and a damped one (global5000, 4 % when
    measured).  On a yaw-damped aircraft the design's step is the one whose flown doublet reaches
    the undamped approximation's peak (within 5 %) or the travel cap."""
    from aerosid.simulation.jsbsim_design import DAMPER_TOLERANCE, loaded_fdm
    from aerosid.simulation.jsbsim_modes import doublet_sideslip_peak, flown_doublet_sideslip_peak
    jsbsim = _import_jsbsim()
    design = flight_design(jsbsim, aircraft)
    m, fb = design.manoeuvre, design.feedback
    half, rise = m["rudder_half_s"], m["rudder_rise_s"]
    fdm = loaded_fdm(jsbsim, aircraft, ET.parse(design.xml_path).getroot(), design.trim)
    step = m["surface_steps_rad"]["rudder"]
    flown = flown_doublet_sideslip_peak(fdm, design.trim, 0.5 * m["rudder_amplitude_norm"], half, rise, 0.01)
    model = 0.5 * step * doublet_sideslip_peak(design.derivatives, design.state, half, rise,
                                                fb["r"]["yaw"], fb["beta"]["yaw"])
    assert flown == pytest.approx(model, rel=0.1)
    damped = abs(fb["r"]["yaw"]) > 1e-3
    assert damped == (aircraft == "global5000")
    if damped:
        target = (math.radians(BETA_STEP_DEG) * abs(design.derivatives["Cn_beta"] / design.derivatives["Cn_delta_y"])
                  * doublet_sideslip_peak(design.derivatives, design.state, half, rise, 0.0, fb["beta"]["yaw"]))
        full = flown_doublet_sideslip_peak(fdm, design.trim, m["rudder_amplitude_norm"], half, rise, 0.01)
        assert full == pytest.approx(target, rel=DAMPER_TOLERANCE + 0.01)  # + the command's rounding
        assert step > 2.0 * math.radians(BETA_STEP_DEG) * abs(design.derivatives["Cn_beta"] / design.derivatives["Cn_delta_y"])


def test_short_period_of_mode_frequencies_is_the_two_state_models_eigenvalues():
    """alpha' = Z_a alpha + q, q' = M_a alpha + M_q q + M_ad alpha': omega_sp^2 is the determinant
    (M_ad drops out of it) and 2 zeta omega minus the trace; an earlier version put M_ad into both."""
    base = {"aero/qbar-psf": 60.0, "metrics/Sw-sqft": 170.0, "metrics/cbarw-ft": 5.0, "metrics/bw-ft": 36.0,
            "velocities/vt-fps": 150.0, "inertia/mass-slugs": 70.0, "inertia/ixx-slugs_ft2": 1000.0,
            "inertia/iyy-slugs_ft2": 1300.0, "inertia/izz-slugs_ft2": 2000.0}
    d = {"Cm_alpha": -1.0, "Cm_q": -12.0, "Cm_alpha_dot": -7.0, "CN_alpha": 5.0, "Cn_beta": 0.1, "Cl_p": -0.5}
    m = mode_frequencies(d, base)
    Za, Ma, Mq, Mad = m["Z_alpha_s"], m["M_alpha_s2"], m["M_q_s"], m["M_alpha_dot_s"]
    assert Mad / Mq == pytest.approx(7.0 / 12.0)
    A = np.array([[Za, 1.0], [Ma + Mad * Za, Mq + Mad]])  # alpha' substituted into q'
    eig = np.linalg.eigvals(A)
    assert m["omega_sp_rad_s"] ** 2 == pytest.approx(float(np.prod(eig).real), rel=1e-12)
    assert 2 * m["zeta_sp"] * m["omega_sp_rad_s"] == pytest.approx(-float(np.sum(eig).real), rel=1e-12)
    # the design frequency of an overdamped short period is its slower real root
    stiff = mode_frequencies({**d, "Cm_q": -200.0}, base)
    Mq2 = stiff["M_q_s"]
    eig2 = np.linalg.eigvals(np.array([[Za, 1.0], [Ma + Mad * Za, Mq2 + Mad]]))
    assert np.all(np.isreal(eig2))
    assert stiff["omega_pitch_design_rad_s"] == pytest.approx(float(np.min(np.abs(eig2.real))), rel=1e-9)


def test_closed_loop_derivatives_closed_form():
    d = {"Cm_alpha": -1.0, "Cm_delta_p": -2.0, "Cl_p": -0.5, "Cl_delta_r": 0.2, "Cn_beta": 0.1, "Cn_delta_y": -0.4}
    fb = {"alpha": {"pitch": 0.25}, "p": {"roll": -0.1}, "beta": {"yaw": -1.5}}
    c = closed_loop_derivatives(d, fb, 50.0, 10.0)
    assert c["Cm_alpha"] == pytest.approx(-1.0 - 2.0 * 0.25)
    assert c["Cl_p"] == pytest.approx(-0.5 + 0.2 * -0.1 * 2 * 50.0 / 10.0)
    assert c["Cn_beta"] == pytest.approx(0.1 + -0.4 * -1.5)
    assert closed_loop_derivatives(d, {}, 50.0, 10.0) == {k: d[k] for k in ("Cm_alpha", "Cl_p", "Cn_beta")}


def test_aircraft_that_cannot_be_flown_say_why():
    jsbsim = _import_jsbsim()
    with pytest.raises(UnsupportedAircraft, match="pitch rate"):  # fly-by-wire: closed-loop pitch
        simulate_jsbsim("f16")
    with pytest.raises(UnsupportedAircraft, match="statically unstable"):
        flight_design(jsbsim, "XB-70")
    with pytest.raises(UnsupportedAircraft, match="steeper than"):  # X-15 burnt out: a -15 deg glide
        flight_design(jsbsim, "X15")
    with pytest.raises(UnsupportedAircraft, match="ships .*pa28"):
        flight_design(jsbsim, "no-such-aircraft")
    assert issubclass(UnsupportedAircraft, ValueError)


def test_evaluator_elements_against_closed_forms(tmp_path):
    xml = tmp_path / "toy.xml"
    axes = "".join(f'<axis name="{a}"><function name="aero/{a}"><value>0</value></function></axis>'
                   for a in ("DRAG", "SIDE", "ROLL", "PITCH", "YAW"))
    xml.write_text(f"""<fdm_config><aerodynamics>
      <function name="aero/k"><product><p>aero/x</p><v>2</v></product></function>
      {axes}
      <axis name="LIFT">
        <function name="aero/a"><ifthen><gt><p>aero/x</p><v>0</v></gt><pow><p>aero/x</p><v>2</v></pow>
          <abs><p>aero/k</p></abs></ifthen></function>
        <function name="aero/b"><table><independentVar lookup="row">aero/x</independentVar>
          <independentVar lookup="column">aero/y</independentVar>
          <tableData>  0 1
            -1 0 10
             1 2 30 </tableData></table></function>
        <function name="aero/c"><sum><min><p>aero/x</p><v>0.5</v></min><atan2><p>aero/y</p><v>1</v></atan2>
          <difference><v>1</v><p>-aero/y</p></difference></sum></function>
      </axis></aerodynamics></fdm_config>""")
    t = AeroTables(xml)
    assert t.leaf_properties() == ["aero/x", "aero/y"]
    x, y = np.array([-0.5, 0.25, 3.0]), np.array([0.5, 0.0, 2.0])
    lift = t.axis_sums({"aero/x": x, "aero/y": y})["LIFT"]
    a = np.where(x > 0, x**2, np.abs(2 * x))
    xc = np.clip(x, -1, 1)
    b = np.interp(xc, [-1, 1], [0, 2]) * (1 - np.clip(y, 0, 1)) + np.interp(xc, [-1, 1], [10, 30]) * np.clip(y, 0, 1)
    c = np.minimum(x, 0.5) + np.arctan2(y, 1.0) + 1 + y
    assert np.allclose(lift, a + b + c)
    bad = tmp_path / "bad.xml"
    bad.write_text(xml.read_text().replace("<min>", "<unknown_op>").replace("</min>", "</unknown_op>"))
    with pytest.raises(NotImplementedError, match="unknown_op"):
        AeroTables(bad)
    root = ET.parse(xml).getroot()
    assert root.find("aerodynamics") is not None


def test_an_aircraft_that_reads_engine_zero_by_its_index_is_flown():
    """J3Cub's aerodynamics read 'propulsion/engine[0]/thrust-coefficient'; JSBSim's catalogue
    lists it as 'propulsion/engine/thrust-coefficient'. It was refused as undefined."""
    from aerosid.simulation.jsbsim_design import in_catalogue

    cat = {"propulsion/engine/thrust-coefficient", "propulsion/engine[1]/thrust-coefficient"}
    assert in_catalogue("propulsion/engine[0]/thrust-coefficient", cat)
    assert in_catalogue("propulsion/engine[1]/thrust-coefficient", cat)
    assert not in_catalogue("propulsion/engine[2]/thrust-coefficient", cat)
    flight = simulate_jsbsim("J3Cub", seed=0, faults=False)
    assert "propulsion/engine[0]/thrust-coefficient" in AeroTables(flight_design(_import_jsbsim(), "J3Cub")
                                                                   .xml_path).leaf_properties()
    assert np.all(np.isfinite(flight.truth["Cm"].to_numpy(float)))


def test_no_input_socket_is_opened(capfd):
    """737.xml asks JSBSim for TCP and UDP input ports; aerosid's instances never open them
    (before: one bind attempt, and an error line, at every initialisation of the trim)."""
    jsbsim = _import_jsbsim()
    fdm = open_fdm(jsbsim, "737", 0.01)
    fdm.run_ic()
    fdm.run_ic()
    captured = capfd.readouterr()
    assert "input socket" not in captured.out + captured.err


def test_powered_level_flight_gets_a_speed_term_in_cm(written, tmp_path):
    """A jet flown level (T37) holds its speed with thrust; along the phugoid the thrust's moment
    and the Mach effects change with speed in step with alpha, so its default C_m model carries
    Cm_mach, and with it the default model fitted to the noise-free truth finds the at-trim
    C_m,alpha closer than without it.  The glider-like idle descent of pa28 gets no such term."""
    from aerosid.modelling.models import default_models

    assert not any(t.coefficient == "Cm_mach" for t in default_models(load_vehicle(written["vehicle"]))["Cm"].terms)
    jet = simulate_aircraft("T37", seed=0)
    out = jet.write(tmp_path / "T37")
    vehicle = load_vehicle(out["vehicle"])
    model = default_models(vehicle)["Cm"]
    # about the trim Mach (C_m,0 stays the trim's value), in the diagnosis' own spelling of mach_cm0
    term = next(t for t in model.terms if t.coefficient == "Cm_mach")
    assert term.expression.replace(" ", "") == f"(mach-{vehicle.mach_reference:g})"
    # the truth's Cm_mach (the tables' slope alone) is not what this term estimates: named apart
    assert "Cm_mach" not in jet.coefficients and "Cm_mach_aero" in jet.coefficients
    T = jet.truth
    sig = {"alpha": T["alpha_rad"], "mach": T["mach"], "delta_p": T["delta_p_rad"], "q_hat": T["q_hat"],
           "alpha_dot_hat": T["alpha_dot_hat"], "beta": T["beta_rad"]}
    sig = {k: v.to_numpy(float) for k, v in sig.items()}
    X = model.regressors(sig)
    y = (T["Cm"] + T["Cm_prop"]).to_numpy(float)
    truth = jet.coefficients["Cm_alpha"]
    errors = {}
    for with_speed in (True, False):
        cols = [c for c in X.columns if with_speed or c != "Cm_mach"]
        sol = dict(zip(cols, np.linalg.lstsq(X[cols].to_numpy(), y, rcond=None)[0]))
        errors[with_speed] = abs(sol["Cm_alpha"] / truth - 1.0)
    assert errors[True] < 0.5 * errors[False]


def test_jsbsim_output_files_an_aircraft_asks_for_stay_out_of_the_installation():
    """c172x's XML asks for a CSV output file, which JSBSim opens even with its output disabled;
    it must land in the process's scratch folder, never in the jsbsim package (an install folder)."""
    from pathlib import Path

    jsbsim = _import_jsbsim()
    package = Path(jsbsim.get_default_root_dir())
    before = set(package.glob("*.csv"))
    fdm = open_fdm(jsbsim, "c172x", 0.01)
    fdm.run_ic()
    for _ in range(10):
        fdm.run()
    assert Path(str(fdm.get_output_path())).resolve() != package.resolve()
    assert set(package.glob("*.csv")) == before


@pytest.mark.parametrize("aircraft", ["c310", "pa28"])
def test_the_elevator_step_moves_alpha_by_the_designed_amount_in_jsbsim(aircraft):
    """The 3-2-1-1's step is sized to change alpha by ALPHA_STEP_DEG in the steady short period,
    where the vehicle turns at q = -Z_alpha alpha and the pitch damping holds alpha back as well.
    Checked against JSBSim itself: half the design's elevator command held from trim, alpha 2.5 s
    later (the short period settled, the phugoid barely started) is half the step's alpha.  Half,
    because the design is linear and c310 is not beyond that: the full command gives 2.8 deg where
    the linear truth says 1.4 (0.64 at half).  c310 is heavily damped (C_m,q c/(2V) Z_alpha
    1.4 x C_m,alpha): sized on C_m,alpha alone, its step gave 0.3 deg at half command.  Its step is
    capped by the elevator's travel, and the design records the step flown, not the one wanted."""
    from aerosid.simulation.jsbsim_design import ALPHA_STEP_DEG, loaded_fdm
    from aerosid.simulation.jsbsim_trim import initialise
    jsbsim = _import_jsbsim()
    design = flight_design(jsbsim, aircraft)
    want = ALPHA_STEP_DEG
    capped = [n for n in design.notes if n.startswith("pitch: step")]
    if capped:  # "pitch: step X deg limited to Y deg (...)": alpha scales with the surface
        x, y = (float(v) for v in capped[0].split("step ")[1].split(" deg (")[0].split(" deg limited to "))
        want *= y / x
    flown = design.manoeuvre["surface_steps_rad"]["elevator"]
    assert abs(design.manoeuvre["elevator_amplitudes_norm"][0] * design.gains["pitch"]) == pytest.approx(flown, rel=0.01)
    assert bool(capped) == (aircraft == "c310")
    fdm = loaded_fdm(jsbsim, aircraft, ET.parse(design.xml_path).getroot(), design.trim)
    initialise(fdm, design.trim)
    alpha0 = fdm["aero/alpha-deg"]
    fdm["fcs/elevator-cmd-norm"] = design.trim.elevator_cmd + 0.5 * design.manoeuvre["elevator_amplitudes_norm"][0]
    for _ in range(250):
        fdm.run()
    assert abs(fdm["aero/alpha-deg"] - alpha0) == pytest.approx(0.5 * want, rel=0.2)
