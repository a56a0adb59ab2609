"""The prior on the pitch-damping split (aerosid.identification.damping_prior): the update is the
exact posterior (closed form against the augmented least squares), it only constrains the split,
a flight that determines the split keeps its own answer, and the posterior intervals cover a
truth inside the prior's range on a design where the flight cannot split the damping."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from aerosid.identification.damping_prior import PRIOR_SHARE, PRIOR_SHARE_SIGMA, damping_terms, split_update
from aerosid.identification.prior_structure import with_pitch_damping_prior, with_structure_uncertainty
from aerosid.identification.regression import fit_linear
from aerosid.modelling.models import default_models
from aerosid.vehicles.vehicle import VehicleError, load_vehicle

# columns: 1, alpha, q_hat, alpha_dot_hat; truth: C_m,q + C_m,alpha_dot = -20, split f = 0.3
TRUTH = np.array([0.01, -0.8, -14.0, -6.0])
IQ, IA, IALPHA = 2, 3, 1


def _design(rng, n: int, collinear: float):
    """alpha_dot_hat = q_hat - k alpha + collinear x independent part (small: the flight cannot split)."""
    alpha = 0.02 * np.sin(np.linspace(0, 40, n)) + 0.005 * rng.normal(size=n)
    q_hat = 0.002 * np.cos(np.linspace(0, 40, n) + 0.3) + 0.0005 * rng.normal(size=n)
    adot_hat = q_hat - 0.01 * alpha + collinear * 0.002 * rng.normal(size=n)
    return np.column_stack([np.ones(n), alpha, q_hat, adot_hat])


def _ols(X, y):
    theta = np.linalg.lstsq(X, y, rcond=None)[0]
    e = y - X @ theta
    s2 = e @ e / (len(y) - X.shape[1])
    return theta, s2 * np.linalg.inv(X.T @ X)


def _flight(seed: int, n: int, collinear: float, noise: float, truth=TRUTH):
    """(X, theta, P): a seeded design, the response with white noise, its least-squares fit."""
    rng = np.random.default_rng(seed)
    X = _design(rng, n, collinear)
    theta, P = _ols(X, X @ truth + noise * rng.normal(size=n))
    return X, theta, P


def _damping_and_split_rows():
    """(w, r): the total damping C_m,q + C_m,alpha_dot and the prior's row, on the 4 columns."""
    w = np.zeros(4)
    w[IQ] = w[IA] = 1.0
    r = np.zeros(4)
    r[IQ], r[IA] = -PRIOR_SHARE, 1 - PRIOR_SHARE
    return w, r


def test_the_update_is_the_least_squares_with_the_prior_as_one_more_weighted_row():
    X, theta, P = _flight(0, 800, 0.05, 2e-3)
    upd = split_update(theta, P, IQ, IA)
    # the same posterior from the normal equations of the data and the prior row r theta = 0
    w, r = _damping_and_split_rows()
    s2 = PRIOR_SHARE_SIGMA ** 2 * ((theta[IQ] + theta[IA]) ** 2 + w @ P @ w)
    info = np.linalg.inv(P) + np.outer(r, r) / s2
    post_cov = np.linalg.inv(info)
    post = post_cov @ (np.linalg.inv(P) @ theta)
    assert np.allclose(upd.estimate, post, rtol=1e-8, atol=1e-12)
    assert np.allclose(upd.cov, post_cov, rtol=1e-8, atol=1e-14)
    # information only added: the posterior covariance is below the flight's (P - P_post >= 0)
    assert np.linalg.eigvalsh(P - upd.cov).min() > -1e-12 * np.abs(P).max()


def test_the_prior_constrains_the_split_not_the_total_damping():
    X, theta, P = _flight(1, 800, 0.002, 5e-3)
    upd = split_update(theta, P, IQ, IA)
    w, _ = _damping_and_split_rows()
    sd_damping = np.sqrt(w @ P @ w)
    # the total moves by a small part of its own sigma; the split moves to the prior's share
    assert abs(w @ upd.estimate - w @ theta) < 0.5 * sd_damping
    assert upd.share_data_sigma > 2 * PRIOR_SHARE_SIGMA  # this flight cannot split the damping
    assert abs(upd.share_post - PRIOR_SHARE) < 0.05


