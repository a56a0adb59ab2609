"""The error against its floor (issue 18 item 3).

A channel's residual RMS (model - flight-derived coefficient) cannot fall below the
*floor*: the estimation error of the flight-derived coefficient itself, which no model
term can remove.  The headline number is the *excess* over the floor,

    excess_rms = sqrt(max(residual_rms^2 - floor_rms^2, 0)),

the part of the residual the model could still explain; it falls toward zero as the
model completes, where the residual itself barely moves (docs/modelling-loop.md §5).

How the floor is computed
-------------------------
``flight_data.parquet`` carries per-sample ``sigma_<channel>`` columns: the EKF + MBF
smoother's state sigma propagated to the coefficient (``aerosid.flight_coefficients``).
The floor is their RMS over the samples the diagnosis uses.

Is that sigma honest?  On the band path (the default) the regression's target *and* its
regressors go through the same low-pass at ``band_hz``, so the error that no model term
can remove is ``measured - LP(true)`` (the low-pass's attenuation of the true
coefficient is matched by the low-passed regressors, the model fits it).  Against that,
RMS(sigma) / RMS(measured - LP(true)) on seed-rlv (Mach window, 5 flights) is
Cm 1.18, Cl 1.05, Cn 0.67 (bench/results/modelling_loop_floor.md).  Against the old
bench column RMS(measured - true) the ratio is only 0.57 for Cm: that column counts the
band-limit's attenuation of the signal as error although the band-limited model
reproduces it (the default model's Cm residual is 0.6-0.8 x that "floor").  A floor
from the residual's high-frequency power was tried and rejected: the error spectrum
falls faster above the band than a 2nd-order low-pass of differentiated white noise
(the preprocessing filters too), so the extrapolation gave 2 % of the floor.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["ChannelFloor", "channel_floor", "floors", "excess", "floor_table"]


@dataclass(frozen=True)
class ChannelFloor:
    """One channel's residual against its floor."""

    channel: str
    residual_rms: float
    floor_rms: float
    method: str  # "smoother sigma"

    @property
    def excess_rms(self) -> float:
        return excess(self.residual_rms, self.floor_rms)

    @property
    def excess_share(self) -> float:
        """excess / residual (0: the residual is all floor)."""
        return self.excess_rms / self.residual_rms if self.residual_rms > 0 else float("nan")

    def to_dict(self) -> dict:
        f = lambda x: float(x) if math.isfinite(x) else None  # noqa: E731
        return {"residual_rms": f(self.residual_rms), "floor_rms": f(self.floor_rms),
                "excess_rms": f(self.excess_rms), "method": self.method}


def excess(residual_rms: float, floor_rms: float) -> float:
    """sqrt(max(residual^2 - floor^2, 0))."""
    if not (math.isfinite(residual_rms) and math.isfinite(floor_rms)):
        return float("nan")
    return math.sqrt(max(residual_rms ** 2 - floor_rms ** 2, 0.0))


def channel_floor(channel: str, residual: np.ndarray, sigma: np.ndarray | None) -> ChannelFloor:
    """One channel's residual RMS against the RMS of its per-sample sigma (module doc)."""
    r = np.asarray(residual, float)
    res_rms = float(np.sqrt(np.mean(r * r))) if r.size else float("nan")
    if sigma is None:
        return ChannelFloor(channel, res_rms, float("nan"), "none (no sigma column in the flight data)")
    s = np.asarray(sigma, float)
    s = s[np.isfinite(s)]
    if s.size == 0:
        return ChannelFloor(channel, res_rms, float("nan"), "none (sigma column not finite)")
    return ChannelFloor(channel, res_rms, float(np.sqrt(np.mean(s * s))), "smoother sigma")


def floors(residuals: dict, flight_data) -> dict[str, ChannelFloor]:
    """{channel: ChannelFloor} from {channel: residual array} and the flight-data rows they
    belong to (its ``sigma_<channel>`` columns)."""
    return {ch: channel_floor(ch, r, flight_data[f"sigma_{ch}"].to_numpy(float)
                              if f"sigma_{ch}" in flight_data else None)
            for ch, r in residuals.items()}


def floor_table(floor: dict) -> list[str]:
    """Lines of the summary: residual, floor and the excess over it per channel."""
    lines = ["The error against its floor (floor = RMS of the flight-derived coefficient's own sigma; "
             "excess = sqrt(residual^2 - floor^2), what a model term could still remove):",
             f"  {'channel':<8}{'residual':>11}{'floor':>11}{'excess':>11}{'excess/residual':>17}"]
    for ch, f in floor.items():
        share = f.excess_share
        lines.append(f"  {ch:<8}{f.residual_rms:>11.3g}{f.floor_rms:>11.3g}{f.excess_rms:>11.3g}"
                     f"{(f'{share:.0%}' if math.isfinite(share) else 'nan'):>17}")
    return lines
