"""SIMEX correction for vane noise (aerosid.identification.eiv): a known slope attenuated by noise in its
regressor is recovered; without noise the correction changes nothing."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from aerosid.identification import eiv
from aerosid.identification.eiv import CORRECTION_SHARE, filtered_noise, simex_estimates


def _frame(alpha: np.ndarray, t: np.ndarray) -> pd.DataFrame:
    return pd.DataFrame({"t_s": t, "flight": "f", "segment": "s0", "alpha_rad": alpha, "beta_rad": 0.0 * alpha,
                         "alpha_r_rad": np.abs(alpha), "phi_r_rad": 0.0 * alpha})


def _design(frame: pd.DataFrame) -> dict:
    a = frame["alpha_rad"].to_numpy()
    return {"Cm": np.column_stack([np.ones_like(a), a])}


@pytest.mark.parametrize("sigma", [0.02, 0.03])
def test_simex_recovers_a_slope_attenuated_by_filtered_vane_noise(sigma):
    rng = np.random.default_rng(0)
    t = np.arange(6000) * 0.01
    alpha = 0.01 * np.sin(2 * np.pi * 0.3 * t) + 0.006 * np.sin(2 * np.pi * 0.9 * t + 1.0)
    y = 0.1 - 1.8 * alpha + 1e-4 * rng.standard_normal(t.size)
    measured = alpha + filtered_noise(rng, np.zeros(t.size), t, sigma, 2.0)
    fd = _frame(measured, t)
    naive = np.linalg.lstsq(_design(fd)["Cm"], y, rcond=None)[0][1]
    res = simex_estimates(fd, {"Cm": y}, _design, sigma, 2.0)["Cm"]
    corrected = res.corrected[1]
    assert naive > -1.8 * 0.9  # attenuated by the noise (the test can fail)
    assert abs(corrected / -1.8 - 1) < 0.4 * abs(naive / -1.8 - 1)  # most of the attenuation removed
    # the corrected sigma grows with the correction and covers what is left of the bias
    se = res.std_error(np.array([0.0, 1e-6]), correction_share=CORRECTION_SHARE["vanes"])
    assert abs(corrected + 1.8) <= 2.5 * se[1]


def test_simex_sigma_counts_what_the_quadratic_leaves_of_a_large_attenuation():
    """Vane noise as large as the excursion (naive slope attenuated by about 55 %), six seeds:
    the quadratic extrapolant takes back only part of it, so the truth lies further than
    1.96 x the quadratic-vs-linear spread from the corrected slope on several seeds (the old
    sigma missed); the sigma that counts the correction's own error (the vanes' CORRECTION_SHARE x
    |corrected - naive|) covers it on every seed."""

    t = np.arange(6000) * 0.01
    alpha = 0.01 * np.sin(2 * np.pi * 0.3 * t) + 0.006 * np.sin(2 * np.pi * 0.9 * t + 1.0)
    old_missed, new_z = 0, []
    for seed in range(6):
        rng = np.random.default_rng(seed)
        y = 0.1 - 1.8 * alpha + 1e-4 * rng.standard_normal(t.size)
        fd = _frame(alpha + filtered_noise(rng, np.zeros(t.size), t, 0.05, 2.0), t)
        res = simex_estimates(fd, {"Cm": y}, _design, 0.05, 2.0)["Cm"]
        naive, corrected = res.naive[1], res.corrected[1]
        assert naive > -1.8 * 0.6 and corrected < naive  # attenuated by > 40 %; corrected the right way
        se = res.std_error(np.array([0.0, 1e-6]), correction_share=CORRECTION_SHARE["vanes"])[1]
        assert se >= CORRECTION_SHARE["vanes"] * abs(corrected - naive) - 1e-12
        old_missed += abs(corrected + 1.8) > 1.96 * res.spread[1]
        new_z.append(abs(corrected + 1.8) / se)
    assert old_missed >= 2  # the spread alone misses (3 of the 6 when written)
    assert max(new_z) <= 1.96  # the new sigma covers every seed (largest z 1.69 when written)


def test_the_correction_share_follows_the_angle_source():
    """Vanes 1, angles inverted from the force database 0.6 (eiv.CORRECTION_SHARE), the rates'
    noise alone the vanes' share; a source nobody measured is refused, not given a share."""
    from types import SimpleNamespace

    from aerosid.identification.eiv_fit import correction_share

    assert correction_share(SimpleNamespace(air_data_source="vanes")) == 1.0
    assert correction_share(SimpleNamespace(air_data_source="database")) == 0.6
    assert correction_share(SimpleNamespace(air_data_source="database"), angles=False) == 1.0
    with pytest.raises(KeyError):
        correction_share(SimpleNamespace(air_data_source="laser"))


