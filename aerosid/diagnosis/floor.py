"""The error against its floor (issue 18 item 3).

A channel's residual RMS (model - flight-derived coefficient) cannot fall below the
*floor*: what a complete model would still leave, because the flight-derived
coefficient and the regressors both carry estimation errors no model term can remove.
The headline number is the *excess* over the floor,

    excess_rms = sqrt(max(residual_rms^2 - floor_rms^2, 0)),

the part of the residual the model could still explain; it falls toward zero as the
model completes, where the residual itself barely moves (docs/modelling-loop.md §5).

How the floor is computed: the two parts below in quadrature
-------------------------------------------------------------
``coefficient_floor_rms``, the error of the flight-derived coefficient.  On the band path
(the default: flight data with ``band_hz`` and the sensors' white-noise sigma, the filter's
R, per sample) it is that noise through what the band path does to it: the gyros' through
the common low-pass and its central-difference derivative (:func:`band_derivative_noise_gain`)
and the Euler equations read backwards, the accelerometers' through the low-pass and the
lever arm; times the coefficient's scale factor (I/(q-bar S l), m/(q-bar S)).  On seed-rlv
(10 no-effect flights, Mach window) it is 0.82-1.05 x RMS(measured - LP(true)) for Cm, 0.83-1.00
for Cl and 0.76-1.02 for Cn, where the smoother's sigma (the ``sigma_<channel>`` columns, used
before, and still the fallback for flight data without those columns) was 1.1-1.8 x for Cm:
the smoother's chains are not the band path's filter.

``angle_floor_rms``, the recovered angles' error through the fitted model.  Measured, not
linearised: the channel's model is refitted with one more draw of the angles' own noise
(``eiv_sigma_*`` through the band, as the SIMEX correction draws it; ANGLE_REPLICATES draws)
and the rise of the residual's mean square is the angles' share of it.  A refit includes
what the least-squares fit absorbs into attenuated coefficients; the linearised
sqrt((dm/dalpha sigma_alpha)^2 + ...) (used before, for reference only) did not, and put
the floor above complete models' residuals (Cl 1.3-2.4e-4 against 0.8-1.0e-4 on seed-rlv:
near alpha_r = 0 the roll angle's derivative is huge but bounded sin(4 phi_r) terms are not).

The band path's own non-linearity (the low-pass taken before a non-linear term is formed:
LP(m(x)) - m(LP(x))) was a third part until 2026-11-29: 4.4-4.8e-5 in Cl on noise-free seed-rlv
flights, 1.1-1.5 x the Cl floor without it.  The fit now forms those columns in the band's order
(aerosid.identification.band_order), so a complete model no longer leaves it.

A floor from the residual's high-frequency power was tried and rejected: the error spectrum
falls faster above the band than a 2nd-order low-pass of differentiated white noise.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from aerosid.identification.band import segment_keys, segment_rates_and_bands

__all__ = ["ChannelFloor", "channel_floor", "floors", "excess", "floor_table", "band_sigmas", "angle_floor_rms",
           "ANGLE_REPLICATES"]

#: Draws of the angles' noise whose refits measure the angles' part of the floor.
ANGLE_REPLICATES = 8
#: Seed of those draws (the diagnosis is deterministic).
ANGLE_SEED = 20261126
FORCE_CHANNELS = ("CA", "CY", "CN")
MOMENT_CHANNELS = ("Cl", "Cm", "Cn")


@dataclass(frozen=True)
class ChannelFloor:
    """One channel's residual against its floor (module doc)."""

    channel: str
    residual_rms: float
    floor_rms: float  # the two parts below in quadrature
    method: str
    coefficient_floor_rms: float = float("nan")  # the flight-derived coefficient's own error
    angle_floor_rms: float = 0.0  # the recovered angles' error through the fitted model

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


def _rms(x) -> float:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x * x))) if x.size else float("nan")


def channel_floor(channel: str, residual: np.ndarray, sigma: np.ndarray | None, angle_rms: float = 0.0,
                  method: str = "smoother sigma") -> ChannelFloor:
    """One channel's residual RMS against its floor: the RMS of the coefficient's per-sample
    sigma combined in quadrature with the angles' part angle_rms (module doc)."""
    res_rms = _rms(residual) if np.size(residual) else float("nan")
    ang = float(angle_rms) if math.isfinite(angle_rms) else 0.0
    if sigma is None:
        return ChannelFloor(channel, res_rms, float("nan"), "none (no sigma of the coefficient)", float("nan"), ang)
    coef = _rms(sigma)
    if not math.isfinite(coef):
        return ChannelFloor(channel, res_rms, float("nan"), "none (sigma not finite)", float("nan"), ang)
    return ChannelFloor(channel, res_rms, math.sqrt(coef * coef + ang * ang), method, coef, ang)


