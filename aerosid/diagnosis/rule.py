"""The diagnosis' decision rule and its constants (aerosid.diagnosis.core applies them,
aerosid.diagnosis.result reports them; docs/modelling-loop.md gives their numbers)."""
from __future__ import annotations

import math


P_MAX = 1e-3
"""Largest corrected p-value of the added term for a significant finding."""
MIN_WINDOW_CONSISTENCY = 0.7
"""Smallest held-out (leave-one-window-out) consistency for a significant finding."""
MIN_VARIANCE_SHARE = 0.01
"""Smallest share of the residual variance a significant finding must explain."""
SIMEX_REPLICATES = 8
"""Replicates per extra-noise level of the SIMEX check (even: antithetic pairs, aerosid.identification.eiv.simex_frames)."""
SIMEX_LAMBDAS = (1.0, 2.0)
"""Extra angle-noise variances (in units of sigma^2) of the SIMEX check; quadratic extrapolation to -1.
The diagnosis' own check, calibrated on the look-alike bench (docs/modelling-loop.md), not the
identification's levels (aerosid.identification.eiv.LAMBDAS_BY_SOURCE)."""
if SIMEX_REPLICATES % 2:
    raise ValueError(f"SIMEX_REPLICATES must be even (antithetic pairs), not {SIMEX_REPLICATES}")
SIMEX_SEED = 20240613
"""Seed of the SIMEX extra noise (the diagnosis is deterministic)."""
FLAG_RATIO = 1.5
"""A time window or regime bin is flagged when its residual RMS is >= FLAG_RATIO x the channel's."""
MIN_BIN_SAMPLES = 30
"""Regime bins with fewer samples are not flagged (too few to judge)."""
CONFUSION_R = 0.9
"""Candidates whose base-residualised regressors correlate by at least this are reported as confusable."""
REGIME_BINS = 8
"""Quantile bins per regime variable."""
REGIME_VARIABLES = {  # name in the report -> (signal, unit)
    "alpha": ("alpha", "rad"), "beta": ("beta", "rad"), "mach": ("mach", "-"), "qbar": ("qbar", "Pa"),
    "delta_p": ("delta_p", "rad"), "delta_y": ("delta_y", "rad"), "delta_r": ("delta_r", "rad"),
    "phi_r": ("phi_r", "rad"),
}
ACF_LAGS_S = (0.1, 0.5, 1.0, 2.0)
"""Lags [s] at which the residual autocorrelation is reported."""
SPECTRUM_BANDS_HZ = ((0.0, 0.1), (0.1, 0.5), (0.5, 2.0), (2.0, 10.0), (10.0, math.inf))
"""Frequency bands for the residual power shares."""

RULE_TEXT = (f"significant = identifiable and corrected p < {P_MAX:g} (t^2 of the added term with the "
             f"coloured-residual sigma) and held-out window consistency >= {MIN_WINDOW_CONSISTENCY:.0%} "
             f"and explains >= {MIN_VARIANCE_SHARE:.0%} of the residual variance and lowers the PSE and is not an "
             f"errors-in-variables artefact (the SIMEX-corrected estimate also has p < {P_MAX:g} with the "
             "extrapolation's own error in its sigma); "
             "ranked significant first, then by the corrected partial F net of the share angle errors could make (SIMEX)")




def _f(x) -> float | None:
    """JSON-safe float (NaN/inf -> None)."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None