def test_simex_without_noise_changes_nothing():
    t = np.arange(3000) * 0.01
    alpha = 0.01 * np.sin(2 * np.pi * 0.3 * t)
    y = 0.1 - 1.8 * alpha
    out = simex_estimates(_frame(alpha, t), {"Cm": y}, _design, 0.0, 2.0)["Cm"]
    assert out.corrected == pytest.approx([0.1, -1.8], rel=1e-9)
    assert out.std_error(np.array([1e-3, 2e-3]), correction_share=1.0) == pytest.approx([1e-3, 2e-3], rel=1e-6)



def test_simex_draws_come_in_antithetic_pairs_common_to_every_lambda():
    """simex_frames: pair k moves alpha, beta and the rates by +sqrt(lambda) d_k and -sqrt(lambda) d_k,
    with the same d_k at every lambda (common random numbers), REPLICATES frames per lambda; the
    angles' draws are the same with or without the rates' (their own generators); fd is untouched."""
    from aerosid.identification.eiv import LAMBDAS, REPLICATES, SEED, simex_frames

    t = np.arange(2000) * 0.01
    alpha = 0.01 * np.sin(2 * np.pi * 0.3 * t)
    q = 0.02 * np.sin(2 * np.pi * 0.5 * t)
    fd = _rate_frame(t, q, alpha)
    before = fd.copy()
    cols = ("alpha_rad", "beta_rad", "q_rad_s")
    sig = np.full(t.size, 0.01)
    with_rates = list(simex_frames(fd, 0.02, 2.0, (0 * sig, sig, 0 * sig), 2.0))
    angles_only = list(simex_frames(fd, 0.02, 2.0))
    pd.testing.assert_frame_equal(fd, before)
    for (lam, f), (lam2, g) in zip(with_rates, angles_only):
        assert lam == lam2
        for col in ("alpha_rad", "beta_rad"):
            np.testing.assert_array_equal(f[col].to_numpy(), g[col].to_numpy())
    # no seed's rate draws are the next seed's angle draws (the rates' generator is (seed, k, 1); with
    # (seed + 1, k) q's draw, the second from its stream after p's, was the next seed's beta draw)
    q_move = with_rates[0][1]["q_rad_s"].to_numpy() - q
    nxt = next(simex_frames(fd, 0.01, 2.0, seed=SEED + 1))[1]
    for col, base in (("alpha_rad", alpha), ("beta_rad", 0.0 * t)):
        assert not np.allclose(q_move, nxt[col].to_numpy() - base)
    for col in cols:
        moves: dict[float, list] = {lam: [] for lam in LAMBDAS}
        for lam, f in with_rates:
            moves[lam].append((f[col].to_numpy() - fd[col].to_numpy()) / np.sqrt(lam))
        for lam in LAMBDAS:
            m = np.array(moves[lam])
            assert len(m) == REPLICATES
            np.testing.assert_allclose(m[0::2], -m[1::2], atol=1e-15)  # antithetic
            np.testing.assert_allclose(m, np.array(moves[LAMBDAS[0]]), atol=1e-12)  # common to every lambda
            # the noise through the 2 Hz low-pass at 100 Hz samples: about 0.2 x its white sigma
            assert 0.1 * (0.01 if col == "q_rad_s" else 0.02) < np.std(m[0]) < (0.01 if col == "q_rad_s" else 0.02)


