"""The flight-averaged linear truth (aerosid.simulation.jsbsim_truth_avg) on known answers:
a synthetic JSBSim model with a piecewise-linear C_m(alpha) table (one segment: equals the
at-trim truth; across a kink: the time-weighted mean of the two slopes; Gaussian
excursions: the least-squares slope, Stein's lemma), and a real JSBSim flight (its first
sample is the trim state: the average over it is the at-trim truth)."""
from __future__ import annotations

import numpy as np
import pytest

from aerosid.simulation.jsbsim_linear import Controls, linear_truth
from aerosid.simulation.jsbsim_tables import AeroTables
from aerosid.simulation.jsbsim_truth_avg import flight_average, generated_state

SLOPE_LO, SLOPE_HI, SLOPE_E = -1.1, -1.7, -0.9   # C_m per rad: alpha < 0, alpha > 0; elevator

XML = f"""<fdm_config name="synthetic">
 <aerodynamics>
  <axis name="DRAG"/> <axis name="SIDE"/> <axis name="ROLL"/> <axis name="YAW"/>
  <axis name="LIFT">
   <function name="aero/force/L"><product><property>aero/qbar-psf</property><property>metrics/Sw-sqft</property>
    <table><independentVar>aero/alpha-rad</independentVar><tableData>
      -0.2 -0.9
       0.0  0.2
       0.2  1.4
    </tableData></table></product></function>
  </axis>
  <axis name="PITCH">
   <function name="aero/moment/Cm_alpha"><product><property>aero/qbar-psf</property><property>metrics/Sw-sqft</property>
    <property>metrics/cbarw-ft</property>
    <table><independentVar>aero/alpha-rad</independentVar><tableData>
      -0.2 {0.05 - 0.2 * SLOPE_LO}
       0.0  0.05
       0.2 {0.05 + 0.2 * SLOPE_HI}
    </tableData></table></product></function>
   <function name="aero/moment/Cm_de"><product><property>aero/qbar-psf</property><property>metrics/Sw-sqft</property>
    <property>metrics/cbarw-ft</property><property>fcs/elevator-pos-rad</property><value>{SLOPE_E}</value></product>
   </function>
  </axis>
 </aerodynamics>
</fdm_config>
"""
CONTROLS = Controls(pitch="fcs/elevator-pos-rad", roll="fcs/aileron-pos-rad", yaw="fcs/rudder-pos-rad",
                    left_aileron=None, right_aileron=None)


@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    path = tmp_path_factory.mktemp("xml") / "synthetic.xml"
    path.write_text(XML)
    return AeroTables(path)


def record(alpha, delta_e) -> dict:
    """A flight's record: the CG at the AERORP (C_m about the CG = the table's C_m)."""
    n = len(alpha)
    const = {"aero/qbar-psf": 80.0, "metrics/Sw-sqft": 170.0, "metrics/cbarw-ft": 5.0, "metrics/bw-ft": 35.0,
             "aero/ci2vel": 0.05, "aero/bi2vel": 0.3, "metrics/aero-rp-x-in": 40.0, "metrics/aero-rp-y-in": 0.0,
             "metrics/aero-rp-z-in": 10.0, "inertia/cg-x-in": 40.0, "inertia/cg-y-in": 0.0, "inertia/cg-z-in": 10.0}
    rec = {k: np.full(n, v) for k, v in const.items()}
    rec.update({"aero/alpha-rad": np.asarray(alpha, float), "aero/beta-rad": np.zeros(n),
                "fcs/elevator-pos-rad": np.asarray(delta_e, float), "fcs/aileron-pos-rad": np.zeros(n),
                "fcs/rudder-pos-rad": np.zeros(n), "velocities/p-aero-rad_sec": np.zeros(n),
                "velocities/q-aero-rad_sec": np.zeros(n), "velocities/r-aero-rad_sec": np.zeros(n),
                "aero/alphadot-rad_sec": np.zeros(n)})
    return rec


def test_inside_one_table_segment_the_average_is_the_at_trim_truth(tables):
    rng = np.random.default_rng(1)
    alpha = rng.uniform(0.01, 0.19, 500)   # all above the breakpoint at 0
    rec = record(alpha, rng.normal(0.0, 0.05, 500))
    avg = flight_average(*generated_state(tables, rec, CONTROLS))
    trim = {k: float(v[0]) for k, v in rec.items()}
    at_trim, _, _ = linear_truth(tables, trim, CONTROLS)
    for name in ("Cm_alpha", "Cm_delta_p", "Cm_q", "CN_delta_p"):
        assert avg[name] == pytest.approx(at_trim[name], rel=1e-6, abs=1e-9), name
    assert avg["Cm_alpha"] == pytest.approx(SLOPE_HI, rel=1e-6)
    assert avg["Cm_delta_p"] == pytest.approx(SLOPE_E, rel=1e-6)
    # the intercept of the averaged table: the segment's line through alpha = 0
    assert avg["Cm_0"] == pytest.approx(0.05, abs=1e-9)


