"""The modelling loop's diagnosis (method.md §13): compare the model with the
measurements, see where it fails, and learn which physical effect is missing.

    >>> from aerosid.diagnosis import diagnose
    >>> d = diagnose(flight_data, load_vehicle("seed-rlv"))
    >>> print(d.summary()); d.to_json()   # -> RUN_DIR/diagnosis.json

See ``docs/modelling-loop.md``.
"""
from aerosid.diagnosis.candidates import (Candidate, catalogue_candidates, default_candidates, derived_signals,
                                          extra_candidates, smooth_derivative)
from aerosid.diagnosis.core import (CONFUSION_R, FLAG_RATIO, MIN_VARIANCE_SHARE, MIN_WINDOW_CONSISTENCY, P_MAX,
                                    RULE_TEXT, ChannelReport, Diagnosis, EffectEvidence, RegimeBin, WindowStat,
                                    Whiteness, diagnose)

__all__ = [
    "diagnose", "Diagnosis", "EffectEvidence", "ChannelReport", "WindowStat", "RegimeBin", "Whiteness",
    "Candidate", "default_candidates", "catalogue_candidates", "extra_candidates", "derived_signals",
    "smooth_derivative", "P_MAX", "MIN_WINDOW_CONSISTENCY", "MIN_VARIANCE_SHARE", "FLAG_RATIO", "CONFUSION_R",
    "RULE_TEXT",
]