def test_simex_correction_hardly_depends_on_the_draws_seed():
    """A sideslip-like regressor with a little vane noise, correlated with an exact rate (the
    yaw channel of a fast jet, where the correction is small and the Monte-Carlo error was most
    of it).  Over six seeds of the draws the corrected slopes spread 5.5e-5 (C_n_beta) and 6.6e-6
    (C_n_r) when written; independent draws at each lambda, as before, spread 5.0e-4 and 1.8e-4
    (measured with the same six seeds), 22 % of C_n_beta's correction."""
    t = np.arange(6000) * 0.01
    beta = 0.004 * np.sin(2 * np.pi * 0.5 * t) + 0.002 * np.sin(2 * np.pi * 1.1 * t + 0.4)
    r = 0.012 * np.sin(2 * np.pi * 0.5 * t + 1.2) + 0.003 * np.sin(2 * np.pi * 0.2 * t)
    rng = np.random.default_rng(1234)  # not one of the draws' seeds below
    y = 0.12 * beta - 0.15 * r + 2e-4 * rng.standard_normal(t.size)
    fd = _frame(0 * t, t).assign(beta_rad=beta + filtered_noise(rng, np.zeros(t.size), t, 0.0026, 1.4), r=r)

    def design(f):
        return {"Cn": np.column_stack([np.ones(len(f)), f["beta_rad"].to_numpy(), f["r"].to_numpy()])}

    runs = [simex_estimates(fd, {"Cn": y}, design, 0.0026, 1.4, seed=s)["Cn"] for s in range(6)]
    corrected = np.array([res.corrected for res in runs])
    correction = abs(corrected[:, 1].mean() - runs[0].naive[1])
    assert correction > 1e-3  # the noise attenuates C_n_beta (so the spread is measured against something)
    assert corrected[:, 1].std(ddof=1) < 0.1 * correction
    assert corrected[:, 2].std(ddof=1) < 3e-5


# --------------------------------------------------------------------------- the gyros' part
def _rate_frame(t: np.ndarray, q: np.ndarray, alpha: np.ndarray) -> pd.DataFrame:
    z = 0.0 * t
    return pd.DataFrame({"t_s": t, "flight": "f", "segment": "s0", "alpha_rad": alpha, "beta_rad": z,
                         "alpha_r_rad": np.abs(alpha), "phi_r_rad": z, "p_rad_s": z, "q_rad_s": q, "r_rad_s": z})


def _rate_design(frame: pd.DataFrame) -> dict:
    return {"Cm": np.column_stack([np.ones(len(frame)), frame["alpha_rad"].to_numpy(), frame["q_rad_s"].to_numpy()])}


