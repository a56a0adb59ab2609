"""The regression's errors in variables: what noise the flight data says its regressors carry
(the angles', the gyros' and the surfaces' white-noise 1-sigma columns), the fits corrected for
it by SIMEX at the levels and with the share measured for the angles' source
(aerosid.identification.eiv holds the numerics), and the warning on a control that barely moves
above its own noise.  identify (aerosid.identification.identify) calls these."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from aerosid.identification.eiv import CORRECTION_SHARE, LAMBDAS, LAMBDAS_BY_SOURCE, RATE_COLUMNS, simex_estimates
from aerosid.identification.regression import with_corrected_estimate
from aerosid.modelling import models as model_signals
from aerosid.modelling.models import vehicle_signals
from aerosid.vehicles.vehicle import Vehicle


def angle_eiv_sigma(fd: pd.DataFrame, vehicle: Vehicle):
    """(sigma_alpha, sigma_beta) [rad] of the white noise in the angles (per sample), or None
    when the angles are taken as exact: the flight data's eiv_sigma_* columns
    (aerosid.identification.flight_data), else the vehicle file's vane noise for vanes."""
    if {"eiv_sigma_alpha_rad", "eiv_sigma_beta_rad"} <= set(fd.columns):
        sa, sb = (fd[c].to_numpy(float) for c in ("eiv_sigma_alpha_rad", "eiv_sigma_beta_rad"))
        if np.all(np.isfinite(sa)) and np.all(np.isfinite(sb)) and (sa.max() > 0 or sb.max() > 0):
            return sa, sb
        return None
    if vehicle.air_data_source == "vanes" and vehicle.vane_noise_rad > 0:
        return vehicle.vane_noise_rad, vehicle.vane_noise_rad
    return None


#: The flight data's white-noise 1-sigma of the gyros whose band-limited part is in p, q, r
#: [rad/s] (aerosid.identification.flight_data), for the gyro part of the SIMEX correction.
RATE_EIV_COLUMNS = ("eiv_sigma_p_rad_s", "eiv_sigma_q_rad_s", "eiv_sigma_r_rad_s")


def rate_eiv_sigma(fd: pd.DataFrame):
    """(sigma_p, sigma_q, sigma_r) [rad/s] per sample of the gyros' white noise whose
    band-limited part is in the flight data's rates, or None when the rates are taken as
    exact: flight data without the eiv_sigma_p/q/r columns (written before they existed, or
    the smoother's rates), or with them all zero or not finite."""
    return _declared_sigma(fd, RATE_EIV_COLUMNS)


def _declared_sigma(fd: pd.DataFrame, cols: tuple[str, ...]):
    """The flight data's 1-sigma columns ``cols`` as arrays, or None when any is missing or not
    finite, or all are zero."""
    if not set(cols) <= set(fd.columns):
        return None
    sig = tuple(fd[c].to_numpy(float) for c in cols)
    if all(np.all(np.isfinite(x)) for x in sig) and max(float(x.max(initial=0.0)) for x in sig) > 0:
        return sig
    return None


def control_eiv_sigma(fd: pd.DataFrame):
    """(sigma_delta_p, sigma_delta_y, sigma_delta_r) [rad] per sample of the mixed surfaces' white
    noise whose band-limited part is in the flight data's controls (flight_data.CONTROL_NOISE_COLUMNS,
    measured from the fins' second differences), or None when the controls are taken as exact:
    flight data without those columns, or with them all zero (quantised or held surfaces) or not
    finite."""
    from aerosid.identification.flight_data import CONTROL_NOISE_COLUMNS

    return _declared_sigma(fd, tuple(CONTROL_NOISE_COLUMNS[c] for c in ("delta_p", "delta_y", "delta_r")))


#: A control whose white noise through the band is more than this share of its variance in the
#: fit window gets a warning on every term that reads it: a share s attenuates such a term's
#: estimate by about s (errors in variables; corrected by SIMEX with control_eiv, the default).
CONTROL_NOISE_SHARE = 0.05