def band_sigmas(fd, vehicle) -> dict[str, np.ndarray] | None:
    """Per-sample 1-sigma of the band path's flight-derived coefficients (module doc): the
    gyros' white noise (``eiv_sigma_p/q/r_rad_s``) through the band's low-pass and derivative
    and the Euler equations read backwards, the accelerometers' (``R_sigma_ax/ay/az_m_s2``)
    through the low-pass and the lever arm, times the coefficients' scale factors.  None when
    the flight data do not say so much (smoother path: zero gyro sigma; older files)."""
    from aerosid.identification.band import aero_angular_acceleration, band_derivative_noise_gain, band_noise_gain

    gyro = ("eiv_sigma_p_rad_s", "eiv_sigma_q_rad_s", "eiv_sigma_r_rad_s")
    acc = ("R_sigma_ax_m_s2", "R_sigma_ay_m_s2", "R_sigma_az_m_s2")
    if not len(fd) or not ({"band_hz", "t_s", "qbar_pa", *gyro} <= set(fd.columns)):
        return None
    sg = np.column_stack([fd[c].to_numpy(float) for c in gyro])
    band = fd["band_hz"].to_numpy(float)
    if not (np.all(np.isfinite(sg)) and sg.max() > 0 and np.isfinite(band).any()):
        return None
    # the gains per flight segment: pooled flights (or segments whose band the flight set) keep
    # their own band and sample rate; a segment without a band (smoother path) gets NaN
    g_der, g_lp = np.full(len(fd), np.nan), np.full(len(fd), np.nan)
    for idx, fs, b in segment_rates_and_bands(fd):
        if math.isfinite(fs) and math.isfinite(b):
            g_der[idx], g_lp[idx] = band_derivative_noise_gain(fs, b), band_noise_gain(fs, b)
    s_wdot = sg * g_der[:, None]  # (N, 3) [rad/s^2]
    inertia = (vehicle.Ixx_kg_m2, vehicle.Iyy_kg_m2, vehicle.Izz_kg_m2, vehicle.Ixz_kg_m2)
    # the Euler equations read backwards are linear in the rate derivatives: rows of B^-1
    b_inv = aero_angular_acceleration(np.zeros((3, 3)), np.eye(3), inertia).T
    s_ang = np.sqrt((s_wdot ** 2) @ (b_inv ** 2).T)  # (N, 3) L, M, N hat
    qs = fd["qbar_pa"].to_numpy(float) * vehicle.S_m2
    lengths = (vehicle.length_lateral_m, vehicle.length_pitch_m, vehicle.length_lateral_m)
    inert = (vehicle.Ixx_kg_m2, vehicle.Iyy_kg_m2, vehicle.Izz_kg_m2)
    out = {ch: s_ang[:, j] * inert[j] / (qs * lengths[j]) for j, ch in enumerate(MOMENT_CHANNELS)}
    if set(acc) <= set(fd.columns):
        sa = np.column_stack([fd[c].to_numpy(float) for c in acc]) * g_lp[:, None]
        rx, ry, rz = (float(v) for v in vehicle.accel_offset_m)
        lever = np.column_stack([np.hypot(s_wdot[:, 1] * rz, s_wdot[:, 2] * ry),  # (w_dot x r) noise
                                 np.hypot(s_wdot[:, 2] * rx, s_wdot[:, 0] * rz),
                                 np.hypot(s_wdot[:, 0] * ry, s_wdot[:, 1] * rx)])
        s_acc = np.hypot(sa, lever)
        if np.isfinite(s_acc).any():
            out.update({ch: s_acc[:, j] * vehicle.mass_kg / qs for j, ch in enumerate(FORCE_CHANNELS)})
    return out


