"""The safe expression language: it evaluates arithmetic on signals and refuses anything else."""
import numpy as np
import pytest

from aerosid.modelling.expressions import ExpressionError, evaluate

SIG = {"alpha": np.array([0.1, -0.2]), "mach": np.array([12.0, 13.0]), "q_hat": np.array([1e-5, 2e-5])}


def test_arithmetic_and_whitelisted_functions():
    np.testing.assert_allclose(evaluate("alpha*abs(alpha)", SIG), [0.01, -0.04])
    np.testing.assert_allclose(evaluate("alpha*(mach - 12.4)", SIG), [0.1 * -0.4, -0.2 * 0.6])
    np.testing.assert_allclose(evaluate("sin(4*alpha)**2 + -q_hat", SIG), np.sin(4 * SIG["alpha"]) ** 2 - SIG["q_hat"])
    np.testing.assert_allclose(evaluate("1", SIG), [1.0, 1.0])


@pytest.mark.parametrize("text, fragment", [
    ("alpha.__class__", "attribute access"),
    ("__import__('os').system('true')", "call of \"__import__('os').system\" is not allowed"),
    ("open('/etc/passwd')", "call of 'open'"),
    ("eval('1')", "call of 'eval'"),
    ("(lambda: 1)()", "not allowed"),
    ("[x for x in alpha]", "ListComp is not allowed"),
    ("alpha[0]", "Subscript is not allowed"),
    ("alfa * 2", "unknown name 'alfa'"),
    ("alpha +", "syntax error"),
    ("'text'", "only numbers"),
    ("alpha if mach else 1", "IfExp is not allowed"),
    ("sin(alpha, mach)", "exactly one argument"),
    ("alpha // 2", "FloorDiv is not allowed"),
    ("", "empty"),
])
def test_rejected_with_a_clear_message(text, fragment):
    with pytest.raises(ExpressionError) as err:
        evaluate(text, SIG)
    assert fragment in str(err.value)


def test_unknown_name_lists_the_available_signals():
    with pytest.raises(ExpressionError, match="available signals: alpha, mach, q_hat"):
        evaluate("beta", SIG)


@pytest.mark.parametrize("text", ["1", "alpha", "alpha*abs(alpha)", "delta_p/2", "-alpha", "alpha**3 - 2*q",
                                  "log(alpha)", "alpha/(q - q)", "sqrt(alpha - 1)"])
def test_compiled_terms_are_the_evaluator_bit_for_bit_and_silent(text):
    """compile_expression (a simulation's inner loop) gives exactly what the tree evaluator gives,
    for every kind of term, scalars and arrays alike, without a warning where the result is
    inf or NaN; a constant term's array cannot be changed by a caller."""
    import warnings

    from aerosid.modelling.expressions import _eval, compile_expression, parse

    names = ("alpha", "q", "delta_p")
    fn = compile_expression(text, names)
    tree = parse(text, frozenset(names))
    for values in ({"alpha": 0.1, "q": -0.02, "delta_p": 0.05},
                   {"alpha": np.array([0.0, 0.1, -0.2]), "q": np.array([0.0, 1.0, 2.0]), "delta_p": np.zeros(3)}):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            got = fn(values)
        with np.errstate(all="ignore"):
            want = np.asarray(_eval(tree.body, values), dtype=float)
        assert np.array_equal(got, want, equal_nan=True) and got.dtype == want.dtype
    if text == "1":
        with pytest.raises(ValueError):
            fn({})[...] = 2.0


def test_weighted_terms_skip_unidentified_and_zero_values_and_evaluate_sums_them():
    from aerosid.identification.identified import IdentifiedModel
    from aerosid.modelling.models import ChannelModel, Term

    cm = ChannelModel("Cm", (Term("Cm_0", "1"), Term("Cm_alpha", "alpha"), Term("Cm_q", "q_hat"),
                             Term("Cm_delta_p", "delta_p/2")))
    m = IdentifiedModel({"Cm": cm}, {"Cm_0": 0.01, "Cm_alpha": -0.25, "Cm_q": float("nan"), "Cm_delta_p": 0.0})
    assert [v for _, v in m.weighted_terms("Cm")] == [0.01, -0.25]
    assert [v for _, v in m.weighted_terms("Cm", {"Cm_delta_p": 0.04})] == [0.01, -0.25, 0.04]
    sig = {"alpha": 0.1, "q_hat": 3.0, "delta_p": 0.2}
    assert float(m.evaluate("Cm", sig)) == 0.01 + -0.25 * 0.1
    assert float(m.evaluate("Cm", sig, {"Cm_delta_p": 0.04})) == 0.01 + -0.25 * 0.1 + 0.04 * (0.2 / 2)