def control_noise_warnings(fd: pd.DataFrame, models: dict, skip=(), corrected: tuple[str, ...] = ()) -> dict[str, str]:
    """{channel: warning} for the channels with terms that read a control whose own noise is a
    sizeable share of its variation in this flight data (CONTROL_NOISE_SHARE): the flight
    data's eiv_sigma_delta_*_rad (the mixed surfaces' white noise, aerosid.identification.
    flight_data) through the band's low-pass against the control's variance.  Measured on the
    JSBSim A320 (rudder doublet against the yaw damper): the rudder moved 2.8e-4 rad in the
    band and its surfaces' 0.05 deg noise is 1.1e-4 rad there (a share of ~15 %).  The noise
    goes through each flight segment's own band and sample rate.  skip: channels not to warn on
    (the identities alpha and beta are inverted from).  corrected: the channels whose estimates
    were corrected for that noise (SIMEX, identify's control_eiv): their warning says so instead
    of "low by".  Empty for flight data without those columns or without a band."""
    from aerosid.identification.band import band_noise_gain, segment_rates_and_bands
    from aerosid.identification.flight_data import CONTROL_NOISE_COLUMNS
    from aerosid.modelling.expressions import signal_names
    from aerosid.modelling.models import SIGNALS

    if len(fd) < 3 or not ({"band_hz", "t_s", *CONTROL_NOISE_COLUMNS.values()} <= set(fd.columns)):
        return {}
    gain = np.full(len(fd), np.nan)  # the band's noise gain per row, from its segment's rate and band
    for idx, fs, band in segment_rates_and_bands(fd):
        if math.isfinite(fs) and math.isfinite(band):
            gain[idx] = band_noise_gain(fs, band)
    flagged = {}
    for c, col in CONTROL_NOISE_COLUMNS.items():
        in_band = (fd[col].to_numpy(float) * gain) ** 2
        in_band = in_band[np.isfinite(in_band)]
        noise = math.sqrt(float(np.mean(in_band))) if in_band.size else 0.0
        spread = float(np.nanstd(fd[f"{c}_rad"].to_numpy(float)))
        if noise > 0 and spread > 0 and (noise / spread) ** 2 > CONTROL_NOISE_SHARE:
            flagged[c] = (spread, noise)
    out = {}
    for ch, model in models.items():
        if ch in skip:
            continue
        for c, (spread, noise) in flagged.items():
            names = [t.coefficient for t in model.terms if c in signal_names(t.expression, SIGNALS)]
            if names:
                share = (noise / spread) ** 2
                effect = ("corrected for it by SIMEX, with a wider sigma" if ch in corrected else
                          f"the controls are taken as exact, so these estimates are low by about {share:.0%} "
                          "(errors in variables, not corrected)")
                text = (f"{', '.join(names)}: {c} moves only {spread / noise:.1f} x its own noise in the band "
                        f"(std {spread:.2g} rad against {noise:.2g} rad of surface-sensor noise through the band); "
                        f"{effect}: excite the control more")
                out[ch] = f"{out[ch]}; {text}" if ch in out else text
    return out


def simex_channels(fits: dict, skip: tuple[str, ...]) -> tuple[str, ...]:
    """The channels SIMEX corrects: every fit with finite estimates and no dropped column, but
    those in ``skip``."""
    return tuple(ch for ch, f in fits.items()
                 if np.all(np.isfinite(f.estimate)) and f.n_dropped == 0 and ch not in skip)


#: Signals whose presence in a channel's model keeps the gyros' part of SIMEX out of that channel
#: by default (identify's gyro_eiv="auto"): the angle rates read off the angles.
ANGLE_RATE_SIGNALS = ("alpha_dot_hat", "beta_dot_hat")


def angle_rate_free_channels(models: dict) -> tuple[str, ...]:
    """The channels whose model reads no angle rate (ANGLE_RATE_SIGNALS): where the gyros' part of
    SIMEX goes by default.  Joined to the angles' correction, which leaves part of the vane noise's
    attenuation of alpha-dot, it made C_m_alpha worse (docs/estimation.md, "Errors in the rates")."""
    from aerosid.modelling.expressions import signal_names
    from aerosid.modelling.models import SIGNALS

    return tuple(ch for ch, m in models.items()
                 if not any(set(ANGLE_RATE_SIGNALS) & set(signal_names(t.expression, SIGNALS)) for t in m.terms))


#: The model signals the rate columns p, q, r feed (aerosid.modelling.models.vehicle_signals),
#: unless alpha_dot_hat comes from the flight-path kinematics (models.kinematic_angles): a
#: channel left out of the gyros' part reads these from the un-noised flight data
#: (_with_measured_rates).
RATE_SIGNALS = ("p", "q", "r", "p_hat", "q_hat", "r_hat")


def eiv_corrected(fd: pd.DataFrame, vehicle: Vehicle, models: dict, fits: dict, sigma,
                  rate_sigma=None, control_sigma=None, *, skip: tuple[str, ...],
                  rate_channels: tuple[str, ...] | None = None) -> dict:
    """The fits with their estimates corrected for the noise in alpha and beta and, given
    rate_sigma, in the band-limited rates p, q, r (on the channels in rate_channels; None: every
    one), and, given control_sigma, in the band-limited controls (aerosid.identification.eiv,
    SIMEX), on the channels simex_channels(fits, skip) names.  skip: the channels left as they are
    (for inverted angles, the force channels they come from: identify.identity_channels).  One
    set of draws serves every channel: those outside rate_channels read their signals with the
    rates of the flight data as it is (_with_measured_rates), so their answer is the one without
    rate_sigma."""
    ok = simex_channels(fits, skip)
    noisy_rates = tuple(ch for ch in ok if rate_sigma is not None and (rate_channels is None or ch in rate_channels))
    if sigma is None and control_sigma is None:
        ok = noisy_rates  # the others get no noise at all: left as they are
    if not ok:
        return fits
    mixed = rate_sigma is not None and len(noisy_rates) < len(ok)  # some channels read the measured rates
    base = vehicle_signals(fd, vehicle) if mixed and not model_signals.kinematic_angles(fd, vehicle) else None
    parent: dict = {}  # vehicle_signals(fd), whose band order every frame shares (filled on the first)

    def design(frame: pd.DataFrame) -> dict:
        if not parent:
            parent.update(base if base is not None else vehicle_signals(fd, vehicle))
        sig = vehicle_signals(frame, vehicle, like=parent)
        exact = _with_measured_rates(frame, fd, vehicle, sig, base) if mixed else sig
        return {ch: models[ch].regressors(sig if ch in noisy_rates else exact).to_numpy(float) for ch in ok}

    band = fd["band_hz"].to_numpy(float) if "band_hz" in fd.columns else None
    corrected = simex_estimates(fd, {ch: fd[ch].to_numpy(float) for ch in ok}, design, sigma,
                                angle_cutoff_hz(fd, vehicle), rate_sigma, band if rate_sigma is not None else None,
                                lambdas=simex_lambdas(vehicle, angles=sigma is not None),
                                control_sigma=control_sigma,
                                control_cutoff_hz=band if control_sigma is not None else None)
    share = correction_share(vehicle, angles=sigma is not None)
    notes = {ch: _simex_note(vehicle, sigma, rate_sigma if ch in noisy_rates else None, control_sigma, share)
             for ch in ok}
    return {ch: with_corrected_estimate(f, corrected[ch].corrected, notes[ch],
                                        corrected[ch].std_error(f.std_error, correction_share=share),
                                        corrected[ch].information())
            if ch in corrected else f for ch, f in fits.items()}