@pytest.mark.parametrize("seed,sigma", [(1, 0.025), (2, 0.03)])
def test_gyro_simex_corrects_the_known_attenuation_of_a_band_limited_rate(seed, sigma):
    """q measured with white gyro noise through the 2 Hz band low-pass (the colour the
    flight data's rates carry), alpha exact but correlated with q.  The naive slopes are
    the closed form (S + diag(0, 0, gain^2 sigma^2))^-1 S beta (S: the true regressors'
    second moments, gain: band_noise_gain): q's slope attenuated and part of it moved into
    alpha's, far outside the naive interval.  The gyro part of SIMEX removes most of it and
    the truth is inside its reported interval (the naive fit's coloured-residual sigma,
    scaled by the correction, with the extrapolation's own error)."""
    from aerosid.identification.band import band_noise_gain
    from aerosid.identification.regression import fit_linear

    rng = np.random.default_rng(seed)
    t = np.arange(20000) * 0.01
    one = np.zeros(t.size)
    q = filtered_noise(rng, one, t, 1.0, 0.8)
    q *= 0.01 / q.std()
    other = filtered_noise(rng, one, t, 1.0, 0.5)
    alpha = 0.8 * np.roll(q, 30) + other * 0.01 / other.std()
    beta_true = np.array([0.05, -1.5, -1.8])
    y = beta_true[0] + beta_true[1] * alpha + beta_true[2] * q + 1e-4 * rng.standard_normal(t.size)
    fd = _rate_frame(t, q + filtered_noise(rng, one, t, sigma, 2.0), alpha)
    X_true = _rate_design(_rate_frame(t, q, alpha))["Cm"]
    S = X_true.T @ X_true / t.size
    closed = np.linalg.solve(S + np.diag([0.0, 0.0, (band_noise_gain(100.0, 2.0) * sigma) ** 2]), S @ beta_true)
    naive = fit_linear(y, _rate_design(fd)["Cm"], names=["Cm_0", "Cm_alpha", "Cm_q"])
    assert naive.estimate[1:] == pytest.approx(closed[1:], rel=0.03)  # attenuated by the closed-form amount
    assert naive.estimate[2] > 0.85 * beta_true[2]
    assert abs(naive.estimate[2] - beta_true[2]) > 5 * naive.std_error[2]  # the naive interval misses
    z = 0.0 * t
    res = simex_estimates(fd, {"Cm": y}, _rate_design, None, None, (z, np.full(t.size, sigma), z), 2.0)["Cm"]
    assert res.naive == pytest.approx(naive.estimate, rel=1e-9)
    err = np.abs(res.corrected - beta_true)
    naive_err = np.abs(naive.estimate - beta_true)
    assert err[2] < 0.3 * naive_err[2] and err[1] < 0.5 * naive_err[1]  # most of the attenuation removed
    assert np.all(err[1:] <= 2.5 * res.std_error(naive.std_error, correction_share=1.0)[1:])  # inside the interval


def test_gyro_simex_with_zero_or_no_rate_noise_is_the_angle_only_correction():
    """rate_sigma None (the switch off) gives bit-identical results to the angle-only call,
    and a non-zero rate sigma changes the answer (so the comparison can fail)."""
    rng = np.random.default_rng(3)
    t = np.arange(3000) * 0.01
    q = 0.01 * np.sin(2 * np.pi * 0.5 * t)
    alpha = 0.01 * np.sin(2 * np.pi * 0.3 * t) + filtered_noise(rng, np.zeros(t.size), t, 0.02, 2.0)
    fd = _rate_frame(t, q + filtered_noise(rng, np.zeros(t.size), t, 0.02, 2.0), alpha)
    y = 0.1 - 1.8 * alpha - 2.0 * q
    before = simex_estimates(fd, {"Cm": y}, _rate_design, 0.02, 2.0)["Cm"]
    off = simex_estimates(fd, {"Cm": y}, _rate_design, 0.02, 2.0, None, 2.0)["Cm"]
    assert np.array_equal(before.corrected, off.corrected) and np.array_equal(before.spread, off.spread)
    s = np.full(t.size, 0.02)
    on = simex_estimates(fd, {"Cm": y}, _rate_design, 0.02, 2.0, (0 * s, s, 0 * s), 2.0)["Cm"]
    assert not np.allclose(on.corrected, off.corrected, rtol=1e-3)


def test_the_noise_free_gram_is_the_line_through_the_averaged_grams_at_minus_one():
    """E[X^T X](lambda) = A + (1 + lambda) B for noise of variance (1 + lambda) B: the extrapolant gives A."""
    rng = np.random.default_rng(7)
    A = rng.normal(size=(3, 3))
    A = A @ A.T + 3 * np.eye(3)
    B = np.diag([0.0, 0.5, 2.0])
    lams = np.array((0.0, *eiv.LAMBDAS))
    grams = np.array([A + (1 + lam) * B for lam in lams])
    assert np.allclose(eiv.noise_free_gram(lams, grams), A, atol=1e-12)
    res = eiv.SimexResult.from_curve(lams, np.zeros((len(lams), 3)), grams)
    assert np.allclose(res.gram_naive, A + B) and np.allclose(res.gram_corrected, A, atol=1e-12)