def test_a_flight_that_splits_the_damping_keeps_its_own_answer():
    rng = np.random.default_rng(2)
    X = _design(rng, 20000, 5.0)  # alpha_dot_hat largely independent of q_hat and alpha
    y = X @ TRUTH + 2e-3 * rng.normal(size=len(X))
    theta, P = _ols(X, y)
    upd = split_update(theta, P, IQ, IA)
    assert upd.share_data_sigma < 0.05 * PRIOR_SHARE_SIGMA
    assert abs(upd.share_post - upd.share_data) < 0.01
    assert np.all(np.abs(upd.estimate - theta) < 0.05 * np.sqrt(np.diag(P)))


def test_posterior_intervals_cover_a_truth_inside_the_prior_and_are_narrower_where_the_flight_cannot_split():
    """200 seeded flights that cannot split the damping, truth f = 0.3 (inside the prior): the
    posterior's 95 % interval of C_m,alpha covers in >= 90 % and is under half the flight's own."""
    cover, ratio = 0, []
    n_runs = 200
    for seed in range(n_runs):
        rng = np.random.default_rng(100 + seed)
        X = _design(rng, 600, 0.002)
        y = X @ TRUTH + 5e-3 * rng.normal(size=len(X))
        theta, P = _ols(X, y)
        upd = split_update(theta, P, IQ, IA)
        sd = np.sqrt(np.diag(upd.cov))
        cover += abs(upd.estimate[IALPHA] - TRUTH[IALPHA]) <= 1.96 * sd[IALPHA]
        ratio.append(sd[IALPHA] / np.sqrt(P[IALPHA, IALPHA]))
    assert cover >= 0.9 * n_runs
    assert np.median(ratio) < 0.5


def test_a_flight_whose_split_information_is_noise_gets_the_priors_uncertainty_not_a_new_estimate():
    """reliability (the signal's share of the flight's information on the split): 1 is the plain
    update bit for bit; below 1 the estimate stays and the variance of r theta becomes
    1 / (reliability / v + 1 / s2) (0: the prior's s2 alone), every sigma growing as it falls and
    the other coefficients following the given coupling."""
    X, theta, P = _flight(3, 800, 0.5, 2e-3)
    w, r = _damping_and_split_rows()
    s2 = PRIOR_SHARE_SIGMA ** 2 * ((theta[IQ] + theta[IA]) ** 2 + w @ P @ w)
    v = r @ P @ r
    plain = split_update(theta, P, IQ, IA)
    same = split_update(theta, P, IQ, IA, reliability=1.0)
    assert np.array_equal(same.estimate, plain.estimate) and np.array_equal(same.cov, plain.cov)
    assert "information on the split is signal" not in plain.summary()
    coupling = np.array([0.0, 0.01, -1.0, 1.0])  # alpha follows alpha-dot, q compensates
    for c in (None, coupling):
        sd_before = np.sqrt(np.diag(plain.cov))
        for rel in (0.5, 0.1, 0.0):
            upd = split_update(theta, P, IQ, IA, reliability=rel, coupling=c)
            assert np.array_equal(upd.estimate, plain.estimate)
            assert abs(r @ upd.cov @ r / (1.0 / (rel / v + 1.0 / s2)) - 1) < 1e-9
            sd = np.sqrt(np.diag(upd.cov))
            assert np.all(sd >= sd_before * (1 - 1e-12))  # every sigma grows as the reliability falls
            assert sd[IA] > 1.01 * sd_before[IA]
            assert upd.reliability == rel
            assert f"only {rel:.0%} of this flight's information on the split is signal" in upd.summary()
            sd_before = sd
    # a coupling (nearly) orthogonal to r falls back to the posterior's own direction
    along_r_free = np.array([0.0, 1.0, 1.0 - PRIOR_SHARE, PRIOR_SHARE])  # r . c = 0
    fallback = split_update(theta, P, IQ, IA, reliability=0.0, coupling=along_r_free)
    assert np.allclose(fallback.cov, split_update(theta, P, IQ, IA, reliability=0.0).cov, rtol=1e-12)
    # with the coupling, the extra variance lies along it: C_m,alpha's grows by 0.01^2 x the extra
    upd = split_update(theta, P, IQ, IA, reliability=0.0, coupling=coupling)
    extra = s2 - plain.cov.dot(r).dot(r)
    g = coupling / (r @ coupling)
    assert np.allclose(upd.cov - plain.cov, extra * np.outer(g, g), rtol=1e-9, atol=1e-18)


