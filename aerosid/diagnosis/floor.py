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
smoother's state sigma propagated to the coefficient (``aerosid.identification.flight_coefficients``).
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

The regressors carry an error too: the recovered alpha and beta (``eiv_sigma_*`` columns,
white-noise sigma, through the band's low-pass).  Its effect on the model output,
sqrt((dm/dalpha sigma_alpha)^2 + (dm/dbeta sigma_beta)^2), is reported as
``angle_floor_rms`` but is *not* part of the floor the excess is measured against:
added in quadrature it put the floor above the residual of complete models (Cm
7.0e-4 vs 5.8-6.6e-4, Cl 1.3-2.4e-4 vs 0.8-1.0e-4: the least-squares fit absorbs part of
the angle error into attenuated coefficients), which made the excess 0 while a
detectable effect was still missing.  So the excess stays above zero when the model is
complete (Cm: sqrt(6.6^2 - 5.6^2) e-4 ~ 3.5e-4 on seed-rlv); what the bench checks is how
far it falls when the missing effect is added.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["ChannelFloor", "channel_floor", "floors", "excess", "floor_table", "angle_sigmas", "angle_part", "angle_floor_parts"]


@dataclass(frozen=True)
class ChannelFloor:
    """One channel's residual against its floor."""

    channel: str
    residual_rms: float
    floor_rms: float  # RMS of the sigma column: the flight-derived coefficient's own error
    method: str
    coefficient_floor_rms: float = float("nan")  # RMS of the sigma column
    #: the recovered angles' sigma through the fitted model (reported, not in the excess: see module doc)
    angle_floor_rms: float = 0.0

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
                "excess_rms": f(self.excess_rms), "coefficient_floor_rms": f(self.coefficient_floor_rms),
                "angle_floor_rms": f(self.angle_floor_rms), "method": self.method}


def excess(residual_rms: float, floor_rms: float) -> float:
    """sqrt(max(residual^2 - floor^2, 0))."""
    if not (math.isfinite(residual_rms) and math.isfinite(floor_rms)):
        return float("nan")
    return math.sqrt(max(residual_rms ** 2 - floor_rms ** 2, 0.0))


def channel_floor(channel: str, residual: np.ndarray, sigma: np.ndarray | None,
                  angle_part: np.ndarray | None = None) -> ChannelFloor:
    """One channel's residual RMS against its floor, the RMS of its per-sample sigma; the RMS of
    the per-sample error the recovered angles put into the model (when given) is reported
    beside it (module doc)."""
    r = np.asarray(residual, float)
    res_rms = float(np.sqrt(np.mean(r * r))) if r.size else float("nan")
    ang = float(np.sqrt(np.mean(np.square(angle_part)))) if angle_part is not None and np.size(angle_part) else 0.0
    if sigma is None:
        return ChannelFloor(channel, res_rms, float("nan"), "none (no sigma column in the flight data)",
                            float("nan"), ang)
    s = np.asarray(sigma, float)
    s = s[np.isfinite(s)]
    if s.size == 0:
        return ChannelFloor(channel, res_rms, float("nan"), "none (sigma column not finite)", float("nan"), ang)
    coef = float(np.sqrt(np.mean(s * s)))
    return ChannelFloor(channel, res_rms, coef, "smoother sigma", coef, ang)


def angle_sigmas(flight_data) -> tuple[np.ndarray, np.ndarray] | None:
    """Per-sample 1-sigma of the recovered alpha and beta as the regression sees them: the
    flight data's white-noise ``eiv_sigma_*`` through the band path's low-pass
    (``band_noise_gain``); None without those columns."""
    fd = flight_data
    if not {"eiv_sigma_alpha_rad", "eiv_sigma_beta_rad"} <= set(fd.columns):
        return None
    gain = 1.0
    if "band_hz" in fd.columns:
        from aerosid.identification.band import band_noise_gain

        t = fd["t_s"].to_numpy(float)
        dts = np.diff(t)
        dts = dts[dts > 0]
        band = float(np.nanmedian(fd["band_hz"].to_numpy(float)))
        if dts.size and math.isfinite(band) and band > 0:
            gain = band_noise_gain(1.0 / float(np.median(dts)), band)
    return (gain * fd["eiv_sigma_alpha_rad"].to_numpy(float), gain * fd["eiv_sigma_beta_rad"].to_numpy(float))