def test_information_reliability_is_the_reliability_ratio_of_a_noisy_column():
    """Two uncorrelated columns, the second with signal variance s2 and noise variance v: along it
    the signal's share of the information is s2 / (s2 + v) (the classical reliability ratio); the
    clean column's is 1; a direction where the noise-free information is negative gets 0; a
    singular matrix, or a direction on a column left out (NaN), cannot say (NaN), and a column
    left out is left out of both matrices."""
    n, s1, s2, v = 1000, 2.0, 0.3, 0.9
    naive = n * np.diag([s1, s2 + v])
    clean = n * np.diag([s1, s2])
    assert abs(eiv.information_reliability(naive, clean, [0.0, 1.0]) - s2 / (s2 + v)) < 1e-12
    assert abs(eiv.information_reliability(naive, clean, [1.0, 0.0]) - 1.0) < 1e-12
    assert eiv.information_reliability(naive, n * np.diag([s1, -0.1]), [0.0, 1.0]) == 0.0
    assert np.isnan(eiv.information_reliability(naive, n * np.diag([s1, 0.0]), [0.0, 1.0]))
    naive3 = n * np.array([[s1, 0.0, 0.5], [0.0, s2 + v, 0.4], [0.5, 0.4, 1.0]])
    clean3 = np.full((3, 3), np.nan)
    clean3[:2, :2] = clean
    assert np.isnan(eiv.information_reliability(naive3, clean3, [0.0, 1.0, 1.0]))
    # the third column left out of both: the same ratio as the 2 x 2 problem without it
    assert abs(eiv.information_reliability(naive3, clean3, [0.0, 1.0, 0.0]) - s2 / (s2 + v)) < 1e-12


def test_the_profile_direction_is_what_the_other_columns_absorb_of_one():
    """Column 2 = 3 x column 0 - column 1 + its own part: a change d of coefficient 2 refitted by
    the others moves them by -d x (3, -1) as its own part vanishes; for a positive definite
    Gram matrix it is G^-1 e_j scaled to 1 at j."""
    rng = np.random.default_rng(3)
    X = rng.normal(size=(500, 2))
    for own in (0.0, 0.5):
        Z = np.column_stack([X, 3 * X[:, 0] - X[:, 1] + own * rng.normal(size=500)])
        g = eiv.profile_direction(Z.T @ Z, 2)
        if own == 0.0:
            assert np.allclose(g, [-3.0, 1.0, 1.0], atol=1e-9)
        else:
            h = np.linalg.solve(Z.T @ Z, np.eye(3)[2])
            assert np.allclose(g, h / h[2], atol=1e-9)
    assert eiv.profile_direction(np.zeros((3, 3)), 0) is None


