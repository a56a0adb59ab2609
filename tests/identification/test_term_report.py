"""A coefficient whose 95 % interval holds 0 is printed as not determined by the flight."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from aerosid.identification.term_report import UNDETERMINED_NOTE, interval_includes_zero, undetermined


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
