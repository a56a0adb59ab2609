"""aerosid design end to end on a synthetic run with a fake (linear, open-loop) vehicle:
the written input respects the limits, and an impossible request says so with numbers."""
import json

import numpy as np
import pandas as pd
import pytest
import scipy.signal

from aerosid.design.core import DesignError, design, write_design
from aerosid.design.io import read_input
from aerosid.design.limits import read_limits

FS = 100.0
DUR = 60.0
V = 1000.0
TRUE = {"Cm_0": 0.01, "Cm_alpha": -0.25, "Cm_delta_p": 0.04, "Cm_q": -30.0}


class FakeFlyer:
    """alpha'' + 2 zeta w alpha' + w^2 alpha = K w^2 delta_p; q = alpha' + 0.3 alpha; fins d2 = -d4 = -delta_p/2."""

    column = "delta_p_cmd_rad"
    dt = 1.0 / FS
    t = np.arange(int(DUR * FS) + 1) / FS

    def fly(self, u):
        w, z, k = 3.0, 0.3, 0.15
        sys = scipy.signal.lti([k * w * w], [1.0, 2 * z * w, w * w])
        _, alpha, _ = scipy.signal.lsim(sys, np.asarray(u, float), self.t)
        alpha = alpha + 0.02
        adot = np.gradient(alpha, self.dt)
        q = adot + 0.3 * (alpha - 0.02)
        return truth_frame(self.t, alpha, q, np.asarray(u, float))


def truth_frame(t, alpha, q, dp):
    n = t.size
    z = np.zeros(n)
    cm = TRUE["Cm_0"] + TRUE["Cm_alpha"] * alpha + TRUE["Cm_delta_p"] * dp / 2 + TRUE["Cm_q"] * q * 1.0 / (2 * V)
    return pd.DataFrame({
        "t_s": t, "V_m_s": np.full(n, V), "h_m": np.full(n, 30000.0), "rho_kg_m3": np.full(n, 0.018),
        "mach": np.full(n, 12.4), "qbar_pa": np.full(n, 9000.0), "CA": np.full(n, 0.05), "CY": z, "CN": 1.7 * alpha,
        "Cl": z, "Cm": cm, "Cn": z, "alpha_rad": alpha, "beta_rad": z, "delta_p_rad": dp, "delta_y_rad": z,
        "delta_r_rad": z, "p_rad_s": z, "q_rad_s": q, "r_rad_s": z,
        "d1_rad": z, "d2_rad": -dp / 2, "d3_rad": z, "d4_rad": dp / 2,
        "az_cg_m_s2": -9.80665 * (1.0 + 20.0 * alpha),
    })


def fake_factory(vehicle, limits, coefs, effect, size, say):
    f = FakeFlyer()
    return f, f.fly(np.zeros_like(f.t)), 5.0, DUR - 2.0, False


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    from aerosid.diagnosis.synthetic import NoiseLevels, flight_data_from_truth

    d = tmp_path_factory.mktemp("run")
    f = FakeFlyer()
    u = np.where((f.t > 10) & (f.t < 12), 0.05, 0.0) - np.where((f.t > 12) & (f.t < 14), 0.05, 0.0)
    noise = NoiseLevels(CN=1e-3, CY=1e-4, Cm=3e-4, Cn=1e-4, Cl=1e-4, alpha_rad=0.0, beta_rad=0.0, rates_rad_s=0.0)
    flight_data_from_truth(f.fly(u), noise, seed=4).to_parquet(d / "flight_data.parquet")
    (d / "run.json").write_text(json.dumps({"vehicle": "seed-rlv"}))
    return d


def test_written_input_respects_the_surface_and_rate_limits(run_dir, tmp_path):
    d = design(run_dir, "pitch_damping", -30.0, refine=False, flyer_factory=fake_factory)
    paths = write_design(d, tmp_path)
    lim = read_limits("seed-rlv")
    for path in (paths["parquet"], paths["csv"]):
        df = read_input(path)
        u = df["delta_p_cmd_rad"].to_numpy()
        fin = np.abs(u) / 2.0  # d2 = -d4 = -delta_p/2 on this vehicle
        assert fin.max() <= lim.surface_rad[1][1] * (1 - lim.margin) + 1e-9
        assert fin.max() >= 0.5 * lim.surface_rad[1][1]  # the design uses the authority it has
        rate = np.abs(np.diff(fin)) * FS
        assert rate.max() <= lim.surface_rate_rad_s + 1e-6
    doc = json.loads(paths["json"].read_text())
    assert doc["manoeuvre"]["amplitude_rad"] == pytest.approx(np.abs(d.input["delta_p_cmd_rad"]).max(), rel=1e-9)
    assert doc["limit_use"]["surface"] <= 1.0 and doc["limit_use"]["surface_rate"] <= 1.0
    # before/after: the design beats the run's small doublet
    assert d.after["Cm_q"]["sigma"] < d.before["Cm_q"]["sigma"]