def test_simex_gives_the_naive_and_the_noise_free_information_of_the_design():
    """simex_estimates' Gram matrices: the naive one is the design's X^T X; extrapolated to no noise,
    the noisy alpha column's variance comes back to the clean alpha's (within the noise's own
    sampling error), the constant column's stays exact, and abs(alpha) -- not linear in the noise,
    put first so no ordering favours it -- is left out (NaN), whatever the others; the reliability
    along alpha is then finite, below 1, near the clean/measured variance ratio."""
    rng = np.random.default_rng(5)
    t = np.arange(6000) * 0.01
    alpha = 0.004 + 0.01 * np.sin(2 * np.pi * 0.3 * t) + 0.006 * np.sin(2 * np.pi * 0.9 * t + 1.0)
    sigma = 0.03
    measured = alpha + filtered_noise(rng, np.zeros(t.size), t, sigma, 2.0)
    fd = _frame(measured, t)

    def design(frame):
        a = frame["alpha_rad"].to_numpy()
        return {"Cm": np.column_stack([np.abs(a), np.ones_like(a), a])}

    res = simex_estimates(fd, {"Cm": -1.8 * alpha}, design, sigma, 2.0)["Cm"]
    X = design(fd)["Cm"]
    naive, clean = res.information()
    assert np.allclose(naive, X.T @ X, rtol=1e-12)
    assert np.all(np.isnan(clean[0])) and np.all(np.isnan(clean[:, 0]))
    assert np.all(np.isfinite(clean[1:, 1:]))
    assert abs(clean[1, 1] - t.size) < 1e-6 * t.size
    clean_var, noisy_var = alpha @ alpha, measured @ measured
    assert noisy_var > 1.2 * clean_var  # the noise is a real part of the column (the test can fail)
    assert abs(clean[2, 2] / clean_var - 1) < 0.2  # the noise's cross term with alpha's mean
    assert np.linalg.eigvalsh(clean[1:, 1:]).min() > 0
    centred = lambda x: x - x.mean()  # noqa: E731
    ratio = (centred(alpha) @ centred(alpha)) / (centred(measured) @ centred(measured))
    rho = eiv.information_reliability(naive, clean, [0.0, 0.0, 1.0])
    assert 0 < rho < 1 and abs(rho / ratio - 1) < 0.15
    assert not naive.flags.writeable


@pytest.mark.parametrize("reliability", [0.5, 0.7, 0.9])
def test_the_vanes_levels_leave_less_of_an_attenuation_than_the_usual_ones(reliability):
    """One noisy regressor of reliability R: the naive slope at extra noise lambda is
    b R / (R + (1 - R)(1 + lambda)) (the classical attenuation), its size falling convexly in lambda.  A quadratic
    through the vanes' levels (0.25..1) extrapolated to lambda = -1 leaves less of the attenuation
    than one through the usual levels (0.5..2), and both leave some (neither overshoots)."""
    b = -1.8

    def naive(lams):
        return b * reliability / (reliability + (1 - reliability) * (1 + lams))

    left = {}
    for source, levels in eiv.LAMBDAS_BY_SOURCE.items():
        lams = np.array((0.0, *levels))
        left[source] = (b - eiv.extrapolate(lams, naive(lams))) / (b - naive(0.0))
    assert 0 < left["vanes"] < left["database"] < 1



@pytest.mark.parametrize("source, angles, expected", [("vanes", True, "vanes"), ("database", True, "database"),
                                                      ("database", False, "rates")])
def test_identify_runs_simex_at_the_levels_of_the_noise_source(monkeypatch, source, angles, expected):
    """identify's SIMEX (eiv_fit.eiv_corrected) refits at the vanes' levels for vane angles, at the usual
    ones for angles inverted from the force database, and at the usual ones for the gyros' noise
    alone (measured there, bench/results/gyro_simex.md); an unknown source is refused."""
    from types import SimpleNamespace

    import aerosid.identification.eiv_fit as eiv_fit
    from aerosid.identification.regression import fit_linear

    seen = {}

    def spy(fd, y_by_channel, design, sigma, cutoff, rate_sigma=None, rate_cutoff=None, **kwargs):
        seen.update(kwargs)
        k = 2
        return {ch: eiv.SimexResult.from_curve(np.array([0.0, 0.5, 1.0]), np.zeros((3, k))) for ch in y_by_channel}

    monkeypatch.setattr(eiv_fit, "simex_estimates", spy)
    t = np.arange(200) * 0.01
    alpha = 0.01 * np.sin(t)
    fd = _frame(alpha, t).assign(Cm=-1.8 * alpha, band_hz=2.0)
    fits = {"Cm": fit_linear(fd["Cm"].to_numpy(), _design(fd)["Cm"], names=["Cm_0", "Cm_alpha"], channel="Cm")}
    vehicle = SimpleNamespace(air_data_source=source, vane_cutoff_hz=None)
    sigma = (np.full(t.size, 0.01), np.full(t.size, 0.01)) if angles else None
    rate_sigma = None if angles else tuple(np.full(t.size, 1e-3) for _ in range(3))
    eiv_fit.eiv_corrected(fd, vehicle, {"Cm": None}, fits, sigma, rate_sigma, skip=())
    assert seen["lambdas"] == {"vanes": eiv.LAMBDAS_BY_SOURCE["vanes"], "database": eiv.LAMBDAS,
                               "rates": eiv.LAMBDAS}[expected]
    assert max(eiv.LAMBDAS_BY_SOURCE["vanes"]) < max(eiv.LAMBDAS)
    with pytest.raises(KeyError):
        eiv_fit.simex_lambdas(SimpleNamespace(air_data_source="laser"))


