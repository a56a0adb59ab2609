"""The verdict of a two-term design (aerosid.design.verdict): separated means each term, present at
its size, would be found at 90 % with the other in the model, the model fits the manoeuvre, and the
design beats the flown manoeuvre."""
from aerosid.design.verdict import MAX_MODEL_ERROR_PCT, design_verdict

T = ("Cm_alpha_delta_p", "Cm_alpha_abs_alpha")
SIZES = (0.15, -0.43)


def _side(s1, s2, k=4.6, corr=-0.4):
    return {T[0]: {"sigma": s1, "detectable_size": 3.3 * s1, "reliable_size": k * s1},
            T[1]: {"sigma": s2, "detectable_size": 3.3 * s2, "reliable_size": k * s2}, "correlation": corr}


def test_separated_when_each_is_found_from_below_its_size():
    before, after = _side(0.04, 0.19, corr=-0.94), _side(0.02, 0.066)
    ok, text = design_verdict(T, SIZES, before, after, None, {}, "multisine", 0.6, 0.99)
    assert ok and text.startswith("SEPARATED")
    assert "found at 90 % from 0.092" in text and "run 0.184" in text


def test_not_separated_when_one_is_found_only_above_its_size_or_the_model_cannot_fit():
    before = _side(0.08, 0.5)
    ok, text = design_verdict(T, SIZES, before, _side(0.02, 0.1), None, {}, "doublets", 0.4, 0.9)
    assert not ok and text.startswith("NOT SEPARATED")  # 4.6 x 0.1 = 0.46 > 0.43
    calls = []
    ok, text = design_verdict(T, SIZES, before, _side(0.02, 0.066), None,
                              {T[0]: MAX_MODEL_ERROR_PCT + 2.0, T[1]: 1.0}, "doublets", 0.4, 0.9,
                              hint=lambda rel: calls.append(rel) or "PROPOSAL: fly power-off")
    assert not ok and "model error on the manoeuvre" in text and text.endswith("PROPOSAL: fly power-off")
    assert calls and abs(calls[0][T[0]] - 100 * 0.02 / 0.15) < 1e-9


def test_never_better_than_flown_is_said_so_per_unit_time():
    before = _side(0.02, 0.06)
    ok, text = design_verdict(T, SIZES, before, _side(0.04, 0.1), None, {}, "3-2-1-1s", 0.3, 1.0)
    assert not ok and text.startswith("NO BETTER MANOEUVRE WITHIN THE LIMITS")
    assert "0.04" in text and "0.02" in text and "found at 90 % from" in text
    # the run had 4x the design's time on condition: per second the design is better
    ok, text = design_verdict(T, SIZES, _side(0.04, 0.1), _side(0.05, 0.12), None, {}, "3-2-1-1s", 0.3, 1.0,
                              time_ratio=0.25)
    assert not ok and text.startswith("NOT SEPARATED")
    # a design that does what was asked is never called worse
    ok, text = design_verdict(T, SIZES, before, _side(0.03, 0.05), None, {}, "3-2-1-1s", 0.3, 1.0)
    assert ok and text.startswith("SEPARATED")
