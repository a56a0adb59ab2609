"""Cramér–Rao bounds (aerosid.identification.crb) against closed forms and Monte-Carlo."""
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
import scipy.stats

from aerosid.identification.crb import (R_COLUMNS, coefficient_bounds, crb_linear, information_matrix,
                                        output_sensitivities, rate_coupling_matrix, runs_of)

VEH = SimpleNamespace(S_m2=2.0, mass_kg=500.0, length_pitch_m=1.5, length_lateral_m=8.0, Ixx_kg_m2=300.0,
                      Iyy_kg_m2=900.0, Izz_kg_m2=1100.0, Ixz_kg_m2=0.0, accel_offset_m=(0.0, 0.0, 0.0))


def flight_frame(t, qbar, sigma, rates=None):
    n = len(t)
    fd = pd.DataFrame({"t_s": t, "flight": "f", "segment": "s0", "qbar_pa": np.full(n, qbar)})
    r = np.zeros((n, 3)) if rates is None else rates
    fd[["p_rad_s", "q_rad_s", "r_rad_s"]] = r
    for c, s in zip(R_COLUMNS, sigma):
        fd[c] = s
    return fd


def test_static_linear_model_is_sigma2_xtx_inverse():
    rng = np.random.default_rng(1)
    X = np.column_stack([np.ones(400), rng.normal(size=400), np.sin(np.arange(400) / 7)])
    expect = 0.3 * np.sqrt(np.diag(np.linalg.inv(X.T @ X)))
    np.testing.assert_allclose(crb_linear(X, 0.3), expect, rtol=1e-10)
    # the same through the output-error machinery: one output whose sensitivity is X
    M = information_matrix(X[:, None, :], np.array([0.3]))
    np.testing.assert_allclose(M, X.T @ X / 0.09, rtol=1e-12)


def test_side_force_channel_reduces_to_the_static_form():
    """C_Y acts on a_y only (no lever arm): its bound is sigma_ay m/(qbar S) sqrt(diag((X'X)^-1))."""
    t = np.arange(500) * 0.01
    X = np.column_stack([np.ones_like(t), np.sin(2 * t), np.cos(5 * t)])
    sigma = (0.5, 0.7, 1.1, 0.01, 0.02, 0.03)
    fd = flight_frame(t, 4000.0, sigma)
    b = coefficient_bounds(fd, VEH, {"CY": (X, ("CY_0", "CY_beta", "CY_d"), np.ones(3, bool))})
    expect = crb_linear(X, 0.7) * VEH.mass_kg / (4000.0 * VEH.S_m2)
    np.testing.assert_allclose([b.std[k] for k in ("CY_0", "CY_beta", "CY_d")], expect, rtol=1e-9)
    # an identity channel stays a parameter but gets no number; a non-identifiable column neither
    b2 = coefficient_bounds(fd, VEH, {"CY": (X, ("CY_0", "CY_beta", "CY_d"), np.array([True, True, False]))},
                            {"CY": True})
    assert np.isnan(b2.std["CY_d"]) and np.isfinite(b2.std["CY_beta"])
    b3 = coefficient_bounds(fd, VEH, {"CY": (X, ("CY_0", "CY_beta", "CY_d"), np.ones(3, bool))}, {"CY": False})
    assert all(np.isnan(v) for v in b3.std.values())
    # the gyros alone know nothing of a side force at the CG
    b4 = coefficient_bounds(fd, VEH, {"CY": (X, ("CY_0", "CY_beta", "CY_d"), np.ones(3, bool))}, outputs=("p", "q", "r"))
    assert all(np.isnan(v) for v in b4.std.values()) and "p, q, r only" in b4.method


def test_pitch_rate_sensitivity_is_the_integral_of_the_input():
    """q_dot = g (Cm_0 + Cm_x sin(w t)): the gyro's sensitivities are g t and g (1 - cos w t)/w,
    with the initial q unknown; the bound is the closed form's inverse information."""
    w, g_qbar = 1.3, 3000.0
    t = np.arange(2001) * 0.005
    X = np.column_stack([np.ones_like(t), np.sin(w * t)])
    sq = 0.02
    fd = flight_frame(t, g_qbar, (1.0, 1.0, 1.0, 0.01, sq, 0.01))
    b = coefficient_bounds(fd, VEH, {"Cm": (X, ("Cm_0", "Cm_x"), np.ones(2, bool))})
    g = g_qbar * VEH.S_m2 * VEH.length_pitch_m / VEH.Iyy_kg_m2
    S = np.column_stack([g * t, g * (1 - np.cos(w * t)) / w, np.ones_like(t)])
    cov = np.linalg.inv(S.T @ S) * sq**2
    np.testing.assert_allclose([b.std["Cm_0"], b.std["Cm_x"]], np.sqrt(np.diag(cov))[:2], rtol=1e-4)
    # a gap splits the record into two runs, each with its own unknown initial rate: less information
    gap = np.r_[t[:1000], t[1000:] + 0.5]
    b_gap = coefficient_bounds(flight_frame(gap, g_qbar, (1.0, 1.0, 1.0, 0.01, sq, 0.01)), VEH,
                               {"Cm": (X, ("Cm_0", "Cm_x"), np.ones(2, bool))})
    assert b_gap.n_runs == 2 and b_gap.std["Cm_0"] > 1.5 * b.std["Cm_0"]