def _roll_frame(t: np.ndarray, p: np.ndarray, delta: np.ndarray) -> pd.DataFrame:
    z = 0.0 * t
    return pd.DataFrame({"t_s": t, "flight": "f", "segment": "s0", "alpha_rad": z, "beta_rad": z,
                         "alpha_r_rad": z, "phi_r_rad": z, "p_rad_s": p, "q_rad_s": z, "r_rad_s": z,
                         "delta_p_rad": z, "delta_y_rad": z, "delta_r_rad": delta})


def _roll_design(frame: pd.DataFrame) -> dict:
    return {"Cl": np.column_stack([np.ones(len(frame)), frame["p_rad_s"].to_numpy(),
                                   frame["delta_r_rad"].to_numpy()])}


@pytest.mark.parametrize("seed", [4, 5])
def test_control_simex_corrects_the_attenuation_of_a_noisy_control_in_a_near_collinear_pair(seed):
    """A roll channel as a small aircraft flies it: p follows the aileron through a fast roll mode,
    so C_l_p p and C_l_delta delta nearly cancel and the fit lives on their small difference.  The
    aileron is measured with white noise through the 2 Hz band, 1 % of its variance there: the naive
    slopes are the closed form (S + diag(0, 0, gain^2 sigma^2))^-1 S beta, both low by far more than
    1 % and outside their intervals.  With control_sigma the controls' part of SIMEX removes most
    of it and the truth is inside the reported interval; without it (None) nothing moves."""
    from aerosid.identification.band import band_noise_gain
    from aerosid.identification.regression import fit_linear

    rng = np.random.default_rng(seed)
    t = np.arange(20000) * 0.01
    one = np.zeros(t.size)
    delta = filtered_noise(rng, one, t, 1.0, 0.7)
    delta *= 0.01 / delta.std()
    tau = 0.12  # roll-mode time constant [s]: p = -k delta through a first-order lag
    p = np.zeros_like(delta)
    for i in range(1, t.size):
        p[i] = p[i - 1] + 0.01 / tau * (2.0 * delta[i - 1] - p[i - 1])
    # in a steady roll (p = 2 delta) C_l_p p + C_l_delta delta is 2 % of C_l_delta delta
    beta_true = np.array([0.0, -0.47, 0.47 * 2.0 * 0.98])
    y = beta_true[1] * p + beta_true[2] * delta + 1e-6 * rng.standard_normal(t.size)
    sigma = 0.1 * 0.01 / band_noise_gain(100.0, 2.0)  # 10 % of the aileron's std through the band
    fd = _roll_frame(t, p, delta + filtered_noise(rng, one, t, sigma, 2.0))
    X_true = _roll_design(_roll_frame(t, p, delta))["Cl"]
    S = X_true.T @ X_true / t.size
    closed = np.linalg.solve(S + np.diag([0.0, 0.0, (band_noise_gain(100.0, 2.0) * sigma) ** 2]), S @ beta_true)
    naive = fit_linear(y, _roll_design(fd)["Cl"], names=["Cl_0", "Cl_p", "Cl_delta_r"])
    assert naive.estimate[1:] == pytest.approx(closed[1:], rel=0.05)
    assert np.all(np.abs(naive.estimate[1:] / beta_true[1:] - 1) > 0.05)  # far more than the 1 % share
    assert np.all(np.abs(naive.estimate[1:] - beta_true[1:]) > 5 * naive.std_error[1:])
    s = np.full(t.size, sigma)
    res = simex_estimates(fd, {"Cl": y}, _roll_design, None, None, control_sigma=(0 * s, 0 * s, s),
                          control_cutoff_hz=2.0)["Cl"]
    assert res.naive == pytest.approx(naive.estimate, rel=1e-9)
    err, naive_err = np.abs(res.corrected - beta_true), np.abs(naive.estimate - beta_true)
    assert np.all(err[1:] < 0.5 * naive_err[1:])
    assert np.all(err[1:] <= 1.96 * res.std_error(naive.std_error, correction_share=1.0)[1:])
    off = simex_estimates(fd, {"Cl": y}, _roll_design, None, None)["Cl"]
    assert off.corrected == pytest.approx(naive.estimate, rel=1e-9, abs=1e-12)  # no noise declared: nothing moves