def test_across_a_kink_the_average_weights_the_slopes_by_the_time_on_each_segment(tables):
    alpha = np.concatenate([np.linspace(-0.15, -0.01, 300), np.linspace(0.01, 0.1, 100)])
    rec = record(alpha, np.zeros_like(alpha))
    avg = flight_average(*generated_state(tables, rec, CONTROLS))
    assert avg["Cm_alpha"] == pytest.approx(0.75 * SLOPE_LO + 0.25 * SLOPE_HI, rel=1e-6)
    trim = {k: float(v[0]) for k, v in rec.items()}   # a trim point below the kink sees one slope only
    assert linear_truth(tables, trim, CONTROLS)[0]["Cm_alpha"] == pytest.approx(SLOPE_LO, rel=1e-6)


def test_for_gaussian_excursions_the_average_is_the_least_squares_slope(tables):
    """Stein's lemma: E[x f(x)] = sigma^2 E[f'(x)] for Gaussian x, so the least-squares slope
    of a linear model fitted to the flight is the averaged derivative (here with two
    correlated regressors: alpha and the elevator)."""
    rng = np.random.default_rng(7)
    n = 200_000
    cov = np.array([[0.06 ** 2, -0.5 * 0.06 * 0.04], [-0.5 * 0.06 * 0.04, 0.04 ** 2]])
    alpha, de = rng.multivariate_normal([-0.02, 0.01], cov, n).T
    rec = record(alpha, de)
    evaluate, x = generated_state(tables, rec, CONTROLS)
    avg = flight_average(evaluate, x)
    cm = evaluate(x)["Cm"]
    X = np.column_stack([np.ones(n), alpha, de])
    sol, *_ = np.linalg.lstsq(X, cm, rcond=None)
    # the averaged slope lies strictly between the segment slopes, and the fit finds it
    assert SLOPE_HI < avg["Cm_alpha"] < SLOPE_LO
    assert sol[1] == pytest.approx(avg["Cm_alpha"], rel=5e-3)
    assert sol[2] == pytest.approx(avg["Cm_delta_p"], rel=5e-3)


def test_a_state_without_a_variable_is_refused(tables):
    rec = record(np.zeros(3), np.zeros(3))
    evaluate, x = generated_state(tables, rec, CONTROLS)
    del x["q_hat"]
    with pytest.raises(ValueError, match="q_hat"):
        flight_average(evaluate, x)


def test_a_real_flight_at_its_trim_sample_gives_the_at_trim_truth(monkeypatch):
    """pa28 (JSBSim): the model re-evaluated at every recorded state is JSBSim's own
    coefficients, and the average over the first sample (the trim state) is the at-trim
    truth."""
    pytest.importorskip("jsbsim")
    import aerosid.simulation.jsbsim_aircraft as ja
    import aerosid.simulation.jsbsim_truth_avg as avg_mod
    from aerosid.simulation.jsbsim_flight import simulate_jsbsim

    seen = {}

    def spy(*args):
        seen["args"] = args
        return avg_mod.generated_flight_average(*args)

    monkeypatch.setattr(ja, "generated_flight_average", spy)
    flight = simulate_jsbsim("pa28", "3211", 0, faults=False)
    tables, rec, controls, gains = seen["args"]
    evaluate, x = generated_state(tables, rec, controls, gains, steady_cl_squared=False)
    c = evaluate(x)
    for k in ("CN", "Cm", "Cl", "Cn"):
        assert np.max(np.abs(c[k] - flight.truth[k].to_numpy())) < 1e-9, k
    first = flight_average(*generated_state(tables, {k: np.asarray(v)[:1] for k, v in rec.items()}, controls, gains))
    for name in ("Cm_alpha", "Cm_delta_p", "Cm_q", "CN_alpha", "Cl_p", "Cn_beta", "Cn_r"):
        assert first[name] == pytest.approx(flight.coefficients[name], rel=1e-6), name
    table = flight.info["coefficients_flight_average"]
    assert table["CN_alpha"] != flight.coefficients["CN_alpha"]   # the flight leaves the trim segment
    assert table["CN_alpha"] == pytest.approx(flight.coefficients["CN_alpha"], rel=0.02)