def test_the_share_sigma_is_the_delta_method_of_the_fit_covariance():
    """Against a Monte-Carlo of the share over draws from the fit's own Gaussian."""
    X, theta, P = _flight(4, 4000, 2.0, 2e-3)
    upd = split_update(theta, P, IQ, IA)
    draws = np.random.default_rng(40).multivariate_normal(theta, P, size=20000)
    shares = draws[:, IA] / (draws[:, IQ] + draws[:, IA])
    assert abs(upd.share_data - theta[IA] / (theta[IQ] + theta[IA])) < 1e-12
    assert abs(upd.share_data_sigma / np.std(shares) - 1) < 0.05


def test_a_term_written_with_a_factor_takes_the_prior_on_the_derivative_not_the_coefficient():
    """A model term 2*q_hat has C_m,q = 2 x its coefficient: the posterior share is the same as
    with q_hat."""
    X, _, _ = _flight(5, 800, 0.002, 5e-3)
    y = X @ TRUTH + 5e-3 * np.random.default_rng(50).normal(size=len(X))
    theta, P = _ols(X, y)
    X2 = X.copy()
    X2[:, IQ] *= 2.0  # the same flight, its q column written as 2*q_hat
    theta2, P2 = _ols(X2, y)
    a = split_update(theta, P, IQ, IA)
    b = split_update(theta2, P2, IQ, IA, factors=(2.0, 1.0))
    assert abs(a.share_post - b.share_post) < 1e-9
    assert np.isclose(a.share_data_sigma, b.share_data_sigma, rtol=1e-9)
    assert np.allclose(b.estimate[IQ] * 2.0, a.estimate[IQ]) and np.allclose(b.estimate[IA], a.estimate[IA])


def test_a_term_without_an_estimate_is_kept_and_the_others_take_the_prior():
    """The term without an estimate comes first, so the damping terms' places in the finite block
    differ from their places in the fit."""
    X, theta, P = _flight(6, 800, 0.002, 5e-3)
    th5 = np.insert(theta, 0, np.nan)
    P5 = np.full((5, 5), np.nan)
    P5[1:, 1:] = P
    full = split_update(theta, P, IQ, IA)
    part = split_update(th5, P5, IQ + 1, IA + 1)
    assert np.allclose(part.estimate[1:], full.estimate) and np.isnan(part.estimate[0])
    assert np.allclose(part.cov[1:, 1:], full.cov) and np.isnan(part.cov[0, 0])
    assert np.isclose(part.share_post, full.share_post)


def test_a_damping_estimated_as_zero_still_gets_a_prior_as_wide_as_its_own_uncertainty():
    """The prior's variance is sigma_f^2 (D^2 + var D): at D = 0 the split is held to +- sigma_f x
    sigma_D, not pinned (the posterior variance of r theta is the harmonic combination)."""
    X, theta, P = _flight(8, 800, 0.002, 5e-3)
    theta = theta.copy()
    theta[IA] = -theta[IQ]  # an estimated damping of exactly zero
    upd = split_update(theta, P, IQ, IA)
    w, r = _damping_and_split_rows()
    s2 = PRIOR_SHARE_SIGMA ** 2 * (w @ P @ w)
    v = r @ P @ r
    assert np.isclose(r @ upd.cov @ r, v * s2 / (v + s2), rtol=1e-8)
    assert r @ upd.cov @ r > 0.5 * s2


def test_why_the_prior_cannot_be_applied_is_said():
    P = np.eye(4)
    assert "zero" in split_update(np.array([0.0, -1.0, 5.0, -5.0]), np.diag([1.0, 1.0, 0.0, 0.0]), IQ, IA)
    assert "finite" in split_update(np.array([0.0, -1.0, np.nan, -5.0]), P, IQ, IA)


