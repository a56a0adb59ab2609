"""Held-out (leave-one-window-out) prediction error of a model, per channel (issue 18).

In-sample residual RMS always falls when a term is added, and a look-alike of the true
term lowers it almost as much (control_alpha flight, seed 1: -17 % with the wrong
alpha_nonlinearity, -16 % with the true control_alpha).  What a model is for is
predicting data it was not fitted to, so ``aerosid history`` ranks versions on the
held-out error: the samples inside the Mach window (as ``identify``) are cut into
``n_windows`` time blocks; the model is fitted without block k and predicts block k;
``heldout_rms = sqrt(sum_k SSE_k / N)``.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from aerosid.diagnosis.lookalikes import heldout_sse, windows_index
from aerosid.identification.identify import window_rows
from aerosid.modelling.models import vehicle_signals

__all__ = ["heldout_rms", "HELDOUT_WINDOWS"]

HELDOUT_WINDOWS = 8
"""Time blocks of the held-out error (the diagnosis' n_windows)."""


def heldout_rms(flight_data: pd.DataFrame, vehicle, models: dict, mach_half_width: float | None = 0.5,
                n_windows: int = HELDOUT_WINDOWS) -> dict[str, float]:
    """{channel: leave-one-window-out prediction RMS} of `models` on the flight data."""
    fd = flight_data.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    fd = fd.loc[window_rows(fd, vehicle, mach_half_width, models)]
    fd = fd.reset_index(drop=True)
    if len(fd) < 2 * n_windows:
        return {ch: float("nan") for ch in models}
    signals = vehicle_signals(fd, vehicle)
    win = windows_index(len(fd), n_windows)
    out = {}
    for ch, model in models.items():
        X, _ = model.design(signals)
        A = X.to_numpy(float)
        y = fd[ch].to_numpy(float)
        ok = np.isfinite(y) & np.all(np.isfinite(A), axis=1)
        if ok.sum() < 2 * n_windows:
            out[ch] = float("nan")
            continue
        sse = heldout_sse(A[ok], y[ok], win[ok])
        sse = sse[np.isfinite(sse)]
        out[ch] = float(math.sqrt(sse.sum() / ok.sum())) if sse.size else float("nan")
    return out