def test_impossible_request_says_no_manoeuvre_within_the_limits_with_numbers(run_dir):
    d = design(run_dir, "pitch_damping", -1e-3, refine=False, flyer_factory=fake_factory)
    assert not d.achievable
    assert d.verdict.startswith("NO MANOEUVRE WITHIN THE LIMITS")
    a = d.after["Cm_q"]
    assert f"{a['sigma']:.3g}" in d.verdict and f"{a['detectable_size']:.3g}" in d.verdict
    need = 1e-3 / (d.after["Cm_q"]["reliable_size"] / d.after["Cm_q"]["sigma"])
    assert f"{need:.3g}" in d.verdict


def test_a_large_effect_is_called_detectable_and_the_verdict_follows_the_numbers(run_dir):
    d0 = design(run_dir, "pitch_damping", -30.0, refine=False, flyer_factory=fake_factory)
    big = 2.0 * d0.after["Cm_q"]["reliable_size"]
    d = design(run_dir, "pitch_damping", -big, refine=False, flyer_factory=fake_factory)
    assert d.achievable and d.verdict.startswith("DETECTABLE")


def test_versus_sizes_come_from_the_catalogue_and_the_verdict_from_joint_detection(run_dir):
    """Two look-alikes: the absent one's estimate is ~0 in the joint fit, so the sizes are the
    catalogue's (or given), and 'SEPARATED' means each would be found at 90 % with the other in
    the model (found-from <= |size|), on a manoeuvre better than the flown one."""
    d = design(run_dir, "control_alpha", versus="alpha_nonlinearity", refine=False, flyer_factory=fake_factory)
    from aerosid.modelling.effects import CATALOGUE

    assert d.sizes == (CATALOGUE["control_alpha"].value, CATALOGUE["alpha_nonlinearity"].value)
    detect = all(d.after[t]["reliable_size"] <= abs(s) for t, s in zip(d.targets, d.sizes))
    better = max(d.after[t]["sigma"] / abs(s) for t, s in zip(d.targets, d.sizes)) < \
        max(d.before[t]["sigma"] / abs(s) for t, s in zip(d.targets, d.sizes))
    assert d.achievable == (detect and better)
    # the fake vehicle's run is one small doublet at one alpha: the design separates them
    assert d.achievable and d.verdict.startswith("SEPARATED")
    assert d.after["correlation"] ** 2 < d.before["correlation"] ** 2
    # a size given for the second term is used; a tiny one cannot be separated
    d2 = design(run_dir, "control_alpha", versus="alpha_nonlinearity", versus_size=1e-6, refine=False,
                flyer_factory=fake_factory)
    assert d2.sizes[1] == 1e-6 and not d2.achievable
    # a term the run's model already has is sized by the run's own estimate, not by the catalogue
    # (whose sizes are seed-rlv's: Cm_q = -30 would be wrong for an aircraft)
    d3 = design(run_dir, "control_alpha", versus="Cm_alpha", refine=False, flyer_factory=fake_factory)
    assert d3.sizes[1] == pytest.approx(d3.before["Cm_alpha"]["estimate"])
    assert d3.sizes[1] == pytest.approx(TRUE["Cm_alpha"], rel=0.05)
    for kw in ({"versus_size": 0.1}, {"versus": "alpha_nonlinearity", "versus_size": 0.0}, {"size": float("nan")}):
        with pytest.raises(DesignError):
            design(run_dir, "control_alpha", refine=False, flyer_factory=fake_factory, **kw)


def test_never_proposes_a_manoeuvre_worse_than_the_flown_one(run_dir):
    """A vehicle whose pitch rate barely answers the surface (the candidates' pitch rate is 1e-3
    of the run's): the design says the flown manoeuvre is better instead of proposing a worse one."""

    class Weak(FakeFlyer):
        def fly(self, u):
            u = np.asarray(u, float)
            r = super().fly(1e-3 * u)
            return truth_frame(self.t, r["alpha_rad"].to_numpy(), r["q_rad_s"].to_numpy(), u)

    def weak_factory(vehicle, limits, coefs, effect, size, say):
        f = Weak()
        return f, f.fly(np.zeros_like(f.t)), 5.0, DUR - 2.0, False

    d = design(run_dir, "pitch_damping", -30.0, refine=False, flyer_factory=weak_factory)
    assert d.after["Cm_q"]["sigma"] > d.before["Cm_q"]["sigma"]
    assert not d.achievable and d.verdict.startswith("NO BETTER MANOEUVRE WITHIN THE LIMITS")
    assert f"{d.before['Cm_q']['sigma']:.3g}" in d.verdict
