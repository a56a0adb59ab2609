"""Per-sample quality flag bits of the preprocessing stage.

Every channel of the preprocessed frame carries a ``flags_<channel>`` column
(``uint16``) and the frame a ``flags`` column, the bitwise OR over the channels.
A bit says what was *found* (detection bits) or what was *done* to the
``<channel>_clean`` value (action bits).  A sample whose flags are 0 is a real
measurement: its clean value is the raw value, bit for bit.

Detection bits (the raw value is not a trustworthy measurement):

``MISSING_ROW``   no raw row at this grid time (dropout or sync gap); ``t_raw_s`` and
                  the raw channels are NaN.
``NAN``           the raw value is NaN or +-inf.
``SENTINEL``      the raw value is one of the sentinel values
                  (``PreprocessParams.sentinel_values``).
``FROZEN``        the raw value repeats the previous sample's value exactly, within a
                  run of at least ``frozen_min_run`` identical updates in a channel whose
                  updates otherwise change (the run's first sample, the last genuine
                  update, is not flagged); a channel that rests at its resolution (a
                  quantised surface holding still) is not frozen by that.
``OUTLIER``       an isolated spike: it lies beyond both the left and the right
                  neighbourhood (robust two-sided test, see ``detect_outliers``).
``OUT_OF_RANGE``  finite, not a sentinel, but outside the physical bounds
                  (``schemas.telemetry.PHYSICAL_BOUNDS``).
``TIME_JITTER``   the raw timestamp lies further than ``snap_tolerance`` grid steps
                  from its grid point (set on all channels of that row).
``HELD``          the channel is sampled and held (updated every few grid samples,
                  ``aerosid.preprocess.sensors``) and this sample repeats its last
                  update: a true value, but not a new measurement.  Not a fault: the
                  row still counts as used; the Kalman filter skips it (no new
                  information) and ``<channel>_clean`` is interpolated linearly between
                  the update instants.

Action bits (what ``<channel>_clean`` holds at a flagged sample):

``INTERPOLATED``  linearly interpolated between the nearest good samples (a run of
                  bad samples no longer than ``max_interp_gap_s`` with good samples
                  on both sides; held samples between two update instants always).
``LONG_GAP``      left NaN: the run of bad samples is longer than
                  ``max_interp_gap_s``.
``EDGE_GAP``      left NaN: the run of bad samples touches the first or the last grid
                  sample, so there is no anchor on one side (no extrapolation).

Every detection bit is followed by exactly one or two action bits
(``INTERPOLATED``, or ``LONG_GAP`` and/or ``EDGE_GAP``).
"""
from __future__ import annotations

import enum

import numpy as np
import pandas as pd

FLAGS_DTYPE = np.uint16


class QualityFlag(enum.IntFlag):
    """Bits of the ``flags`` / ``flags_<channel>`` columns (see module docstring)."""

    MISSING_ROW = 1 << 0
    NAN = 1 << 1
    SENTINEL = 1 << 2
    FROZEN = 1 << 3
    OUTLIER = 1 << 4
    OUT_OF_RANGE = 1 << 5
    TIME_JITTER = 1 << 6
    HELD = 1 << 7
    INTERPOLATED = 1 << 8
    LONG_GAP = 1 << 9
    EDGE_GAP = 1 << 10


#: The raw value carries no measurement at all (the "dropout" kinds).
DROPOUT = QualityFlag.MISSING_ROW | QualityFlag.NAN | QualityFlag.SENTINEL
#: Any bit saying the raw value is not a trustworthy measurement (a fault).
FAULT = DROPOUT | QualityFlag.FROZEN | QualityFlag.OUTLIER | QualityFlag.OUT_OF_RANGE | QualityFlag.TIME_JITTER
#: Any bit saying the raw value is not a new, trustworthy measurement (a fault, or held).
DETECTION = FAULT | QualityFlag.HELD
#: Bits saying what the clean value holds at a flagged sample.
ACTION = QualityFlag.INTERPOLATED | QualityFlag.LONG_GAP | QualityFlag.EDGE_GAP
#: The clean value is NaN.
UNFILLED = QualityFlag.LONG_GAP | QualityFlag.EDGE_GAP
#: A sample with any of these bits must not be used as a measurement (Kalman update).
UNUSABLE = DETECTION | ACTION


def flag_names(value: int) -> list[str]:
    """Names of the bits set in ``value`` (e.g. ``["MISSING_ROW", "INTERPOLATED"]``)."""
    return [f.name for f in QualityFlag if int(value) & int(f)]


def usable_mask(frame: pd.DataFrame, channels) -> np.ndarray:
    """``(N, k)`` bool array: True where the sample is a real measurement.

    "Real measurement" = the raw value is present, finite, not a sentinel, not
    frozen, not an outlier, in physical range, on time, and the clean value is
    the raw value (not interpolated).  This is the mask the Kalman filter uses to
    decide whether to update (``False`` -> predict only).

    ``channels``: channel names (e.g. ``["p_rad_s", "q_rad_s"]``) or a single name;
    column order of the result follows it.  Raises ``KeyError`` for a channel without a
    ``flags_<channel>`` column.
    """
    if isinstance(channels, str):
        channels = [channels]
    cols = [f"flags_{c}" for c in channels]
    missing = [c for c in cols if c not in frame.columns]
    if missing:
        raise KeyError(f"no flag column(s) {missing} in the frame (is it a preprocessed frame?)")
    flags = frame[cols].to_numpy()
    return (flags & np.uint16(int(UNUSABLE))) == 0