def test_control_draws_have_their_own_generator_and_leave_the_angles_and_rates_alone():
    """simex_frames with control_sigma: the controls move in antithetic pairs common to every lambda,
    from the generator (seed, k, 2); the angles' and rates' draws are those without it."""
    from aerosid.identification.eiv import CONTROL_COLUMNS, LAMBDAS, simex_frames

    t = np.arange(1500) * 0.01
    d = 0.01 * np.sin(2 * np.pi * 0.4 * t)
    fd = _roll_frame(t, 0.02 * np.sin(2 * np.pi * 0.5 * t), d)
    fd["alpha_rad"] = 0.01 * np.sin(2 * np.pi * 0.3 * t)
    before = fd.copy()
    s = np.full(t.size, 0.01)
    with_controls = list(simex_frames(fd, 0.02, 2.0, (s, s, s), 2.0, control_sigma=(s, 0 * s, s),
                                      control_cutoff_hz=2.0))
    without = list(simex_frames(fd, 0.02, 2.0, (s, s, s), 2.0))
    pd.testing.assert_frame_equal(fd, before)
    moved = {lam: [] for lam in LAMBDAS}
    for (lam, f), (_, g) in zip(with_controls, without):
        for col in ("alpha_rad", "beta_rad", "p_rad_s", "q_rad_s", "r_rad_s"):
            np.testing.assert_array_equal(f[col].to_numpy(), g[col].to_numpy())
        np.testing.assert_array_equal(f["delta_y_rad"].to_numpy(), fd["delta_y_rad"].to_numpy())  # zero sigma
        moved[lam].append((f["delta_r_rad"].to_numpy() - d) / np.sqrt(lam))
    for lam in LAMBDAS:
        m = np.array(moved[lam])
        np.testing.assert_allclose(m[0::2], -m[1::2], atol=1e-15)
        np.testing.assert_allclose(m, np.array(moved[LAMBDAS[0]]), atol=1e-12)
    assert CONTROL_COLUMNS == ("delta_p_rad", "delta_y_rad", "delta_r_rad")  # the order of control_sigma
    # pair 0's unit draw is the (SEED, 0, 2) generator's, in that order (not the rates' (SEED, 0, 1)
    # nor the angles' (SEED, 0))
    groups, first = np.zeros(t.size), with_controls[0]
    unit = eiv.column_noise(np.random.default_rng([eiv.SEED, 0, 2]), groups, t, (s, 0 * s, s), 2.0)
    np.testing.assert_allclose(first[1]["delta_r_rad"].to_numpy() - d, np.sqrt(first[0]) * unit[:, 2], atol=1e-15)
    np.testing.assert_allclose(first[1]["delta_p_rad"].to_numpy(), np.sqrt(first[0]) * unit[:, 0], atol=1e-15)
    rates = eiv.column_noise(np.random.default_rng([eiv.SEED, 0, 1]), groups, t, (s, 0 * s, s), 2.0)
    assert not np.allclose(unit, rates)