def _with_measured_rates(frame: pd.DataFrame, fd: pd.DataFrame, vehicle: Vehicle, sig: dict,
                         base: dict | None) -> dict:
    """The signals of a SIMEX frame with its rates as fd measured them: for the channels the gyros'
    part leaves out.  base: vehicle_signals(fd), whose RATE_SIGNALS replace sig's; None when the
    rates feed the angles too (aerosid.modelling.models.kinematic_angles): then the signals are
    rebuilt from the frame with fd's rate columns."""
    if base is None:
        return vehicle_signals(frame.assign(**{c: fd[c].to_numpy() for c in RATE_COLUMNS}), vehicle, like=sig)
    return {**sig, **{k: base[k] for k in RATE_SIGNALS if k in base}}


def _simex_note(vehicle: Vehicle, sigma, rate_sigma, control_sigma, share: float) -> str:
    """What a SIMEX-corrected fit says of its correction (share: correction_share's)."""
    what = ("the vane noise" if vehicle.air_data_source == "vanes"
            else "the noise the accelerometers put into the inverted angles")
    parts = [text for text, sig, unit in (("the gyro noise in the band-limited rates (SIMEX, median sigma p, q, r ",
                                           rate_sigma, " rad/s)"),
                                          ("the surface-sensor noise in the band-limited controls (SIMEX, median "
                                           "sigma delta_p, delta_y, delta_r ", control_sigma, " rad)"))
             if sig is not None for text in [text + ", ".join(f"{float(np.median(x)):.2g}" for x in sig) + unit]]
    rates = " and ".join(parts)
    if sigma is None:
        head = f"estimates corrected for {rates}"
    else:
        head = (f"estimates corrected for {what} (SIMEX, median sigma alpha {float(np.median(sigma[0])):.2g} rad, "
                f"beta {float(np.median(sigma[1])):.2g} rad)" + (f" and {rates}" if rates else ""))
    part = "the correction itself" if share == 1 else f"{share:.0%} of the correction"
    return head + (f"; sigma scaled by the correction and combined with the correction's own error (at least {part}: "
                   "SIMEX's quadratic extrapolant leaves part of a large attenuation, or overshoots it); residual "
                   "statistics are the uncorrected fit's")


def correction_share(vehicle: Vehicle, angles: bool = True) -> float:
    """The share of SIMEX's correction counted as its own 1-sigma (aerosid.identification.eiv
    CORRECTION_SHARE) for the vehicle's angle source; a source nobody measured raises KeyError.
    angles=False (no angle noise: the rates' and the controls' alone): the vanes' larger share (not
    measured for those: the conservative one)."""
    return CORRECTION_SHARE[vehicle.air_data_source if angles else "vanes"]


def simex_lambdas(vehicle: Vehicle, angles: bool = True) -> tuple:
    """SIMEX's extra-noise levels (aerosid.identification.eiv LAMBDAS_BY_SOURCE) for the vehicle's
    angle source; angles=False (no angle noise: the gyros' and the controls' alone): the usual
    LAMBDAS, where the rates' part was measured (bench/results/gyro_simex.md).  A source nobody measured raises KeyError."""
    return LAMBDAS_BY_SOURCE[vehicle.air_data_source] if angles else LAMBDAS


def angle_cutoff_hz(fd: pd.DataFrame, vehicle: Vehicle) -> float | None:
    """The low-pass the vane angles went through [Hz]: the flight data's common band
    (aerosid.identification.band) when it has one, else the vehicle file's vane corner."""
    if "band_hz" in fd.columns:
        band = fd["band_hz"].to_numpy(float)
        if band.size and np.all(np.isfinite(band)):
            return float(np.median(band))
    return vehicle.vane_cutoff_hz
