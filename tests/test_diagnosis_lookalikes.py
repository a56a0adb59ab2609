"""Look-alikes resolved, the error against its floor, versions ranked on held-out error
(aerosid.diagnosis.lookalikes, .floor, .heldout; issue 18).

Flight data: the reference flight's truth with a catalogue effect added along the
trajectory (open loop) and coloured estimation errors (aerosid.diagnosis.synthetic) at a
quarter of the real pipeline's level, as tests/test_diagnosis.py; the real-pipeline rates
are bench/bench_lookalikes.py (bench/results/lookalikes.md).
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from aerosid.diagnosis import Candidate, diagnose
from aerosid.diagnosis.floor import channel_floor, excess
from aerosid.diagnosis.heldout import heldout_rms
from aerosid.diagnosis.lookalikes import DELTA_MIN, compare, separating_manoeuvre
from aerosid.diagnosis.synthetic import MEASURED_NOISE, flight_data_from_truth
from aerosid.modelling.effects import CATALOGUE
from aerosid.modelling.models import default_models, parse_term
from aerosid.vehicles.vehicle import load_vehicle

NOISE = MEASURED_NOISE.scaled(0.25)
WRONG = {"control_alpha": "alpha_nonlinearity", "alpha_nonlinearity": "control_alpha"}


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle("seed-rlv")


def _flight_data(flight, name: str, seed: int = 0, noise=NOISE):
    fd = flight_data_from_truth(flight.truth, noise, seed=seed)
    tr = flight.truth
    sig = {"alpha": tr["alpha_rad"].to_numpy(), "delta_p": tr["delta_p_rad"].to_numpy()}
    e = CATALOGUE[name]
    fd[e.channel] = fd[e.channel] + e.value * np.asarray(e.regressor(sig), float)
    return fd


def _with(models: dict, name: str) -> dict:
    out = dict(models)
    ch = CATALOGUE[name].channel
    out[ch] = out[ch].with_term(parse_term(name, ch))
    return out


@pytest.fixture(scope="module")
def data(reference_flight):
    cache = {}

    def get(name: str, seed: int = 0):
        if (name, seed) not in cache:
            cache[(name, seed)] = _flight_data(reference_flight, name, seed)
        return cache[(name, seed)]

    return get


# --------------------------------------------------------------------------- compare(), closed forms
def _cands():
    return (Candidate("a_term", "Cm", "Cm_a", "alpha*delta_p/2", "a"),
            Candidate("b_term", "Cm", "Cm_b", "alpha*abs(alpha)", "b"))


def _two_lookalikes(noise_sd: float, seed: int = 1):
    rng = np.random.default_rng(seed)
    n = 4000
    base = np.column_stack([np.ones(n), np.sin(np.linspace(0, 20, n))])
    x1 = np.sin(np.linspace(0, 47, n)) + 0.3 * np.cos(np.linspace(0, 5, n))
    x2 = x1 + 0.25 * np.sin(np.linspace(0, 71, n) + 0.4)  # r ~ 0.97 with x1
    y = base @ np.array([0.1, -0.2]) + 0.5 * x1 + noise_sd * rng.standard_normal(n)
    return y, base, x1, x2


def test_compare_separates_lookalikes_when_the_noise_allows_and_picks_the_true_term():
    y, base, x1, x2 = _two_lookalikes(noise_sd=0.05)
    c = compare("Cm", y, base, ["c0", "c1"], _cands(), [x1, x2], p_distinct=1e-3)
    assert c.correlation["a_term|b_term"] > 0.9  # they are look-alikes
    assert c.verdict == "separated" and c.recommended == "a_term"
    assert c.delta["a_term>b_term"] >= DELTA_MIN and c.delta["b_term>a_term"] == pytest.approx(-c.delta["a_term>b_term"])
    a, b = c.alternative("a_term"), c.alternative("b_term")
    assert a.heldout_rms < b.heldout_rms
    assert a.estimate == pytest.approx(0.5, abs=0.02)  # the true coefficient
    assert abs(a.t_joint) > 3 and abs(b.t_joint) < 3
    # the shift each forces on the base coefficients, in units of their sigma in the base fit
    from aerosid.identification.regression import fit_linear

    fb = fit_linear(y, base, names=["c0", "c1"], channel="Cm")
    fa = fit_linear(y, np.column_stack([base, x1]), names=["c0", "c1", "a"], channel="Cm")
    assert a.coefficient_shift_sigma["c1"] == pytest.approx((fa.estimate[1] - fb.estimate[1]) / fb.std_error[1])
    assert set(b.coefficient_shift_sigma) == {"c0", "c1"}
    # partial residuals: the slope of y_perp on x_perp is the joint-fit estimate
    slope = float(a.partial_x @ a.partial_y / (a.partial_x @ a.partial_x))
    assert slope == pytest.approx(a.estimate_joint, rel=1e-6)
    assert len(a.partial_binned()["x"]) == 20


def test_compare_says_unresolved_and_names_the_separating_manoeuvre_when_the_noise_hides_it():
    y, base, x1, x2 = _two_lookalikes(noise_sd=3.0)
    c = compare("Cm", y, base, ["c0", "c1"], _cands(), [x1, x2], p_distinct=1e-3)
    assert c.verdict == "unresolved" and c.recommended is None
    assert abs(c.delta["a_term>b_term"]) < DELTA_MIN
    assert "cannot be told apart" in c.message and "pitch-fin deflection" in c.message
    assert "No recommendation" in c.message


def test_two_distinct_effects_are_not_called_lookalikes():
    rng = np.random.default_rng(3)
    n = 4000
    base = np.ones((n, 1))
    x1 = np.sin(np.linspace(0, 47, n))
    x2 = np.cos(np.linspace(0, 13, n))
    y = 0.5 * x1 + 0.4 * x2 + 0.05 * rng.standard_normal(n)
    c = compare("Cm", y, base, ["c0"], _cands(), [x1, x2], p_distinct=1e-3)
    assert c.verdict in ("distinct", "separated")
    assert c.verdict == "distinct" and c.recommended == "a_term"


def test_three_distinct_effects_name_every_one_the_model_lacks():
    rng = np.random.default_rng(4)
    n = 4000
    base = np.ones((n, 1))
    xs = [np.sin(np.linspace(0, 47, n)), np.cos(np.linspace(0, 13, n)), np.sin(np.linspace(0, 29, n) + 1.0)]
    y = 0.5 * xs[0] + 0.4 * xs[1] + 0.3 * xs[2] + 0.05 * rng.standard_normal(n)
    cands = (*_cands(), Candidate("c_term", "Cm", "Cm_c", "delta_p**2", "c"))
    c = compare("Cm", y, base, ["c0"], cands, xs, in_model="a_term", p_distinct=1e-3)
    assert c.verdict == "distinct" and c.recommended == "b_term"
    assert "are all needed" in c.message and "add b_term and c_term as well (b_term first)" in c.message
    c2 = compare("Cm", y, base, ["c0"], cands[:2], xs[:2], p_distinct=1e-3)
    assert "are both needed" in c2.message and "add a_term and b_term (a_term first)" in c2.message


def test_separating_manoeuvre_names_what_one_term_has_and_the_other_lacks():
    text = separating_manoeuvre("alpha*delta_p/2", "alpha*abs(alpha)")
    assert "pitch-fin deflection" in text and "alpha" in text and "two" in text
    assert "Mach" in separating_manoeuvre("(mach - 12.4)", "alpha*(mach - 12.4)")
    assert "alpha" in separating_manoeuvre("(mach - 12.4)", "alpha*(mach - 12.4)")


def test_a_mach_term_below_mach_0_3_is_flown_at_distinct_airspeeds():
    # a light aircraft at M 0.1: a fitted "Mach" term is a speed dependence (slipstream, thrust)
    low = separating_manoeuvre("(mach - 0.1)", "alpha*(mach - 0.1)", mach=0.1)
    assert "distinct airspeed levels" in low and "Mach levels" not in low and "compressibility" in low
    high = separating_manoeuvre("(mach - 12.4)", "alpha*(mach - 12.4)", mach=12.4)
    assert "distinct Mach levels" in high and "compressibility" not in high
    # compare() passes the flight's Mach on to the advice
    y, base, x1, x2 = _two_lookalikes(noise_sd=3.0)
    alts = (Candidate("a_term", "Cm", "Cm_a", "(mach - 0.1)", "a"),
            Candidate("b_term", "Cm", "Cm_b", "alpha*(mach - 0.1)", "b"))
    assert "distinct airspeed levels" in compare("Cm", y, base, ["c0", "c1"], alts, [x1, x2], mach=0.1).manoeuvre
    assert "distinct Mach levels" in compare("Cm", y, base, ["c0", "c1"], alts, [x1, x2]).manoeuvre
    # terms without Mach say nothing about it, whatever the speed
    assert "compressibility" not in separating_manoeuvre("alpha*delta_p/2", "alpha*abs(alpha)", mach=0.1)


# --------------------------------------------------------------------------- diagnose() on flight data
@pytest.mark.parametrize("name", ["control_alpha", "alpha_nonlinearity"])
def test_the_true_lookalike_is_recommended(data, vehicle, name):
    d = diagnose(data(name), vehicle)
    assert d.recommended == name
    comp = next(c for c in d.lookalikes if c.in_model is None)
    assert set(comp.names) >= {name, WRONG[name]} and comp.verdict == "separated"
    assert comp.alternative(name).heldout_rms < comp.alternative(WRONG[name]).heldout_rms
    doc = d.to_json()
    json.dumps(doc)
    assert doc["recommended"] == name and doc["lookalikes"][0]["recommended"] == name
    assert doc["effects"] and "nothing_significant" in doc  # the old names stay


@pytest.mark.parametrize("name", ["control_alpha", "alpha_nonlinearity"])
def test_the_loop_is_not_closed_on_the_wrong_lookalike(data, vehicle, name):
    wrong = _with(default_models(vehicle), WRONG[name])
    d = diagnose(data(name), vehicle, wrong)
    assert not d.loop_closed
    comp = next(c for c in d.lookalikes if c.in_model == WRONG[name])
    # the true term still improves the held-out prediction with the wrong one in the model
    assert comp.alternative(name).heldout_rms < comp.alternative(WRONG[name]).heldout_rms
    assert comp.swap and d.recommended == name
    assert "Nothing significant is missing" not in d.message and f'remove = ["{WRONG[name]}"]' in d.message
    # with the true term the loop can close
    right = diagnose(data(name), vehicle, _with(default_models(vehicle), name))
    assert right.loop_closed and right.recommended is None


def test_no_effect_nothing_recommended(data, vehicle, reference_flight):
    fd = flight_data_from_truth(reference_flight.truth, NOISE, seed=4)
    d = diagnose(fd, vehicle)
    assert d.recommended is None and d.loop_closed
    assert d.to_json()["recommended"] is None


# --------------------------------------------------------------------------- the floor
def test_floor_closed_forms():
    assert excess(5.0, 3.0) == pytest.approx(4.0)
    assert excess(3.0, 5.0) == 0.0
    f = channel_floor("Cm", np.full(100, 5.0), np.full(100, 3.0))
    assert (f.residual_rms, f.floor_rms, f.excess_rms) == pytest.approx((5.0, 3.0, 4.0))
    assert math.isnan(channel_floor("Cm", np.ones(5), None).floor_rms)


def test_floor_is_the_sigma_and_the_excess_falls_when_the_effect_is_added(data, vehicle):
    fd = data("control_alpha")
    d0 = diagnose(fd, vehicle)
    d1 = diagnose(fd, vehicle, _with(default_models(vehicle), "control_alpha"))
    f0, f1 = d0.floor["Cm"], d1.floor["Cm"]
    assert f0.floor_rms == pytest.approx(NOISE.Cm)  # the synthetic errors' own sigma
    assert f1.residual_rms < f0.residual_rms
    assert f1.excess_rms < 0.5 * f0.excess_rms
    # the complete model sits near its floor: what is left is the angles' error through it
    assert f1.residual_rms < 1.5 * f1.floor_rms  # floor_rms holds the angles' part when there is one
    assert set(d0.to_json()["floor"]["Cm"]) >= {"residual_rms", "floor_rms", "excess_rms"}
    assert "excess" in d0.summary()


# --------------------------------------------------------------------------- held-out error of versions
def test_heldout_error_prefers_the_true_term_over_its_lookalike(data, vehicle):
    fd = data("control_alpha")
    base = default_models(vehicle)
    h_true = heldout_rms(fd, vehicle, _with(base, "control_alpha"))["Cm"]
    h_wrong = heldout_rms(fd, vehicle, _with(base, "alpha_nonlinearity"))["Cm"]
    h_base = heldout_rms(fd, vehicle, base)["Cm"]
    assert h_true < h_wrong < h_base


def test_history_ranks_versions_by_heldout_error(tmp_path, data, vehicle):
    from aerosid.modelling.versions import fit_version, history

    run = tmp_path / "run"
    run.mkdir()
    data("control_alpha").to_parquet(run / "flight_data.parquet", index=False)
    base = default_models(vehicle)
    fit_version(run, _with(base, "alpha_nonlinearity"), note="the look-alike")  # v001 default, v002
    fit_version(run, _with(base, "control_alpha"), parent="v001", note="the true term")  # v003
    h = history(run)
    ranks = h.heldout_ranks()
    assert ranks["v003"] == 1 and ranks["v001"] == 3
    v = h.get("v003")
    assert v.metrics["channels"]["Cm"]["heldout_rms"] == pytest.approx(h.heldout(v, "Cm"))
    tab = h.table()
    assert {"heldout_Cm", "rms_Cm", "rank_heldout"} <= set(tab.columns)
    text = h.summary()
    order = [line.split()[1] for line in text.splitlines()[2:]]
    assert order == ["v003", "v002", "v001"]
