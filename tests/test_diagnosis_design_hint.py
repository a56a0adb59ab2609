"""The diagnosis points to `aerosid design` where it cannot answer (issues 18 and 20):
an unresolved look-alike pair names the command that separates them, with both names;
a flight where nothing is significant names the command that would show an effect.
(What following that advice achieves is measured in bench/bench_follow_advice.py.)"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from aerosid.diagnosis import diagnose
from aerosid.diagnosis.lookalikes import compare
from aerosid.diagnosis.synthetic import MEASURED_NOISE, flight_data_from_truth
from aerosid.vehicle import load_vehicle


def _cands():
    return [SimpleNamespace(name="alpha_nonlinearity", coefficient="Cm_alpha_abs_alpha", term="alpha*abs(alpha)",
                            spec_term="alpha_nonlinearity"),
            SimpleNamespace(name="control_alpha", coefficient="Cm_alpha_delta_p", term="alpha*delta_p/2",
                            spec_term="control_alpha")]


def _lookalikes(noise_sd: float, seed: int = 2):
    """Two regressors correlated at r ~ 0.97 beyond a constant; y holds a little of the first."""
    rng = np.random.default_rng(seed)
    n = 3000
    s = np.sin(np.linspace(0, 30, n))
    x1 = s + 0.25 * np.sin(np.linspace(0, 91, n))
    x2 = s + 0.25 * np.cos(np.linspace(0, 73, n))
    base = np.ones((n, 1))
    y = 0.05 * x1 + noise_sd * rng.standard_normal(n)
    return y, base, x1, x2


def test_unresolved_lookalikes_name_the_design_command_with_both_terms():
    y, base, x1, x2 = _lookalikes(noise_sd=3.0)
    c = compare("Cm", y, base, ["Cm_0"], _cands(), [x1, x2])
    assert c.verdict == "unresolved" and c.recommended is None
    assert "aerosid design RUN_DIR --effect alpha_nonlinearity --versus control_alpha --out DIR" in c.message


def test_separated_lookalikes_do_not_send_the_engineer_to_design():
    y, base, x1, x2 = _lookalikes(noise_sd=0.002)
    c = compare("Cm", y, base, ["Cm_0"], _cands(), [x1, x2])
    assert c.recommended == "alpha_nonlinearity"
    assert "aerosid design" not in c.message


def test_nothing_significant_names_the_design_command(reference_flight):
    vehicle = load_vehicle("seed-rlv")
    fd = flight_data_from_truth(reference_flight.truth, MEASURED_NOISE.scaled(0.25), seed=0)
    d = diagnose(fd, vehicle, localisation=False)
    assert d.nothing_significant, d.summary()
    assert "could not have detected" in d.message
    assert "aerosid design RUN_DIR --effect NAME --out DIR" in d.message