def test_the_damping_terms_are_found_in_any_spelling_and_only_when_pure():
    assert damping_terms(["1", "alpha", "q_hat", "alpha_dot_hat"]) == ((2, 1.0), (3, 1.0))
    assert damping_terms(["1", "(q_hat)", "2*alpha_dot_hat"]) == ((1, 1.0), (2, 2.0))
    assert damping_terms(["1", "alpha*q_hat", "alpha_dot_hat"]) is None
    assert damping_terms(["1", "q_hat", "q_hat/2", "alpha_dot_hat"]) is None  # two q_hat terms: which?


def _c172x_flight(alpha_dot_truth: float = -6.0, seed: int = 7, collinear: float = 0.002):
    """(vehicle, models, fits, regressors, response): c172x's default models and a C_m fit on a
    synthetic design with its six terms (C_m,alpha_dot's truth and independence as given)."""
    veh = load_vehicle("c172x")
    models = default_models(veh)
    rng = np.random.default_rng(seed)
    n = 1500
    X = _design(rng, n, collinear)
    cols = np.column_stack([X[:, 0], X[:, 1], 0.01 * rng.normal(size=n), X[:, 2], X[:, 3],
                            np.abs(0.01 * rng.normal(size=n))])
    names = models["Cm"].names
    truth = np.array([0.01, -0.8, -1.2, -14.0, alpha_dot_truth, 0.0])
    y = cols @ truth + 5e-3 * rng.normal(size=n)
    fit = fit_linear(y, pd.DataFrame(cols, columns=names), names=names, channel="Cm", cov="ols")
    return veh, models, {"Cm": fit}, cols, y


class _Fixed:
    """A channel model whose regressors() are given columns (what the mixture refits)."""

    def __init__(self, model, cols):
        self.terms, self._frame = model.terms, pd.DataFrame(cols, columns=model.names)

    def regressors(self, _signals):
        return self._frame


@pytest.fixture(scope="module")
def c172x_fits():
    return _c172x_flight()[:3]


def test_identify_combines_the_prior_into_an_aircrafts_pitch_fit_and_says_so(c172x_fits):
    veh, models, fits = c172x_fits
    out, covered = with_pitch_damping_prior(veh, models, fits)
    assert covered == {"Cm": ("Cm_q", "Cm_alpha_dot")}
    f = out["Cm"]
    assert not np.allclose(f.estimate, fits["Cm"].estimate)
    assert any("pitch-damping split" in w for w in f.warnings)
    assert np.all(f.std_error <= fits["Cm"].std_error * (1 + 1e-12))


def test_identify_widens_the_split_where_the_angle_noise_supplies_its_information():
    """A fit whose errors-in-variables correction says the noise-free alpha_dot_hat column carries
    almost no information of its own (X^T X extrapolated to no noise: 5 % of the alpha-dot
    column's independent part is signal, the rest noise): the estimates are the plain prior's,
    C_m,alpha's sigma grows, and the fit says so."""
    # alpha_dot_hat's independent part (collinear 0.5) looks like information: it is mostly noise
    veh, models, fits, X, _ = _c172x_flight(collinear=0.5)
    names = list(fits["Cm"].names)
    ia, iq, ialpha = names.index("Cm_alpha_dot"), names.index("Cm_q"), names.index("Cm_alpha")
    G = X.T @ X
    clean = G.copy()
    own = X[:, ia] - (X[:, iq] - 0.01 * X[:, ialpha])  # alpha_dot_hat's independent part: 5 % of it signal
    a = X[:, iq] - 0.01 * X[:, ialpha] + 0.05 * own
    clean[ia, :] = clean[:, ia] = X.T @ a
    clean[ia, ia] = a @ a
    plain, _ = with_pitch_damping_prior(veh, models, fits)
    noisy = {"Cm": replace(fits["Cm"], information_eiv=(G, clean))}
    out, covered = with_pitch_damping_prior(veh, models, noisy)
    f = out["Cm"]
    assert covered == {"Cm": ("Cm_q", "Cm_alpha_dot")}
    assert np.allclose(f.estimate, plain["Cm"].estimate, rtol=1e-12, atol=0)
    assert f.std_error[ialpha] > 2 * plain["Cm"].std_error[ialpha]
    assert any("of this flight's information on the split is signal" in w for w in f.warnings)
    assert not any("information on the split is signal" in w for w in plain["Cm"].warnings)