def simulate_outputs(theta, t, X_moment, X_force, rates0, offset, inertia, qs_len, qs_m):
    """The output simulation the bound linearises: measured inputs, rates integrated from
    the Euler equations (coupling on the measured rates), accelerometers at the offset."""
    B = rate_coupling_matrix(inertia)
    lmn = np.column_stack([qs_len[:, j] * (X_moment[j] @ theta[j]) for j in range(3)])
    wdot = lmn @ B.T  # + the coupling on the measured rates, which does not depend on theta
    w = rates0[0] + np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * np.diff(t)[:, None] * (wdot[1:] + wdot[:-1]),
                                                                  axis=0)])
    a_cg = np.column_stack([np.zeros_like(t), qs_m * (X_force[0] @ theta[3]), -qs_m * (X_force[1] @ theta[4])])
    r = np.asarray(offset)
    acc = a_cg + np.cross(wdot, r) + np.cross(w, np.cross(w, r))
    return np.column_stack([acc, w])


def test_sensitivities_equal_finite_differences_of_the_output_simulation():
    rng = np.random.default_rng(3)
    t = np.arange(600) * 0.01
    inertia = (300.0, 900.0, 1100.0, 40.0)
    offset = (0.4, -0.1, 0.2)
    u = np.column_stack([np.sin(1.1 * t), np.cos(0.7 * t), rng.normal(size=t.size) * 0.1])
    Xm = [np.column_stack([np.ones_like(t), u[:, 0]]), np.column_stack([np.ones_like(t), u[:, 1]]),
          np.column_stack([u[:, 2], u[:, 0]])]
    Xf = [np.column_stack([np.ones_like(t), u[:, 1]]), np.column_stack([np.ones_like(t), u[:, 0]])]
    theta = [np.array([0.01, -0.2]), np.array([0.02, -0.5]), np.array([0.1, 0.05]), np.array([0.0, -1.0]),
             np.array([0.1, 3.0])]
    qs = np.full(t.size, 2500.0)
    qs_len = np.column_stack([qs * 8 / 300, qs * 1.5 / 900, qs * 8 / 1100])
    qs_m = qs / 500.0
    w0 = np.tile([[0.3, -0.1, 0.2]], (t.size, 1))
    y0 = simulate_outputs(theta, t, Xm, Xf, w0, offset, inertia, qs_len, qs_m)
    # linearise about the simulated trajectory (its rates are the 'measured' ones)
    P = 10
    dforce = np.zeros((t.size, 3, P))
    dmoment = np.zeros((t.size, 3, P))
    for j in range(3):
        dmoment[:, j, 2 * j:2 * j + 2] = qs_len[:, j:j + 1] * Xm[j]
    dforce[:, 1, 6:8] = qs_m[:, None] * Xf[0]
    dforce[:, 2, 8:10] = -qs_m[:, None] * Xf[1]
    S = output_sensitivities(t, dforce, dmoment, y0[:, 3:], inertia, offset, [slice(0, t.size)])
    assert S.shape == (t.size, 6, P + 3)
    flat = np.concatenate(theta)
    for i in range(P):
        h = 1e-2 * max(abs(flat[i]), 1e-1)  # outputs are quadratic in theta: central differences are exact
        tp, tm = flat.copy(), flat.copy()
        tp[i] += h
        tm[i] -= h
        split = lambda v: [v[0:2], v[2:4], v[4:6], v[6:8], v[8:10]]  # noqa: E731
        fd_ = (simulate_outputs(split(tp), t, Xm, Xf, w0, offset, inertia, qs_len, qs_m)
               - simulate_outputs(split(tm), t, Xm, Xf, w0, offset, inertia, qs_len, qs_m)) / (2 * h)
        np.testing.assert_allclose(S[:, :, i], fd_, rtol=1e-7, atol=1e-9 * np.abs(fd_).max())
    # the initial rates: an offset of the gyros, and a lever-arm term in the accelerometers
    np.testing.assert_allclose(S[:, 3:, P:], np.broadcast_to(np.eye(3), (t.size, 3, 3)))


