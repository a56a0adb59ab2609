"""Output-error refinement (aerosid.identification.output_error) on the independent seed-rlv
simulator's noise-free flight (tests/identification/conftest.py: clean_flight), whose true
linear model the output predictor reproduces to a TIC of 1e-5..5e-5 with held controls."""
import numpy as np
import pytest

from aerosid.identification.output_error import output_error_fit

FREE = ("CN_0", "CN_alpha", "Cm_0", "Cm_alpha", "Cm_delta_p")


@pytest.fixture(scope="module")
def pitch_doublet(clean_flight):
    """The first pitch doublet (t < 17 s) of the clean flight: (vehicle, inputs, measured, true model)."""
    veh, inputs, measured, model = clean_flight
    short = (inputs["t_s"] < 17.0).to_numpy()
    return veh, inputs[short].reset_index(drop=True), measured[short].reset_index(drop=True), model


def test_a_perturbed_start_converges_to_the_true_model(pitch_doublet):
    veh, inputs, measured, model = pitch_doublet
    start = model.with_values(Cm_alpha=1.15 * model.values["Cm_alpha"], Cm_delta_p=0.85 * model.values["Cm_delta_p"],
                              CN_alpha=1.05 * model.values["CN_alpha"])
    fit = output_error_fit(start, inputs, measured, veh, "lon", free=FREE, controls="hold")
    assert fit.converged
    for k in ("CN_alpha", "Cm_alpha", "Cm_delta_p"):
        assert fit.start[k] != pytest.approx(model.values[k], rel=0.04)
        assert fit.estimate[k] == pytest.approx(model.values[k], rel=2e-3), k
    assert max(fit.tic_end.values()) < 1e-3 < min(fit.tic_start[o] for o in ("alpha_rad", "q_rad_s"))
    assert fit.model.values["Cm_alpha"] == fit.estimate["Cm_alpha"]
    # a sum's sigma from the covariance: Var(a + b) = Var a + Var b + 2 Cov(a, b)
    i, j = fit.names.index("Cm_alpha"), fit.names.index("Cm_delta_p")
    est, se = fit.combination({"Cm_alpha": 1.0, "Cm_delta_p": 1.0})
    assert est == pytest.approx(fit.estimate["Cm_alpha"] + fit.estimate["Cm_delta_p"])
    c = fit.covariance
    assert se == pytest.approx(np.sqrt(c[i, i] + c[j, j] + 2 * c[i, j]))
    assert fit.sigma["Cm_alpha"] == pytest.approx(np.sqrt(c[i, i]))
    assert "output error" in fit.summary() and "Cm_delta_p" in fit.summary()


def test_noisy_outputs_truth_inside_the_reported_interval(pitch_doublet):
    """White noise on the measured alpha, q and a_z (0.05 deg, 0.1 deg/s, 0.05 m/s^2): the
    estimates stay unbiased (output noise, not regressor noise) and the 95 % interval from the
    reported sigma holds the truth; the coloured-residual sigma is at least the CRB's."""
    veh, inputs, measured, model = pitch_doublet
    rng = np.random.default_rng(7)
    n = len(measured)
    noisy = measured.assign(alpha_rad=measured["alpha_rad"] + np.radians(0.05) * rng.standard_normal(n),
                            q_rad_s=measured["q_rad_s"] + np.radians(0.1) * rng.standard_normal(n),
                            az_m_s2=measured["az_m_s2"] + 0.05 * rng.standard_normal(n))
    fit = output_error_fit(model, inputs, noisy, veh, "lon", free=FREE, controls="hold")
    lo_hi = fit.conf_int()
    for k in FREE:
        assert lo_hi[k][0] <= model.values[k] <= lo_hi[k][1], (k, fit.estimate[k], fit.sigma[k], model.values[k])
        assert fit.sigma[k] >= 0.7 * fit.sigma_white[k] > 0
    assert fit.noise_std["q_rad_s"] == pytest.approx(np.radians(0.1), rel=0.15)
    assert fit.noise_std["alpha_rad"] == pytest.approx(np.radians(0.05), rel=0.15)


def test_refuses_coefficients_outside_the_axis_and_a_diverging_start(pitch_doublet):
    veh, inputs, measured, model = pitch_doublet
    with pytest.raises(ValueError, match="Cn_beta"):
        output_error_fit(model, inputs, measured, veh, "lon", free=("Cm_alpha", "Cn_beta"))
    with pytest.raises(ValueError, match="not identifiable"):
        output_error_fit(model.with_values(CN_0=float("nan")), inputs, measured, veh, "lon", free=("CN_0",))
    unstable = model.with_values(Cm_alpha=-20.0 * model.values["Cm_alpha"])
    with pytest.raises(ValueError, match="leaves the envelope"):
        output_error_fit(unstable, inputs, measured, veh, "lon", free=FREE, controls="hold")
