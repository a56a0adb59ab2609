"""Tests of aerosid.identification.structure: Efroymson stepwise regression and PSE search (method.md §11)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from aerosid.identification.structure import StepwiseResult, pse_search, stepwise
from tests.identification.test_regression import FS, N, TRUE, ar1, manoeuvre


def pitch_candidates(seed: int):
    """C_N = C_N0 + C_Nalpha alpha + C_Ndelta delta/2 + AR(1) noise (phi = 0.99), with two
    null candidates: alpha^2 and an unrelated 0.11 Hz signal (slow, like the true terms)."""
    rng = np.random.default_rng(seed)
    X = manoeuvre(rng)
    X[:, 2] *= 4.0  # stronger fin excitation so that C_Ndelta is clearly identifiable
    y = X @ TRUE + ar1(rng, N, 0.99, 0.002)
    t = np.arange(N) / FS
    null = np.deg2rad(1.0) * np.sin(2 * np.pi * 0.11 * t + rng.uniform(0, 2 * np.pi))
    cands = pd.DataFrame(
        {"CN_0": X[:, 0], "CN_alpha": X[:, 1], "CN_delta": X[:, 2], "CN_alpha2": X[:, 1] ** 2, "CN_null": null}
    )
    return y, cands


TRUE_TERMS = {"CN_alpha", "CN_delta"}
NULL_TERMS = {"CN_alpha2", "CN_null"}


def test_stepwise_recovers_structure_with_coloured_noise(record_property):
    seeds = range(30)
    true_in, null_in, null_in_plain = [], [], []
    for seed in seeds:
        y, cands = pitch_candidates(seed)
        res = stepwise(y, cands, forced=["CN_0"], channel="CN")
        plain = stepwise(y, cands, forced=["CN_0"], channel="CN", criterion="plain")
        sel = set(res.selected)
        true_in.append(TRUE_TERMS <= sel)
        null_in.append(bool(NULL_TERMS & sel))
        null_in_plain.append(bool(NULL_TERMS & set(plain.selected)))
    msg = (
        f"true terms in {np.mean(true_in):.2f}, a null term in {np.mean(null_in):.2f} "
        f"(plain partial F: {np.mean(null_in_plain):.2f}) of {len(seeds)} seeds"
    )
    print(msg)
    record_property("stepwise", msg)
    assert np.mean(true_in) >= 0.9, msg
    assert np.mean(null_in) <= 0.2, msg
    # the uncorrected partial F, inflated by N/N_eff, lets null terms in far more often
    assert np.mean(null_in_plain) > np.mean(null_in) + 0.5, msg


def test_stepwise_records_steps():
    y, cands = pitch_candidates(1)
    res = stepwise(y, cands, forced=["CN_0"], channel="CN")
    assert isinstance(res, StepwiseResult)
    assert res.steps[0].action == "start" and res.steps[0].names == ("CN_0",)
    assert res.steps[1].action == "enter" and res.steps[1].term == "CN_alpha"
    for s in res.steps:
        if s.action == "enter":
            assert s.partial_f > res.f_enter
            assert s.partial_f == s.partial_f_corrected
            assert s.partial_f_plain > 10 * s.partial_f_corrected  # inflated by N / N_eff
        assert np.isfinite(s.r2) and np.isfinite(s.pse)
    assert res.steps[-1].action == "stop" and res.steps[-1].partial_f < res.f_enter
    assert res.final.names == res.selected and res.selected[0] == "CN_0"
    pses = [s.pse for s in res.steps if s.action != "stop"]
    assert res.pse_best_step == int(np.argmin(pses))
    assert res.pse_best_names == res.steps[res.pse_best_step].names
    text = res.summary()
    assert "min PSE" in text and "F-to-enter" in text and "CN_alpha" in text
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.selected = ()  # type: ignore[misc]


def test_stepwise_backward_elimination_removes_redundant_term():
    """Classic case: x3 = x1 + x2 + small noise enters first, then x1, x2 make it redundant."""
    rng = np.random.default_rng(2)
    n = 2000
    x1, x2 = rng.normal(size=n), rng.normal(size=n)
    x3 = x1 + x2 + 0.3 * rng.normal(size=n)
    y = 1.0 + x1 + x2 + 0.5 * rng.normal(size=n)
    cands = pd.DataFrame({"c0": np.ones(n), "x1": x1, "x2": x2, "x3": x3})
    res = stepwise(y, cands, forced=["c0"], cov="ols")
    actions = [(s.action, s.term) for s in res.steps]
    assert actions[1] == ("enter", "x3")
    assert ("remove", "x3") in actions
    assert set(res.selected) == {"c0", "x1", "x2"}
    removal = next(s for s in res.steps if s.action == "remove")
    assert removal.partial_f < res.f_remove
    # with cov="ols" the two partial F coincide and equal the classical (RSS_r - RSS_f)/s^2
    s = res.steps[1]
    assert s.partial_f_plain == pytest.approx(s.partial_f_corrected)
    A = cands[["c0", "x3"]].to_numpy()
    rss_f = np.sum((y - A @ np.linalg.lstsq(A, y, rcond=None)[0]) ** 2)
    rss_r = np.sum((y - y.mean()) ** 2)
    assert s.partial_f_plain == pytest.approx((rss_r - rss_f) / (rss_f / (n - 2)), rel=1e-9)


def test_stepwise_options():
    y, cands = pitch_candidates(4)
    res = stepwise(y, cands, forced=["CN_0"], max_terms=1)
    assert res.selected == ("CN_0", "CN_alpha")
    assert any("max_terms" in n for n in res.notes)
    with pytest.raises(ValueError):
        stepwise(y, cands, forced=["CN_0"], f_enter=3.0, f_remove=4.0)
    with pytest.raises(KeyError):
        stepwise(y, cands, forced=["nope"])
    cands2 = cands.copy()
    cands2.loc[10, "CN_null"] = np.nan
    res2 = stepwise(y, cands2, forced=["CN_0"])
    assert res2.n_dropped == 1 and res2.final.n_obs == N - 1


def test_pse_search_marks_minimum():
    rng = np.random.default_rng(5)
    n = 3000
    X = manoeuvre(rng, n)
    y = X @ TRUE + rng.normal(0, 0.002, n)  # white noise: PSE's nominal-N penalty is right
    t = np.arange(n) / FS
    cands = pd.DataFrame(X, columns=["CN_0", "CN_alpha", "CN_delta"])
    cands["CN_null"] = np.sin(2 * np.pi * 0.11 * t)
    res = pse_search(y, cands, forced=["CN_0"], channel="CN")
    assert res.method == "pse"
    assert len(res.steps) == 4  # start + every candidate entered along the path
    pses = np.array([s.pse for s in res.steps])
    assert res.pse_best_step == int(np.argmin(pses))
    assert set(res.selected) == set(res.pse_best_names)
    assert {"CN_alpha", "CN_delta"} <= set(res.selected)
    assert res.final.pse == pytest.approx(pses.min())
    assert "min PSE" in res.summary()