def test_efficient_estimator_scatter_matches_the_bound():
    """Output error on the gyro of q_dot = g (Cm_0 + Cm_x sin w t) is least squares on
    [g t, g (1 - cos w t)/w, 1]: an efficient estimator.  Its Monte-Carlo std over 300 seeds
    lies in the chi-square band of the bound from coefficient_bounds."""
    w, qbar, sq = 0.9, 2000.0, 0.03
    t = np.arange(1500) * 0.01
    X = np.column_stack([np.ones_like(t), np.sin(w * t)])
    b = coefficient_bounds(flight_frame(t, qbar, (1.0, 1.0, 1.0, 0.01, sq, 0.01)), VEH,
                           {"Cm": (X, ("Cm_0", "Cm_x"), np.ones(2, bool))})
    g = qbar * VEH.S_m2 * VEH.length_pitch_m / VEH.Iyy_kg_m2
    A = np.column_stack([g * t, g * (1 - np.cos(w * t)) / w, np.ones_like(t)])
    truth = np.array([0.01, -0.3, 0.05])
    rng = np.random.default_rng(7)
    n = 300
    est = np.array([np.linalg.lstsq(A, A @ truth + rng.normal(0, sq, t.size), rcond=None)[0][:2] for _ in range(n)])
    ratio = est.std(axis=0, ddof=1) / np.array([b.std["Cm_0"], b.std["Cm_x"]])
    lo, hi = (np.sqrt(scipy.stats.chi2.ppf(p, n - 1) / (n - 1)) for p in (0.0005, 0.9995))
    assert np.all((ratio > lo) & (ratio < hi)), ratio
    # and an inefficient one (equation error on a differenced gyro) scatters well above it
    qm = A @ truth + rng.normal(0, sq, (200, t.size))
    qdot = np.gradient(qm, t, axis=1) / g
    ee = np.linalg.lstsq(X, qdot.T, rcond=None)[0]
    assert ee[1].std(ddof=1) > 3 * b.std["Cm_x"]


def test_runs_split_at_gaps_and_groups():
    t = np.r_[np.arange(10) * 0.1, 2 + np.arange(5) * 0.1]
    assert [(r.start, r.stop) for r in runs_of(t)] == [(0, 10), (10, 15)]
    g = np.array(["a"] * 4 + ["b"] * 6 + ["b"] * 5)
    assert [(r.start, r.stop) for r in runs_of(t, g)] == [(0, 4), (4, 10), (10, 15)]


def test_no_noise_estimate_gives_no_bound():
    t = np.arange(100) * 0.01
    fd = flight_frame(t, 1000.0, (1, 1, 1, 1, 1, 1)).drop(columns=list(R_COLUMNS))
    b = coefficient_bounds(fd, VEH, {"Cm": (np.ones((100, 1)), ("Cm_0",), np.ones(1, bool))})
    assert np.isnan(b.std["Cm_0"]) and "R_sigma" in b.note


if __name__ == "__main__":
    pytest.main([__file__])


def test_coefficient_table_carries_the_bound():
    """crb_std reaches coefficients.parquet (schema with unit metadata) and the CLI table."""
    import pandera.errors

    from aerosid.identification.identify import Identification, format_table
    from aerosid.modelling.models import ChannelModel, Term
    from aerosid.identification.regression import fit_linear
    from schemas.coefficients import Coefficients

    rng = np.random.default_rng(0)
    alpha = rng.normal(0, 0.05, 300)
    fit = fit_linear(0.01 - 0.5 * alpha + rng.normal(0, 1e-3, 300), np.column_stack([np.ones(300), alpha]),
                     names=("Cm_0", "Cm_alpha"), channel="Cm")
    model = ChannelModel("Cm", (Term("Cm_0", "1"), Term("Cm_alpha", "alpha")))
    ident = Identification({"Cm": fit}, {"Cm": model}, {}, 300, (0.9, 1.1), crb_std={"Cm_0": 1e-4, "Cm_alpha": 2e-3})
    tab = ident.table()
    Coefficients.validate(tab)
    assert tab.set_index("coefficient")["crb_std"].to_dict() == {"Cm_0": 1e-4, "Cm_alpha": 2e-3}
    text = format_table(tab)  # SI per radian by default
    line = next(x for x in text.splitlines() if x.strip().startswith("Cm_alpha"))
    assert "CRB" in text and " 0.002 " in line
    line = next(x for x in format_table(tab, per_degree=True).splitlines() if x.strip().startswith("Cm_alpha"))
    assert "3.5e-05" in line  # 2e-3 per rad, printed per degree
    assert Coefficients.to_schema().columns["crb_std"].metadata["unit"].startswith("per rad")
    with pytest.raises(pandera.errors.SchemaError):
        Coefficients.validate(tab.assign(crb_std=-1.0))