def angle_floor_rms(fd, vehicle, models: dict, channels, replicates: int = ANGLE_REPLICATES) -> dict[str, float]:
    """{channel: RMS the recovered angles' error puts into the fitted model's residual}: the
    rise of the residual's mean square when the model is refitted with one more draw of the
    angles' own noise (the SIMEX draw: ``eiv_sigma_*`` per sample, through the band), averaged
    over `replicates` draws.  Empty when the angles are taken as exact.  The rise measures the
    step from sigma^2 to 2 sigma^2 of angle noise; where the fit attenuates strongly that step
    costs less than the first sigma^2, so the part is then on the low side (a floor that errs
    toward showing an excess, not toward hiding one)."""
    from aerosid.diagnosis.candidates import derived_signals
    from aerosid.diagnosis.lookalikes import scaled_lstsq
    from aerosid.identification.eiv import with_angle_noise
    from aerosid.identification.eiv_fit import angle_eiv_sigma, angle_cutoff_hz
    from aerosid.modelling.models import vehicle_signals

    sigma = angle_eiv_sigma(fd, vehicle)
    channels = [ch for ch in channels if ch in models and ch in fd]
    if sigma is None or not channels:
        return {}
    groups = segment_keys(fd)
    cutoff = angle_cutoff_hz(fd, vehicle)
    rng = np.random.default_rng(ANGLE_SEED)
    parent = vehicle_signals(fd, vehicle)

    def mean_squares(sig: dict) -> dict[str, float]:
        sig = derived_signals(sig, vehicle.length_pitch_m, vehicle.length_lateral_m)
        out = {}
        for ch in channels:
            A = models[ch].design(sig)[0].to_numpy(float)
            y = fd[ch].to_numpy(float)
            ok = np.all(np.isfinite(A), axis=1) & np.isfinite(y)
            e = y[ok] - A[ok] @ scaled_lstsq(A[ok], y[ok])
            out[ch] = float(np.mean(e * e)) if e.size else float("nan")
        return out

    base = mean_squares(parent)
    rise = {ch: 0.0 for ch in channels}
    for _ in range(replicates):
        noisy = with_angle_noise(fd, rng, groups, sigma, cutoff)
        for ch, ms in mean_squares(vehicle_signals(noisy, vehicle, like=parent)).items():
            rise[ch] += (ms - base[ch]) / replicates
    return {ch: math.sqrt(max(v, 0.0)) if math.isfinite(v) else float("nan") for ch, v in rise.items()}


def floors(residuals: dict, flight_data, angle_rms: dict | None = None, vehicle=None) -> dict[str, ChannelFloor]:
    """{channel: ChannelFloor} from {channel: residual array} and the flight-data rows they
    belong to: the band path's sigma (:func:`band_sigmas`, needs the vehicle) where the flight
    data carry what it needs, else their ``sigma_<channel>`` columns; angle_rms: {channel:
    the angles' part} (:func:`angle_floor_rms`)."""
    angle_rms = angle_rms or {}
    band = band_sigmas(flight_data, vehicle) if vehicle is not None else None
    out = {}
    for ch, r in residuals.items():
        if band is not None and ch in band:
            sigma, method = band[ch], "band path: the sensors' noise (the filter's R) through the band"
        else:
            sigma = flight_data[f"sigma_{ch}"].to_numpy(float) if f"sigma_{ch}" in flight_data else None
            method = "smoother sigma"
        out[ch] = channel_floor(ch, r, sigma, angle_rms.get(ch, 0.0), method)
    return out


def floor_table(floor: dict) -> list[str]:
    """Lines of the summary: residual, floor and the excess over it per channel."""
    lines = ["The error against its floor (floor = what a complete model would leave: the flight-derived "
             "coefficient's own error and the recovered angles' error through the model, from the sensors' white "
             "noise, in quadrature; "
             "excess = sqrt(residual^2 - floor^2): what a model term could still remove, or an error the floor "
             "does not know, e.g. turbulence, sensor biases, timing or the force database's own error in the "
             "inverted angles):",
             f"  {'channel':<8}{'residual':>11}{'floor':>11}{'excess':>11}{'excess/residual':>17}"
             f"{'coefficient':>13}{'angles':>10}"]
    for ch, f in floor.items():
        share = f.excess_share
        lines.append(f"  {ch:<8}{f.residual_rms:>11.3g}{f.floor_rms:>11.3g}{f.excess_rms:>11.3g}"
                     f"{(f'{share:.0%}' if math.isfinite(share) else 'nan'):>17}{f.coefficient_floor_rms:>13.3g}"
                     f"{f.angle_floor_rms:>10.3g}")
    return lines
