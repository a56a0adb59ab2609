"""The error against its floor (issue 18 item 3).

A channel's residual RMS (model - flight-derived coefficient) cannot fall below the
*floor*: what a complete model would still leave, because the flight-derived
coefficient and the regressors both carry estimation errors no model term can remove.
The headline number is the *excess* over the floor,

    excess_rms = sqrt(max(residual_rms^2 - floor_rms^2, 0)),

the part of the residual the model could still explain; it falls toward zero as the
model completes, where the residual itself barely moves (docs/modelling-loop.md §5).

How the floor is computed: the three parts below in quadrature
---------------------------------------------------------------
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

``nonlinearity_floor_rms``, the band path's own part.  The band path low-passes the signals
and then forms the model's columns, so a complete model m leaves LP(m(x)) - m(LP(x)) where
the coefficient holds the low-pass of m(x): nothing for a linear model, 4.4-4.8e-5 in Cl on
noise-free seed-rlv flights (its roll terms, cos 4 phi_r and alpha_r, are far from linear near
alpha_r = 0), 1.1-1.5 x the Cl floor without it.  It is formed with the fitted model from the
regressor signals *before* the low-pass, which the band path writes into the flight data
(``*_wideband_*``: the smoother's angles and rates, the clean fins and V), and what a refit
would absorb of it (its projection on the model's columns) is taken off.  Both sides come from
the same x, so the low-pass's attenuation of in-band content cancels.  Against the truth
(seed 0): 3.9e-5 from the smoother's angles, 3.8e-5 from the true ones.  An approximation
where the angles are inverted from the force database: the band path's angles are the
inversion of the low-passed forces, not the low-pass of the angles, and the inversion's own
non-linearity is not in this part.

A floor from the residual's high-frequency power was tried and rejected: the error spectrum
falls faster above the band than a 2nd-order low-pass of differentiated white noise.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from aerosid.identification.band import finite_runs, segment_keys, segment_rates_and_bands

__all__ = ["ChannelFloor", "channel_floor", "floors", "excess", "floor_table", "band_sigmas", "angle_floor_rms",
           "band_nonlinearity_rms", "ANGLE_REPLICATES"]

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
    floor_rms: float  # the three parts below in quadrature
    method: str
    coefficient_floor_rms: float = float("nan")  # the flight-derived coefficient's own error
    angle_floor_rms: float = 0.0  # the recovered angles' error through the fitted model
    nonlinearity_floor_rms: float = 0.0  # the band path's LP(m(x)) - m(LP(x)) of the fitted model

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
                "angle_floor_rms": f(self.angle_floor_rms),
                "nonlinearity_floor_rms": f(self.nonlinearity_floor_rms), "method": self.method}


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
                  method: str = "smoother sigma", nonlinearity_rms: float = 0.0) -> ChannelFloor:
    """One channel's residual RMS against its floor: the RMS of the coefficient's per-sample
    sigma combined in quadrature with the angles' part angle_rms and the band path's
    non-linearity nonlinearity_rms (module doc)."""
    res_rms = _rms(residual) if np.size(residual) else float("nan")
    ang = float(angle_rms) if math.isfinite(angle_rms) else 0.0
    nonlin = float(nonlinearity_rms) if math.isfinite(nonlinearity_rms) else 0.0
    if sigma is None:
        return ChannelFloor(channel, res_rms, float("nan"), "none (no sigma of the coefficient)", float("nan"), ang,
                            nonlin)
    coef = _rms(sigma)
    if not math.isfinite(coef):
        return ChannelFloor(channel, res_rms, float("nan"), "none (sigma not finite)", float("nan"), ang, nonlin)
    return ChannelFloor(channel, res_rms, math.sqrt(coef * coef + ang * ang + nonlin * nonlin), method, coef, ang,
                        nonlin)


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

    def mean_squares(frame) -> dict[str, float]:
        sig = derived_signals(vehicle_signals(frame, vehicle), vehicle.length_pitch_m, vehicle.length_lateral_m)
        out = {}
        for ch in channels:
            A = models[ch].design(sig)[0].to_numpy(float)
            y = fd[ch].to_numpy(float)
            ok = np.all(np.isfinite(A), axis=1) & np.isfinite(y)
            e = y[ok] - A[ok] @ scaled_lstsq(A[ok], y[ok])
            out[ch] = float(np.mean(e * e)) if e.size else float("nan")
        return out

    base = mean_squares(fd)
    rise = {ch: 0.0 for ch in channels}
    for _ in range(replicates):
        for ch, ms in mean_squares(with_angle_noise(fd, rng, groups, sigma, cutoff)).items():
            rise[ch] += (ms - base[ch]) / replicates
    return {ch: math.sqrt(max(v, 0.0)) if math.isfinite(v) else float("nan") for ch, v in rise.items()}


def band_nonlinearity_rms(fd, vehicle, models: dict, channels, model_signals: dict | None = None
                          ) -> dict[str, float]:
    """{channel: RMS of LP(m(x)) - m(LP(x))}: what the band path's order of operations puts
    into the fitted model's residual (module doc).  x: the regressor signals before the
    low-pass (the flight data's wide-band columns, aerosid.identification.flight_data.
    WIDEBAND_COLUMNS; rows where one is NaN are left out); LP: the band's low-pass on every
    run of consecutive rows (:func:`flight_data_runs`); m: the channel's model fitted to the
    flight data.  Both sides are formed from the same x, so the band's own attenuation cancels
    and only the model's non-linearity is left.  The first and last band period of every run
    (the filter's transients) are left out of the RMS.  Empty without those columns (the
    smoother path, older files).  model_signals: the model signals of fd when the caller has them
    (the diagnosis' own), else derived here."""
    from aerosid.diagnosis.candidates import derived_signals
    from aerosid.diagnosis.lookalikes import scaled_lstsq
    from aerosid.identification.band import low_pass_runs
    from aerosid.identification.flight_data import WIDEBAND_COLUMNS
    from aerosid.identification.inversion import total_angles
    from aerosid.modelling.models import vehicle_signals

    channels = [ch for ch in channels if ch in models and ch in fd]
    need = {*WIDEBAND_COLUMNS, *WIDEBAND_COLUMNS.values(), "band_hz", "t_s", "mach", "qbar_pa"}
    if not channels or len(fd) < 3 or not need <= set(fd.columns):
        return {}
    # rows without their wide-band values (pooled with older files, or the inversion of the
    # smoother's forces at the database's edge) end a run and are not counted
    valid = np.all(np.column_stack([np.isfinite(fd[w].to_numpy(float)) for w in WIDEBAND_COLUMNS.values()]), axis=1)
    runs = flight_data_runs(fd, valid)
    if not runs:
        return {}

    def low_pass(x):  # rows outside every run are left as they are (and out of the RMS)
        out = np.array(x, float)
        for r, fs, band, _ in runs:
            out[r] = low_pass_runs(x[r], fs, band, [slice(0, r.stop - r.start)])
        return out

    def signals(values: dict):
        frame = fd.copy()
        for c, v in values.items():
            frame[c] = v
        v_ratio = frame["V_m_s"].to_numpy(float) / fd["V_m_s"].to_numpy(float)
        frame["mach"] = fd["mach"].to_numpy(float) * v_ratio  # the same speed of sound and density
        frame["qbar_pa"] = fd["qbar_pa"].to_numpy(float) * v_ratio ** 2
        frame["alpha_r_rad"], frame["phi_r_rad"] = total_angles(frame["alpha_rad"], frame["beta_rad"])
        return derived_signals(vehicle_signals(frame, vehicle), vehicle.length_pitch_m, vehicle.length_lateral_m)

    # (outside the runs the low-passed values stand in, only so that every signal is finite)
    wide = {c: np.where(valid, fd[w].to_numpy(float), fd[c].to_numpy(float)) for c, w in WIDEBAND_COLUMNS.items()}
    if not all(np.isfinite(x).all() for x in wide.values()):
        return {}
    inner = np.zeros(len(fd), bool)
    for r, _, _, edge in runs:
        inner[r.start + edge:r.stop - edge] = True
    sig_fd = model_signals if model_signals is not None else derived_signals(
        vehicle_signals(fd, vehicle), vehicle.length_pitch_m, vehicle.length_lateral_m)
    sig_w, sig_lp = signals(wide), signals({c: low_pass(x) for c, x in wide.items()})
    out = {}
    for ch in channels:
        A = models[ch].design(sig_fd)[0].to_numpy(float)
        y = fd[ch].to_numpy(float)
        ok = np.all(np.isfinite(A), axis=1) & np.isfinite(y)
        if ok.sum() <= A.shape[1]:
            continue
        theta = scaled_lstsq(A[ok], y[ok])
        m_lp = models[ch].design(sig_lp)[0].to_numpy(float) @ theta
        m_w = models[ch].design(sig_w)[0].to_numpy(float) @ theta
        m_w = np.where(np.isfinite(m_w), m_w, m_lp)  # a non-finite value would spread over its whole run
        d = low_pass(m_w) - m_lp
        use = inner & ok & np.isfinite(d)
        # what a refit leaves of it: the part the model's own columns can take is taken
        e = d[use] - A[use] @ scaled_lstsq(A[use], d[use]) if use.sum() > A.shape[1] else d[use]
        out[ch] = _rms(e)
    return out


def flight_data_runs(fd, valid: np.ndarray | None = None) -> list[tuple[slice, float, float, int]]:
    """(rows, sample rate [Hz], band edge [Hz], edge samples = one band period) of every run of
    consecutive flight-data rows: one flight segment (its own rate and band), adjacent rows, time
    increasing by at most 1.5 of the segment's steps, ``valid`` (default all), and longer than two
    band periods and 16 samples.  Rows are expected in flight and time order (as diagnose sorts
    them); a segment whose rows are not adjacent is cut where they are not."""
    t = fd["t_s"].to_numpy(float)
    valid = np.ones(len(fd), bool) if valid is None else np.asarray(valid, bool)
    out = []
    for idx, fs, band in segment_rates_and_bands(fd):
        if not (math.isfinite(fs) and math.isfinite(band)) or idx.size < 2:
            continue
        edge = int(math.ceil(fs / band - 1e-6))
        dt = np.diff(t[idx])
        joined = np.r_[False, (np.diff(idx) == 1) & (dt > 0) & (dt <= 1.5 / fs)]
        for r in finite_runs(valid[idx]):
            cuts = [r.start, *(r.start + 1 + np.flatnonzero(~joined[r.start + 1:r.stop])), r.stop]
            for a, b in zip(cuts[:-1], cuts[1:]):
                if b - a > 2 * edge + 16:
                    out.append((slice(int(idx[a]), int(idx[a]) + int(b - a)), fs, band, edge))
    return out


def floors(residuals: dict, flight_data, angle_rms: dict | None = None, vehicle=None,
           nonlinearity_rms: dict | None = None) -> dict[str, ChannelFloor]:
    """{channel: ChannelFloor} from {channel: residual array} and the flight-data rows they
    belong to: the band path's sigma (:func:`band_sigmas`, needs the vehicle) where the flight
    data carry what it needs, else their ``sigma_<channel>`` columns; angle_rms: {channel:
    the angles' part} (:func:`angle_floor_rms`); nonlinearity_rms: {channel: the band path's
    non-linearity} (:func:`band_nonlinearity_rms`)."""
    angle_rms = angle_rms or {}
    nonlinearity_rms = nonlinearity_rms or {}
    band = band_sigmas(flight_data, vehicle) if vehicle is not None else None
    out = {}
    for ch, r in residuals.items():
        if band is not None and ch in band:
            sigma, method = band[ch], "band path: the sensors' noise (the filter's R) through the band"
        else:
            sigma = flight_data[f"sigma_{ch}"].to_numpy(float) if f"sigma_{ch}" in flight_data else None
            method = "smoother sigma"
        out[ch] = channel_floor(ch, r, sigma, angle_rms.get(ch, 0.0), method, nonlinearity_rms.get(ch, 0.0))
    return out


def floor_table(floor: dict) -> list[str]:
    """Lines of the summary: residual, floor and the excess over it per channel."""
    lines = ["The error against its floor (floor = what a complete model would leave: the flight-derived "
             "coefficient's own error and the recovered angles' error through the model, from the sensors' white "
             "noise, and the band path's low-pass taken before the model's non-linear terms, in quadrature; "
             "excess = sqrt(residual^2 - floor^2): what a model term could still remove, or an error the floor "
             "does not know, e.g. turbulence, sensor biases, timing or the force database's own error in the "
             "inverted angles):",
             f"  {'channel':<8}{'residual':>11}{'floor':>11}{'excess':>11}{'excess/residual':>17}"
             f"{'coefficient':>13}{'angles':>10}{'band':>10}"]
    for ch, f in floor.items():
        share = f.excess_share
        lines.append(f"  {ch:<8}{f.residual_rms:>11.3g}{f.floor_rms:>11.3g}{f.excess_rms:>11.3g}"
                     f"{(f'{share:.0%}' if math.isfinite(share) else 'nan'):>17}{f.coefficient_floor_rms:>13.3g}"
                     f"{f.angle_floor_rms:>10.3g}{f.nonlinearity_floor_rms:>10.3g}")
    return lines