def angle_part(model, estimate: np.ndarray, fd, vehicle, sig_a: np.ndarray, sig_b: np.ndarray,
               step_rad: float = 1e-5) -> np.ndarray:
    """Per-sample error the angles' sigma puts into the model output: sqrt((dm/dalpha sig_a)^2 +
    (dm/dbeta sig_b)^2), the derivatives by finite differences of the fitted model."""
    from aerosid.diagnosis.candidates import derived_signals
    from aerosid.identification.inversion import total_angles
    from aerosid.modelling.models import vehicle_signals

    def out(da: float, db: float) -> np.ndarray:
        f = fd.copy()
        a = f["alpha_rad"].to_numpy(float) + da
        b = f["beta_rad"].to_numpy(float) + db
        f["alpha_rad"], f["beta_rad"] = a, b
        f["alpha_r_rad"], f["phi_r_rad"] = total_angles(a, b)
        sig = derived_signals(vehicle_signals(f, vehicle), vehicle.length_pitch_m, vehicle.length_lateral_m)
        X, _ = model.design(sig)
        return X.to_numpy(float) @ np.nan_to_num(np.asarray(estimate, float))

    m0 = out(0.0, 0.0)
    ga = (out(step_rad, 0.0) - m0) / step_rad
    gb = (out(0.0, step_rad) - m0) / step_rad
    return np.sqrt((ga * sig_a) ** 2 + (gb * sig_b) ** 2)


def floors(residuals: dict, flight_data, angle_parts: dict | None = None) -> dict[str, ChannelFloor]:
    """{channel: ChannelFloor} from {channel: residual array} and the flight-data rows they
    belong to (its ``sigma_<channel>`` columns); angle_parts: {channel: per-sample angle part}."""
    angle_parts = angle_parts or {}
    return {ch: channel_floor(ch, r, flight_data[f"sigma_{ch}"].to_numpy(float)
                              if f"sigma_{ch}" in flight_data else None, angle_parts.get(ch))
            for ch, r in residuals.items()}


def floor_table(floor: dict) -> list[str]:
    """Lines of the summary: residual, floor and the excess over it per channel."""
    lines = ["The error against its floor (floor = RMS of the flight-derived coefficient's own sigma; excess = "
             "sqrt(residual^2 - floor^2), what a model term could still remove; angles = the recovered angles' "
             "sigma through the model, for reference):",
             f"  {'channel':<8}{'residual':>11}{'floor':>11}{'excess':>11}{'excess/residual':>17}{'angles':>10}"]
    for ch, f in floor.items():
        share = f.excess_share
        lines.append(f"  {ch:<8}{f.residual_rms:>11.3g}{f.floor_rms:>11.3g}{f.excess_rms:>11.3g}"
                     f"{(f'{share:.0%}' if math.isfinite(share) else 'nan'):>17}{f.angle_floor_rms:>10.3g}")
    return lines


def angle_floor_parts(fd, vehicle, models: dict, reports: dict) -> dict:
    """{channel: per-sample angle part} for the channels whose regressors use the recovered
    angles, except the channels the angles were inverted from (CN, CY without vanes: their
    residual is ~0 by construction and the angle error *is* their coefficient error)."""
    sig = angle_sigmas(fd)
    if sig is None:
        return {}
    from aerosid.identification.identify import INVERSION_CHANNELS

    skip = INVERSION_CHANNELS if vehicle.air_data_source != "vanes" else ()
    return {ch: angle_part(models[ch], rep.fit.estimate, fd, vehicle, *sig)
            for ch, rep in reports.items() if ch not in skip}
