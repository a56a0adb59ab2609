"""Output prediction (aerosid.identification.output_prediction) against an independent
simulator: the seed-rlv 6-DOF model (quaternions, its own aerodynamic model, centrifugal
relief) flies a noise-free flight; driven by that flight's controls, airspeed, dynamic
pressure and attitude, the TRUE linear model must reproduce alpha, q, a_z (beta, p, r,
a_y) to a TIC near 0, and a perturbed coefficient must not."""
import numpy as np
import pytest

from aerosid.identification.output_prediction import predict_axis, theil_inequality


def _tics(pred):
    f = pred.frame
    return {o: theil_inequality(f[f"measured_{o}"], f[f"predicted_{o}"]) for o in pred.outputs}


def test_theil_inequality_closed_forms():
    y = np.sin(np.linspace(0, 10, 200)) + 0.3
    assert theil_inequality(y, y) == 0.0
    assert theil_inequality(y, -y) == pytest.approx(1.0)
    assert theil_inequality(y, np.zeros_like(y)) == pytest.approx(1.0)
    assert theil_inequality(y, 2 * y) == pytest.approx(1 / 3)  # |y| / (|y| + 2|y|)


@pytest.mark.parametrize("axis", ["lon", "lat"])
def test_true_model_reproduces_the_independent_simulation(clean_flight, axis):
    veh, inputs, measured, model = clean_flight
    # the simulator holds its fins over each step: with the same hold the remaining error is
    # the integration and the linear model's approximations of the resultant-plane aerodynamics
    # (alpha ~ alpha_r cos(phi_r); in roll, cos(4 phi_r) with phi_r = atan2(tan beta, tan alpha)
    # amplifying beta's error): lon 1e-5..5e-5, lat 4e-4..3e-3 (p)
    tics = _tics(predict_axis(model, inputs, measured, veh, axis, bias="none", controls="hold"))
    assert max(tics.values()) < {"lon": 1e-3, "lat": 4e-3}[axis], tics
    # with the controls interpolated linearly (real data), the half-step shift costs a little (most in
    # the fast roll axis)
    tics = _tics(predict_axis(model, inputs, measured, veh, axis, bias="none", controls="linear"))
    assert max(tics.values()) < 0.05, tics


@pytest.mark.parametrize("axis, coefficient, outputs", [("lon", "Cm_alpha", ("alpha_rad", "q_rad_s", "az_m_s2")),
                                                        ("lon", "Cm_delta_p", ("q_rad_s",)),
                                                        ("lat", "Cn_beta", ("beta_rad", "r_rad_s", "ay_m_s2"))])
def test_a_perturbed_coefficient_raises_the_tic(clean_flight, axis, coefficient, outputs):
    veh, inputs, measured, model = clean_flight
    base = _tics(predict_axis(model, inputs, measured, veh, axis, bias="none", controls="hold"))
    wrong = model.with_values(**{coefficient: 1.2 * model.values[coefficient]})
    tics = _tics(predict_axis(wrong, inputs, measured, veh, axis, bias="none", controls="hold"))
    for o in outputs:
        assert tics[o] > 0.03 and tics[o] > 20 * base[o], (o, base[o], tics[o])


def test_output_offsets_remove_a_constant_sensor_bias(clean_flight):
    veh, inputs, measured, model = clean_flight
    biased = measured.assign(q_rad_s=measured["q_rad_s"] + 0.01, az_m_s2=measured["az_m_s2"] - 0.5)
    raw = predict_axis(model, inputs, biased, veh, "lon", bias="none", controls="hold")
    fixed = predict_axis(model, inputs, biased, veh, "lon", bias="offsets", controls="hold")
    assert _tics(raw)["q_rad_s"] > 0.1
    assert max(_tics(fixed).values()) < 0.003
    assert fixed.frame["offset_q_rad_s"].iloc[0] == pytest.approx(0.01, abs=2e-4)
    assert fixed.frame["offset_az_m_s2"].iloc[0] == pytest.approx(-0.5, abs=0.02)


def test_intercepts_are_re_estimated_by_output_error(clean_flight):
    veh, inputs, measured, model = clean_flight
    short = inputs["t_s"] < 17.0  # the first pitch doublet: enough to pin two intercepts, fast
    inp, meas = inputs[short].reset_index(drop=True), measured[short].reset_index(drop=True)
    truth = {k: model.values[k] for k in ("CN_0", "Cm_0")}
    wrong = model.with_values(CN_0=truth["CN_0"] + 0.004, Cm_0=truth["Cm_0"] + 0.002)
    pred = predict_axis(wrong, inp, meas, veh, "lon", bias="intercepts", controls="hold")
    assert pred.intercepts["Cm_0"][0] == pytest.approx(truth["Cm_0"] + 0.002)
    assert pred.intercepts["Cm_0"][1] == pytest.approx(truth["Cm_0"], abs=1e-4)
    assert pred.intercepts["CN_0"][1] == pytest.approx(truth["CN_0"], abs=5e-4)
    assert max(_tics(pred).values()) < 0.003
