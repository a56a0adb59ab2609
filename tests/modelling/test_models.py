import numpy as np
import pytest

from aerosid.modelling.models import ModelSpecError, default_models, load_models, models_to_toml


def test_default_models_are_the_seed_models():
    m = default_models()
    assert m["Cm"].names == ("Cm_0", "Cm_alpha", "Cm_delta_p")
    assert m["Cl"].names == ("Cl_0", "Cl_alpha_r", "Cl_cos4phi", "Cl_delta_r")


def test_spec_file_adds_a_catalogue_effect_and_a_custom_term(tmp_path):
    spec = tmp_path / "m.toml"
    spec.write_text('[Cm]\nterms = ["Cm_0 = 1", "Cm_alpha = alpha", "Cm_delta_p = delta_p/2", "pitch_damping", '
                    '"Cm_a3 = alpha**3"]\n')
    models = load_models(spec)
    assert models["Cm"].names == ("Cm_0", "Cm_alpha", "Cm_delta_p", "Cm_q", "Cm_a3")
    assert models["CN"].names == default_models()["CN"].names
    sig = {k: np.array([0.1, 0.2]) for k in ("alpha", "delta_p", "q_hat")}
    X = models["Cm"].regressors(sig)
    np.testing.assert_allclose(X["Cm_a3"], [1e-3, 8e-3])
    again = tmp_path / "again.toml"
    again.write_text(models_to_toml(models))
    assert load_models(again) == models


@pytest.mark.parametrize("text, fragment", [
    ('[Cm]\nterms = ["Cm_x = os.system(1)"]', "call of 'os.system' is not allowed"),
    ('[Cm]\nterms = ["Cm_x = alpha.real"]', "attribute access"),
    ('[Cm]\nterms = ["roll_orientation"]', "belongs to channel Cl"),
    ('[Cm]\nterms = ["no_such_effect"]', "neither"),
    ('[Cx]\nterms = ["a = 1"]', "unknown channel [Cx]"),
    ('[Cm]\nterms = "Cm_0 = 1"', "needs terms"),
    ('[Cm]\nterms = ["Cm_0 = 1", "Cm_0 = alpha"]', "appear twice"),
    ('[Cm\nterms = 1', "not valid TOML"),
])
def test_malformed_specs_name_file_channel_and_term(tmp_path, text, fragment):
    spec = tmp_path / "bad.toml"
    spec.write_text(text)
    with pytest.raises(ModelSpecError) as err:
        load_models(spec)
    assert str(spec) in str(err.value) and fragment in str(err.value)


def test_an_aircraft_file_without_models_gets_the_aircraft_models_not_the_finned_ones(tmp_path):
    """A vehicle file written by hand for an aircraft may leave out [models]: it gets the linear
    aircraft model (pitch and roll damping, the yaw rate, both lateral controls), not the finned
    seed's (no damping, C_l in the roll orientation), which ran to "ok" on c182 with C_m,delta
    -13.9 % and C_N,delta +36 %.  A finned vehicle keeps method.md's."""
    import re

    from aerosid.modelling.models import AIRCRAFT_TERMS, DEFAULT_TERMS
    from aerosid.vehicles.vehicle import load_vehicle, resolve_vehicle_path

    text = resolve_vehicle_path("c172x").read_text()
    cut = re.sub(r"\n\[models\]\n(?:#.*\n|[A-Za-z].*\n|\s+.*\n)*?(?=\n\[)", "\n", text)
    assert "[models]" in text and "[models]" not in cut and "[limits]" in cut
    (tmp_path / "v.toml").write_text(cut)
    models = default_models(load_vehicle(tmp_path / "v.toml"))
    names = {ch: [t.coefficient for t in m.terms] for ch, m in models.items()}
    assert {"Cm_q", "Cm_alpha_dot"} <= set(names["Cm"]) and "CN_q" in names["CN"]
    assert {"Cl_p", "Cl_r", "Cl_beta"} <= set(names["Cl"]) and {"Cn_r", "Cn_p"} <= set(names["Cn"])
    assert len(names["Cm"]) == len(AIRCRAFT_TERMS["Cm"]) and "Cl_cos4phi" not in names["Cl"]
    finned = default_models(load_vehicle("seed-rlv"))
    assert [t.coefficient for t in finned["Cl"].terms] == [t.split(" = ")[0] for t in DEFAULT_TERMS["Cl"]]
