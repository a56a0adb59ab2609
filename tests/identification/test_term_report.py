"""A coefficient whose 95 % interval holds 0 is printed as not determined by the flight."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from aerosid.identification.term_report import UNDETERMINED_NOTE, interval_includes_zero, undetermined, wrong_sign


def _table() -> pd.DataFrame:
    rows = [  # channel, coefficient, expression, estimate, sigma
        ("Cm", "Cm_0", "1", 1e-4, 1e-3),            # an intercept near 0: not flagged
        ("Cm", "Cm_alpha", "alpha", -0.5, 0.01),
        ("Cn", "Cn_r", "r_hat", -0.024, 0.05),      # F4N seed 13: -0.024 +- 0.05 against -0.15
        ("Cn", "Cn_beta", "beta", 0.12, 0.002),
        ("CN", "CN_alpha", "alpha", np.nan, np.nan),  # an identity: no interval, reported elsewhere
    ]
    df = pd.DataFrame(rows, columns=["channel", "coefficient", "expression", "estimate", "std_error"])
    df["ci_low"] = df["estimate"] - 1.96 * df["std_error"]
    df["ci_high"] = df["estimate"] + 1.96 * df["std_error"]
    return df


def test_only_non_constant_terms_whose_interval_holds_zero():
    assert undetermined(_table()) == ["Cn_r"]
    assert interval_includes_zero(-1.0, 1.0) and not interval_includes_zero(0.1, 1.0)
    assert not interval_includes_zero(math.nan, 1.0)


def test_the_run_table_marks_it():
    from aerosid.identification.identify import format_table

    df = _table()
    for col, val in (("f_stat", 1.0), ("f_stat_corrected", 1.0), ("r2", 0.9), ("pse", 1e-6),
                     ("condition_number", 2.0), ("n_obs", 100), ("n_eff", 50.0), ("warnings", ""),
                     ("reference", np.nan), ("std_error_ols", 0.01), ("crb_std", np.nan)):
        df[col] = val
    lines = format_table(df).splitlines()
    marked = [li for li in lines if UNDETERMINED_NOTE in li]
    assert len(marked) == 1 and marked[0].split()[0] == "Cn_r"


def test_the_run_summary_names_it(tmp_path):
    from aerosid.cli.run_summary import undetermined_line

    assert undetermined_line(tmp_path) is None  # no coefficients yet
    _table().to_parquet(tmp_path / "coefficients.parquet")
    line = undetermined_line(tmp_path)
    assert line.startswith("not determined by this flight") and "Cn_r" in line and "Cm_0" not in line


# --------------------------------------------------------------------------- damping of the wrong sign
def _damping_table() -> pd.DataFrame:
    rows = [  # channel, coefficient, expression, estimate, sigma
        ("Cm", "Cm_alpha", "alpha", 2.0, 0.1),               # positive, but not a damping term
        ("Cm", "Cm_alpha_dot", "alpha_dot_hat", 6.4, 1.4),   # pa28 seed 3 (truth +0.02)
        ("Cm", "Cm_q", "q_hat", -12.2, 1.3),
        ("Cl", "Cl_p", "p_hat", 0.02, 0.005),
        ("Cn", "Cn_r", "r_hat", 0.01, 0.02),                 # holds 0: undetermined, not "wrong sign"
    ]
    df = pd.DataFrame(rows, columns=["channel", "coefficient", "expression", "estimate", "std_error"])
    df["ci_low"] = df["estimate"] - 1.96 * df["std_error"]
    df["ci_high"] = df["estimate"] + 1.96 * df["std_error"]
    return df


def test_a_damping_term_wholly_positive_is_named():
    from aerosid.identification.term_report import wrong_sign, wrong_sign_damping

    assert wrong_sign(_damping_table()) == ["Cm_alpha_dot", "Cl_p"]
    assert wrong_sign_damping("Cm", "q_hat", 0.1) and not wrong_sign_damping("Cl", "q_hat", 0.1)
    assert not wrong_sign_damping("Cm", "q_hat", -0.1) and not wrong_sign_damping("Cm", "q_hat", math.nan)


def test_the_table_and_the_run_summary_say_so(tmp_path):
    from aerosid.cli.run_summary import wrong_sign_line
    from aerosid.identification.identify import format_table
    from aerosid.identification.term_report import WRONG_SIGN_NOTE

    df = _damping_table()
    for col, val in (("f_stat", 1.0), ("f_stat_corrected", 1.0), ("r2", 0.9), ("pse", 1e-6),
                     ("condition_number", 2.0), ("n_obs", 100), ("n_eff", 50.0), ("warnings", ""),
                     ("reference", np.nan), ("std_error_ols", 0.01), ("crb_std", np.nan)):
        df[col] = val
    marked = [li.split()[0] for li in format_table(df).splitlines() if WRONG_SIGN_NOTE in li]
    assert marked == ["Cm_alpha_dot", "Cl_p"]
    assert wrong_sign_line(tmp_path) is None
    df.to_parquet(tmp_path / "coefficients.parquet")
    line = wrong_sign_line(tmp_path)
    assert "Cm_alpha_dot, Cl_p" in line and "Cn_r" not in line


def test_its_partners_sigma_include_the_model_without_it():
    """A significant positive alpha-dot term (made here by a positive true coefficient: the rule
    looks at the sign only) widens C_m_alpha's sigma by the two-point mixture with the model
    without it; the estimates are unchanged; with the same data but a negative alpha-dot, nothing
    changes."""
    from aerosid.identification.prior_structure import with_structure_uncertainty, wrong_sign_terms
    from aerosid.identification.regression import fit_linear
    from aerosid.modelling.models import ChannelModel, Term

    rng = np.random.default_rng(7)
    n = 3000
    alpha = rng.normal(0, 0.05, n)
    q_hat = 0.8 * alpha + rng.normal(0, 0.01, n)
    adot = 0.5 * alpha + 0.5 * q_hat + rng.normal(0, 0.004, n)
    signals = {"alpha": alpha, "q_hat": q_hat, "alpha_dot_hat": adot}
    model = ChannelModel("Cm", (Term("Cm_0", "1"), Term("Cm_alpha", "alpha"), Term("Cm_q", "q_hat"),
                                Term("Cm_alpha_dot", "alpha_dot_hat")))
    X = model.regressors(signals)
    for sign in (+1.0, -1.0):
        y = 0.01 - 1.0 * alpha - 10.0 * q_hat + sign * 3.0 * adot + rng.normal(0, 0.002, n)
        fit = fit_linear(y, X, names=model.names, channel="Cm")
        out = with_structure_uncertainty(pd.DataFrame({"Cm": y}), signals, {"Cm": model}, {"Cm": fit})["Cm"]
        flagged = wrong_sign_terms({"Cm": model}, {"Cm": fit})
        assert np.allclose(out.estimate, fit.estimate)
        lo = fit.conf_int()[3][0]
        if sign > 0:
            assert lo > 0
            keep = [0, 1, 2]
            full = np.linalg.lstsq(X.to_numpy(), y, rcond=None)[0]
            d = np.linalg.lstsq(X.to_numpy()[:, keep], y, rcond=None)[0][1] - full[1]
            assert np.isclose(out.std_error[1], np.hypot(fit.std_error[1], 0.5 * d), rtol=1e-6)
            assert out.std_error[1] > 1.5 * fit.std_error[1]
            assert any("positive at 95 %" in w for w in out.warnings)
            assert flagged == {"Cm_alpha_dot": float(fit.t_values[3])}
            # its own interval takes the mixture too (the covariance stays one coherent matrix) ...
            assert np.isclose(out.std_error[3], np.hypot(fit.std_error[3], 0.5 * fit.estimate[3]), rtol=1e-6)
            # ... and the table names it for what it is, not as "not determined"
            from aerosid.identification.identify import Identification
            from aerosid.identification.term_report import undetermined, wrong_sign

            table = Identification({"Cm": out}, {"Cm": model}, {}, n, (0.1, 0.1), wrong_sign=flagged).table()
            assert wrong_sign(table) == ["Cm_alpha_dot"] and "Cm_alpha_dot" not in undetermined(table)
        else:
            assert out is fit and not flagged


def test_damping_terms_are_recognised_as_written():
    from aerosid.identification.term_report import damping_signal

    for expr in ("q_hat", "(q_hat)", "2*q_hat", "q_hat * 1"):
        assert damping_signal("Cm", expr) == "q_hat"
    assert damping_signal("Cm", "alpha_dot_hat") == "alpha_dot_hat" and damping_signal("Cl", "p_hat") == "p_hat"
    for ch, expr in (("Cm", "-q_hat"), ("Cm", "q_hat*alpha"), ("Cm", "q_hat**2"), ("Cm", "alpha"), ("Cm", "1"),
                     ("Cl", "q_hat"), ("CN", "q_hat"), ("Cm", "not an expression (")):
        assert damping_signal(ch, expr) is None


def test_a_wrong_sign_term_is_widened_and_named_even_when_no_partner_moves():
    """p_hat orthogonal to the other columns: dropping it moves nothing, but the term's own
    interval must still include the model without it, as the table and the run say."""
    from aerosid.identification.identify import Identification
    from aerosid.identification.prior_structure import with_structure_uncertainty, wrong_sign_terms
    from aerosid.identification.regression import fit_linear
    from aerosid.modelling.models import ChannelModel, Term

    rng = np.random.default_rng(11)
    n = 2000
    k = np.arange(n)
    beta, p_hat = 0.05 * np.sin(2 * np.pi * 5 * k / n), 0.02 * np.sin(2 * np.pi * 13 * k / n)  # orthogonal, mean 0
    signals = {"alpha": np.zeros(n), "beta": beta, "p_hat": p_hat}
    model = ChannelModel("Cl", (Term("Cl_0", "1"), Term("Cl_beta", "beta"), Term("Cl_p", "p_hat")))
    y = -0.1 * beta + 0.05 * p_hat + rng.normal(0, 1e-4, n)
    fit = fit_linear(y, model.regressors(signals), names=model.names, channel="Cl")
    assert fit.conf_int()[2][0] > 0
    out = with_structure_uncertainty(pd.DataFrame({"Cl": y}), signals, {"Cl": model}, {"Cl": fit})["Cl"]
    assert out is not fit and np.isclose(out.std_error[2], np.hypot(fit.std_error[2], 0.5 * fit.estimate[2]))
    assert np.isclose(out.std_error[1], fit.std_error[1], rtol=0.05)
    assert any("Cl_p: positive at 95 %" in w and "p_hat" in w for w in out.warnings)
    flagged = wrong_sign_terms({"Cl": model}, {"Cl": fit})
    table = Identification({"Cl": out}, {"Cl": model}, {}, n, (0.1, 0.1), wrong_sign=flagged).table()
    assert wrong_sign(table) == ["Cl_p"]


def test_the_flag_does_not_depend_on_the_mixture():
    """A channel with a term that is not identifiable (NaN estimate) skips the mixture; its
    wrong-sign damping term is still named (the flag is computed on the fits themselves)."""
    from aerosid.identification.prior_structure import wrong_sign_terms
    from aerosid.identification.regression import fit_linear
    from aerosid.modelling.models import ChannelModel, Term

    rng = np.random.default_rng(12)
    n = 1000
    q_hat = rng.normal(0, 0.02, n)
    signals = {"alpha": np.zeros(n), "q_hat": q_hat, "delta_p": np.zeros(n)}
    model = ChannelModel("Cm", (Term("Cm_0", "1"), Term("Cm_q", "q_hat"), Term("Cm_delta_p", "delta_p")))
    y = 0.3 * q_hat + rng.normal(0, 1e-4, n)
    fit = fit_linear(y, model.regressors(signals), names=model.names, channel="Cm")
    assert not np.isfinite(fit.estimate[2])  # delta_p never moved
    assert list(wrong_sign_terms({"Cm": model}, {"Cm": fit})) == ["Cm_q"]


def test_the_wrong_sign_column_counts_only_true():
    from aerosid.identification.term_report import wrong_sign

    df = _damping_table()
    df["wrong_sign"] = [False, np.nan, None, False, True]  # the rule on the intervals still holds
    assert wrong_sign(df) == ["Cm_alpha_dot", "Cl_p", "Cn_r"]


def test_an_aircraft_control_derivative_of_the_other_sign_is_warned_of():
    """A flipped elevator (c182: C_m,delta_p +0.652 +- 0.016, nothing said) gets a warning in its
    channel; the conventional sign, an interval holding 0 and a scaled term behave as they should."""
    import numpy as np

    from aerosid.identification.regression import fit_linear
    from aerosid.identification.term_report import control_sign_warnings
    from aerosid.modelling.models import ChannelModel, Term

    rng = np.random.default_rng(0)
    n = 2000
    a, d = rng.standard_normal(n), rng.standard_normal(n)
    model = ChannelModel("Cm", (Term("Cm_0", "1"), Term("Cm_alpha", "alpha"), Term("Cm_delta_p", "delta_p/2")))

    def warnings_for(cm_delta: float, noise: float = 0.01) -> dict:
        y = 0.01 - 0.8 * a + cm_delta * d / 2 + noise * rng.standard_normal(n)
        fit = fit_linear(y, np.column_stack([np.ones(n), a, d / 2]), names=["Cm_0", "Cm_alpha", "Cm_delta_p"],
                         channel="Cm")
        return control_sign_warnings({"Cm": fit}, {"Cm": model})

    (text,) = warnings_for(+0.65).values()
    assert "Cm_delta_p came out positive at 95 %" in text and "sign = -1" in text and "canard" in text
    assert warnings_for(-0.65) == {}
    assert warnings_for(+0.001, noise=1.0) == {}  # not determined: nothing to say