def test_the_vehicle_file_sets_its_own_prior_or_turns_it_off(c172x_fits):
    veh, models, fits = c172x_fits
    assert with_pitch_damping_prior(replace(veh, pitch_damping_split=False), models, fits) == (fits, {})
    own = with_pitch_damping_prior(replace(veh, pitch_damping_split=(0.0, 0.05)), models, fits)[0]["Cm"]
    names = list(own.names)
    share = own.estimate[names.index("Cm_alpha_dot")] / (own.estimate[names.index("Cm_q")]
                                                         + own.estimate[names.index("Cm_alpha_dot")])
    assert abs(share) < 0.1
    # a finned vehicle (no downwash lag to speak of) is left alone
    assert with_pitch_damping_prior(replace(veh, vehicle_class="finned"), models, fits) == (fits, {})


def test_the_structure_mixture_leaves_the_split_to_the_prior():
    """C_m,alpha_dot's posterior interval holds 0 here; the mixture would add the model without it
    (f = 0), which the prior already holds: covered terms are left out, so C_m,alpha keeps the
    posterior's sigma."""
    veh, models, fits, cols, y = _c172x_flight()
    post, covered = with_pitch_damping_prior(veh, models, fits)
    f = post["Cm"]
    ia, jalpha = f.names.index("Cm_alpha_dot"), f.names.index("Cm_alpha")
    lo, hi = f.conf_int()[ia]
    assert lo < 0 < hi
    fd, fixed = pd.DataFrame({"Cm": y}), {"Cm": _Fixed(models["Cm"], cols)}
    mixed = with_structure_uncertainty(fd, {}, fixed, post, {}, None)["Cm"]
    kept = with_structure_uncertainty(fd, {}, fixed, post, {}, covered)["Cm"]
    assert mixed.std_error[jalpha] > 1.5 * f.std_error[jalpha]  # what double counting would do
    assert kept.std_error[jalpha] == f.std_error[jalpha]


def test_a_wrong_sign_alpha_dot_the_flight_pins_down_still_takes_the_mixture():
    """A positive C_m,alpha_dot the flight determines (the vane-noise case of pa28) is the data's,
    not the prior's: its wrong-sign mark (taken before the prior) still widens its partners."""
    from aerosid.identification.prior_structure import wrong_sign_terms

    veh, models, fits, cols, y = _c172x_flight(alpha_dot_truth=+5.0, seed=9, collinear=0.1)
    flagged = wrong_sign_terms(models, fits)
    assert "Cm_alpha_dot" in flagged
    post, covered = with_pitch_damping_prior(veh, models, fits)
    fd, fixed = pd.DataFrame({"Cm": y}), {"Cm": _Fixed(models["Cm"], cols)}
    out = with_structure_uncertainty(fd, {}, fixed, post, flagged, covered)["Cm"]
    j = out.names.index("Cm_alpha")
    assert out.std_error[j] > 1.5 * post["Cm"].std_error[j]
    assert any("positive at 95 %" in w for w in out.warnings)


def test_a_bad_setting_in_the_vehicle_file_names_the_key(tmp_path):
    text = open(load_vehicle("c172x").source).read()
    assert "\n[estimation]" not in text
    p = tmp_path / "vehicle.toml"
    p.write_text(text + "\n[estimation]\npitch_damping_split = [0.25]\n")
    with pytest.raises(VehicleError, match="pitch_damping_split.*true, false or 2 numbers"):
        load_vehicle(p)
    p.write_text(text + "\n[estimation]\npitch_damping_split = [0.25, 0.0]\n")
    with pytest.raises(VehicleError, match="pitch_damping_split.*sigma must be positive"):
        load_vehicle(p)
    p.write_text(text + "\n[estimation]\npitch_damping_split = false\n")
    assert load_vehicle(p).pitch_damping_split is False
    p.write_text(text + "\n[estimation]\npitch_damping_split = [0.1, 0.3]\n")
    v = load_vehicle(p)
    assert v.pitch_damping_split == (0.1, 0.3) and "pitch_damping_split" not in v.estimation
