"""Regression stage: fit each channel's model to the flight data (method.md §11).

Produces the coefficients table (``coefficients.parquet``) and a Table-3-style
report: preflight vs flight estimate vs sigma (coloured-residual corrected, and
plain least squares) vs F, printed per degree as the seed does.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from aerosid.modelling.aeromodel import AeroModel
from aerosid.identification.eiv import (CORRECTION_SHARE, LAMBDAS, LAMBDAS_BY_SOURCE, information_reliability,
                                        profile_direction, simex_estimates)
from aerosid.identification.crb import identification_bounds
from aerosid.modelling.models import ChannelModel, default_models, signals_from_flight_data, vehicle_signals
from aerosid.plausibility.estimates import preflight_departure
from aerosid.identification.regression import LinearFit, fit_linear, with_corrected_estimate, with_posterior
from aerosid.identification.damping_prior import (PRIOR_SHARE, PRIOR_SHARE_SIGMA, damping_terms, split_row,
                                                   split_update)
from aerosid.vehicles.vehicle import Vehicle

#: Coefficients that are slopes per radian (the report prints them per degree); the rest are per unit term.
ANGLE_TERMS = ("alpha", "beta", "alpha_r", "delta_p/2", "delta_y/2", "delta_r", "delta_p", "delta_y")


@dataclass(frozen=True)
class Identification:
    """Fits per channel on the samples inside the Mach window."""

    fits: dict  # channel -> LinearFit
    models: dict  # channel -> ChannelModel
    references: dict  # coefficient -> preflight value about the CG (per rad)
    n_samples: int
    mach_window: tuple[float, float]
    #: channels whose fit is an identity by construction (alpha, beta inverted from them)
    identities: tuple[str, ...] = ()
    #: estimates beyond preflight x/÷ this factor are reported (vehicle [plausibility])
    preflight_factor: float = 3.0
    #: coefficient -> Cramér-Rao bound on its std (aerosid.identification.crb), NaN where none
    crb_std: dict = field(default_factory=dict)
    #: coefficient -> its t before the model-structure mixture, for the damping terms whose whole 95 %
    #: interval was positive (term_report.wrong_sign_damping); the table's ``wrong_sign`` column
    wrong_sign: dict = field(default_factory=dict)
    #: +/- pairs of the estimator-bias check counted in the sigma (aerosid.identification.bias_check); 0: none
    bias_pairs: int = 0

    def table(self, alpha: float = 0.05) -> pd.DataFrame:
        """The coefficients.parquet rows.  A channel in ``identities`` is reported without
        numbers: its fit returns the preflight database by construction (``note`` says so)."""
        rows = []
        for channel, fit in self.fits.items():
            identity = channel in self.identities
            for rec in fit.as_records(alpha):
                if identity:
                    rec = {**rec, **{k: np.nan for k in ("estimate", "std_error", "std_error_ols", "ci_low",
                                                         "ci_high", "t_value", "p_value")}}
                ident = bool(np.isfinite(rec["estimate"]))
                reference = float(self.references.get(rec["coefficient"], np.nan))
                ratio, departure = preflight_departure(float(rec["estimate"]), float(rec["std_error"]), reference,
                                                       self.preflight_factor)
                rows.append({
                    "channel": channel, "coefficient": rec["coefficient"],
                    "estimate": float(rec["estimate"]), "std_error": float(rec["std_error"]),
                    "std_error_ols": float(rec["std_error_ols"]),
                    "crb_std": float(self.crb_std.get(rec["coefficient"], np.nan)) if ident else np.nan,
                    "ci_low": float(rec["ci_low"]),
                    "ci_high": float(rec["ci_high"]), "reference": float(self.references.get(rec["coefficient"], np.nan)),
                    "t_value": float(rec["t_value"]), "p_value": float(rec["p_value"]),
                    "identifiable": ident, "note": IDENTITY_NOTE if identity else "",
                    "expression": next((t.expression for t in self.models[channel].terms
                                        if t.coefficient == rec["coefficient"]), ""),
                    "f_stat": float(fit.f_stat), "f_stat_corrected": float(fit.f_stat_corrected),
                    "r2": float(fit.r2), "pse": float(fit.pse), "rms_residual": float(fit.rms_residual),
                    "condition_number": float(fit.condition_number), "n_obs": int(fit.n_obs),
                    "n_eff": float(fit.n_eff), "warnings": " | ".join(fit.warnings),
                    "preflight_ratio": ratio, "preflight_warning": departure,
                    "wrong_sign": rec["coefficient"] in self.wrong_sign,
                })
        return pd.DataFrame(rows)

    def summary(self) -> str:
        head = (f"Regression on {self.n_samples} samples, Mach {self.mach_window[0]:.2f}..{self.mach_window[1]:.2f}")
        return head + "\n" + format_table(self.table())


def format_table(table: pd.DataFrame, per_degree: bool = False) -> str:
    """Seed Table 3 style text of a coefficients table: preflight vs estimate vs sigma
    (corrected and plain OLS) vs CRB vs F.  SI per radian for every coefficient (slopes and rate
    derivatives alike); per_degree: per degree instead (aerosid.identification.coefficient_units), and
    the header says which.  CRB = Cramer-Rao bound on the std from the gyros' and
    accelerometers' noise (aerosid.identification.crb)."""
    from aerosid.identification.coefficient_units import per_degree_factor, unit_label, units_header
    from aerosid.identification.term_report import UNDETERMINED_NOTE, WRONG_SIGN_NOTE, undetermined, wrong_sign

    lines = [f"moments about the CG; {units_header(per_degree)}; CRB = Cramér-Rao bound on the std from the "
             "gyros' and accelerometers' noise (aerosid.identification.crb)",
             f"{'coefficient':<20}{'preflight':>12}{'estimate':>12}{'sigma':>11}{'sigma OLS':>11}{'CRB':>11}"
             f"{'95% interval':>26}  unit"]
    weak_terms = set(undetermined(table))
    signed_terms = set(wrong_sign(table))
    for channel, rows in table.groupby("channel", sort=False):
        first = rows.iloc[0]
        lines.append(f"[{channel}]  F = {first['f_stat']:,.0f} (corrected {first['f_stat_corrected']:,.1f}), "
                     f"R^2 = {first['r2']:.4f}, PSE = {first['pse']:.3g}, condition number "
                     f"{first['condition_number']:.1f}, N = {first['n_obs']} (effective {first['n_eff']:.0f})")
        for _, row in rows.iterrows():
            k = per_degree_factor(row["expression"]) if per_degree else 1.0
            u = unit_label(row["expression"], per_degree) or "-"
            ref = f"{row['reference'] * k:>12.5g}" if np.isfinite(row["reference"]) else f"{'-':>12}"
            if not np.isfinite(row["estimate"]):  # no number is printed for what the data cannot tell
                why = row.get("note") or f"no excitation in {row['expression']}"
                lines.append(f"  {row['coefficient']:<18}{ref}   not identifiable ({why})")
                continue
            weak = row["coefficient"] in weak_terms
            lines.append(f"  {row['coefficient']:<18}{ref}{row['estimate'] * k:>12.5g}"
                         f"{row['std_error'] * k:>11.2g}{row['std_error_ols'] * k:>11.2g}"
                         f"{row.get('crb_std', np.nan) * k:>11.2g}"
                         f"{'[' + format(row['ci_low'] * k, '.5g') + ', ' + format(row['ci_high'] * k, '.5g') + ']':>26}"
                         f"  {u}" + (f"   <- {UNDETERMINED_NOTE}" if weak else "")
                         + (f"   <- {WRONG_SIGN_NOTE}" if row["coefficient"] in signed_terms else ""))
        for i, w in enumerate(w for w in first["warnings"].split(" | ") if w):
            lines.append(f"  warning [{i + 1}] {w}")
    if "preflight_warning" in table.columns:
        far = table[table["preflight_warning"].fillna("").astype(bool)]
        for _, row in far.iterrows():
            lines.append(f"!! WARNING {row['coefficient']}: {row['preflight_warning']}")
    return "\n".join(lines)


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


def _rate_eiv_sigma(fd: pd.DataFrame):
    """(sigma_p, sigma_q, sigma_r) [rad/s] per sample of the gyros' white noise whose
    band-limited part is in the flight data's rates, or None when the rates are taken as
    exact: flight data without the eiv_sigma_p/q/r columns (written before they existed, or
    the smoother's rates), or with them all zero or not finite."""
    if not set(RATE_EIV_COLUMNS) <= set(fd.columns):
        return None
    sig = tuple(fd[c].to_numpy(float) for c in RATE_EIV_COLUMNS)
    if all(np.all(np.isfinite(x)) for x in sig) and max(float(x.max(initial=0.0)) for x in sig) > 0:
        return sig
    return None


def _control_eiv_sigma(fd: pd.DataFrame):
    """(sigma_delta_p, sigma_delta_y, sigma_delta_r) [rad] per sample of the mixed surfaces' white
    noise whose band-limited part is in the flight data's controls (flight_data.CONTROL_NOISE_COLUMNS,
    measured from the fins' second differences), or None when the controls are taken as exact:
    flight data without those columns, or with them all zero (quantised or held surfaces) or not
    finite."""
    from aerosid.identification.flight_data import CONTROL_NOISE_COLUMNS

    cols = tuple(CONTROL_NOISE_COLUMNS[c] for c in ("delta_p", "delta_y", "delta_r"))
    if not set(cols) <= set(fd.columns):
        return None
    sig = tuple(fd[c].to_numpy(float) for c in cols)
    if all(np.all(np.isfinite(x)) for x in sig) and max(float(x.max(initial=0.0)) for x in sig) > 0:
        return sig
    return None


#: A control whose white noise through the band is more than this share of its variance in the
#: fit window gets a warning on every term that reads it: a share s attenuates such a term's
#: estimate by about s (errors in variables; corrected by SIMEX with control_eiv, the default).
CONTROL_NOISE_SHARE = 0.05


def control_noise_warnings(fd: pd.DataFrame, models: dict, skip=(), corrected: bool = False) -> dict[str, str]:
    """{channel: warning} for the channels with terms that read a control whose own noise is a
    sizeable share of its variation in this flight data (CONTROL_NOISE_SHARE): the flight
    data's eiv_sigma_delta_*_rad (the mixed surfaces' white noise, aerosid.identification.
    flight_data) through the band's low-pass against the control's variance.  Measured on the
    JSBSim A320 (rudder doublet against the yaw damper): the rudder moved 2.8e-4 rad in the
    band and its surfaces' 0.05 deg noise is 1.1e-4 rad there (a share of ~15 %).  The noise
    goes through each flight segment's own band and sample rate.  skip: channels not to warn on
    (the identities alpha and beta are inverted from).  corrected: the estimates were corrected
    for that noise (SIMEX, control_eiv), so the warning says so instead of "low by".  Empty for
    flight data without those columns or without a band."""
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
                effect = ("corrected for it by SIMEX, with a wider sigma" if corrected else
                          f"the controls are taken as exact, so these estimates are low by about {share:.0%} "
                          "(errors in variables, not corrected)")
                text = (f"{', '.join(names)}: {c} moves only {spread / noise:.1f} x its own noise in the band "
                        f"(std {spread:.2g} rad against {noise:.2g} rad of surface-sensor noise through the band); "
                        f"{effect}: excite the control more")
                out[ch] = f"{out[ch]}; {text}" if ch in out else text
    return out


#: Channels whose flight values define the angles for a vehicle without vanes (alpha, beta
#: are inverted from C_N and C_Y): their fits are identities, not estimates.
INVERSION_CHANNELS = ("CN", "CY")
IDENTITY_NOTE = ("not identifiable from this telemetry: alpha/beta are inverted from this channel through the "
                 "preflight force database, so the fit returns that database by construction")


def identity_channels(vehicle, channels) -> tuple[str, ...]:
    """The channels that are identities by construction: C_N and C_Y when alpha and beta
    are inverted from them (no vanes), those of ``channels`` (names, or a dict keyed by them)."""
    if getattr(vehicle, "air_data_source", None) == "vanes":
        return ()
    return tuple(ch for ch in INVERSION_CHANNELS if ch in channels)


def _eiv_corrected(fd: pd.DataFrame, vehicle: Vehicle, models: dict, fits: dict, sigma,
                   rate_sigma=None, control_sigma=None) -> dict:
    """The fits with their estimates corrected for the noise in alpha and beta and, given
    rate_sigma, in the band-limited rates p, q, r, and, given control_sigma, in the band-limited
    controls (aerosid.identification.eiv, SIMEX); for inverted angles the force channels they come
    from are left as they are."""
    skip = identity_channels(vehicle, fits)
    ok = {ch: f for ch, f in fits.items()
          if np.all(np.isfinite(f.estimate)) and f.n_dropped == 0 and ch not in skip}
    if not ok:
        return fits

    def design(frame: pd.DataFrame) -> dict:
        sig = vehicle_signals(frame, vehicle)
        return {ch: models[ch].regressors(sig).to_numpy(float) for ch in ok}

    band = fd["band_hz"].to_numpy(float) if "band_hz" in fd.columns else None
    corrected = simex_estimates(fd, {ch: fd[ch].to_numpy(float) for ch in ok}, design, sigma,
                                angle_cutoff_hz(fd, vehicle), rate_sigma, band if rate_sigma is not None else None,
                                lambdas=simex_lambdas(vehicle, angles=sigma is not None),
                                control_sigma=control_sigma,
                                control_cutoff_hz=band if control_sigma is not None else None)
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
    share = correction_share(vehicle, angles=sigma is not None)
    part = "the correction itself" if share == 1 else f"{share:.0%} of the correction"
    note = head + (f"; sigma scaled by the correction and combined with the correction's own error (at least {part}: "
                   "SIMEX's quadratic extrapolant leaves part of a large attenuation, or overshoots it); residual "
                   "statistics are the uncorrected fit's")
    return {ch: with_corrected_estimate(f, corrected[ch].corrected, note,
                                        corrected[ch].std_error(f.std_error, correction_share=share),
                                        corrected[ch].information())
            if ch in corrected else f for ch, f in fits.items()}


def correction_share(vehicle: Vehicle, angles: bool = True) -> float:
    """The share of SIMEX's correction counted as its own 1-sigma (aerosid.identification.eiv
    CORRECTION_SHARE) for the vehicle's angle source; a source nobody measured raises KeyError.
    angles=False (the rates' noise alone, gyro_eiv without angle noise): the vanes' larger share."""
    return CORRECTION_SHARE[vehicle.air_data_source if angles else "vanes"]


def simex_lambdas(vehicle: Vehicle, angles: bool = True) -> tuple:
    """SIMEX's extra-noise levels (aerosid.identification.eiv LAMBDAS_BY_SOURCE) for the vehicle's
    angle source; angles=False (the gyros' noise alone): the usual LAMBDAS, where the rates' part
    was measured (bench/results/gyro_simex.md).  A source nobody measured raises KeyError."""
    return LAMBDAS_BY_SOURCE[vehicle.air_data_source] if angles else LAMBDAS


def angle_cutoff_hz(fd: pd.DataFrame, vehicle: Vehicle) -> float | None:
    """The low-pass the vane angles went through [Hz]: the flight data's common band
    (aerosid.identification.band) when it has one, else the vehicle file's vane corner."""
    if "band_hz" in fd.columns:
        band = fd["band_hz"].to_numpy(float)
        if band.size and np.all(np.isfinite(band)):
            return float(np.median(band))
    return vehicle.vane_cutoff_hz


#: Fewest flight-data samples (inside the Mach window) a fit accepts.
MIN_FIT_SAMPLES = 50


def mach_window_mask(mach: np.ndarray, reference: float, half_width: float | None) -> np.ndarray:
    if half_width is None:
        return np.ones(len(mach), dtype=bool)
    return np.abs(mach - reference) <= half_width


#: The rates' part of SIMEX is off by default.  Right in isolation (it moves C_m_alpha toward the
#: true-rates answer on F4N, OV10 and pa28, bench/results/gyro_simex.md), but joined to the
#: angles' SIMEX, which under-corrects the vane noise in alpha_dot_hat, it made the estimates
#: worse on three of the four aircraft measured, including T37, which it had not been developed
#: on (generalisation bench, 10 seeds, C_m_alpha mean error off -> on: OV10 +3.0 -> +0.9 %,
#: T37 -1.4 -> -5.2 %, F4N -4.6 -> -6.1 %, pa28 -4.0 -> -4.6 %; docs/estimation.md).
GYRO_EIV_DEFAULT = False
#: The controls' part of SIMEX (the surfaces' white noise, flight data eiv_sigma_delta_*_rad) is on
#: by default: see docs/estimation.md, "Errors in the controls".
CONTROL_EIV_DEFAULT = True

#: Antithetic pairs of re-draws of the parametric check of the estimator's own bias
#: (aerosid.identification.bias_check): the flight's regressors taken as the truth, the sensors'
#: known noise drawn again (+ and -), the whole fit repeated; the mean change is the estimator's
#: bias at this flight's noise, counted in sigma.  It costs 2 x BIAS_PAIRS fits more.
BIAS_PAIRS = 3
#: Environment variable that overrides BIAS_PAIRS (0: no check, e.g. a quick look at a flight;
#: the test suite sets it outside the check's own tests).
BIAS_PAIRS_ENV = "AEROSID_BIAS_PAIRS"


def default_bias_pairs() -> int:
    """BIAS_PAIRS, or the environment's AEROSID_BIAS_PAIRS (0, or an integer >= 2)."""
    text = os.environ.get(BIAS_PAIRS_ENV, "").strip()
    if not text:
        return BIAS_PAIRS
    if not text.isdigit():
        raise ValueError(f"{BIAS_PAIRS_ENV}={text!r}: give a non-negative integer (0 turns the estimator-bias "
                         "check off; aerosid.identification.bias_check)")
    return _checked_bias_pairs(int(text), f"{BIAS_PAIRS_ENV}=")


def _checked_bias_pairs(pairs: int, where: str = "bias_pairs = ") -> int:
    """pairs if it is 0 (no check) or >= 2, else a ValueError naming ``where`` it came from."""
    if pairs == 1 or pairs < 0:
        raise ValueError(f"{where}{pairs}: 0 (no check) or at least 2 (the check's Monte-Carlo error is the "
                         "spread of its pairs; aerosid.identification.bias_check)")
    return pairs


def with_pitch_damping_prior(vehicle: Vehicle, models: dict, fits: dict) -> tuple[dict, dict[str, tuple[str, ...]]]:
    """(fits, covered): the fits with the prior on an aircraft's pitch-damping split combined into
    its C_m fit (aerosid.identification.damping_prior), and {channel: the two coefficients whose
    split the prior holds} for the model-structure mixture to leave alone.  Only for an aircraft
    whose prior is not off (``[estimation] pitch_damping_split = false``) and whose C_m model has
    one pure q_hat and one pure alpha_dot_hat term; when the prior cannot be applied to such a
    fit, its warnings say why."""
    setting = vehicle.pitch_damping_split
    fit = fits.get("Cm")
    if vehicle.vehicle_class != "aircraft" or setting is False or fit is None or "Cm" not in models:
        return fits, {}
    terms = damping_terms([t.expression for t in models["Cm"].terms])
    if terms is None:
        return fits, {}
    share, sigma = (PRIOR_SHARE, PRIOR_SHARE_SIGMA) if setting is True else setting
    (iq, cq), (ia, ca) = terms
    upd = split_update(fit.estimate, fit.cov, iq, ia, share, sigma, (cq, ca),
                       *split_information(fit, iq, ia, share, (cq, ca)))
    if isinstance(upd, str):
        note = f"pitch-damping split prior not applied: {upd} (aerosid.identification.damping_prior)"
        return {**fits, "Cm": replace(fit, warnings=tuple(fit.warnings) + (note,))}, {}
    return ({**fits, "Cm": with_posterior(fit, upd.estimate, upd.cov, upd.summary())},
            {"Cm": (fit.names[iq], fit.names[ia])})


def split_information(fit: LinearFit, iq: int, ia: int, share: float, factors: tuple[float, float]
                      ) -> tuple[float, np.ndarray | None]:
    """(reliability, coupling) of the pitch-damping split for damping_prior.split_update, from the
    errors-in-variables correction's X^T X (LinearFit.information_eiv): the share of the fit's
    apparent information on the split that is signal (eiv.information_reliability along the
    prior's row, damping_prior.split_row), and how the other coefficients follow C_m,alpha_dot
    on the noise-free regressors (eiv.profile_direction).  (1, None) when the fit has none
    (exact angles) or a coefficient is not finite."""
    if fit.information_eiv is None or not np.all(np.isfinite(fit.estimate)):
        return 1.0, None
    gram_naive, gram_corrected = fit.information_eiv
    row = split_row(fit.estimate.size, iq, ia, share, factors)
    return information_reliability(gram_naive, gram_corrected, row), profile_direction(gram_corrected, ia)


#: Widen the sigma of the coefficients that depend on a term the flight does not determine
#: (aerosid.identification.structure_uncertainty).
STRUCTURE_UNCERTAINTY = True


def wrong_sign_terms(models: dict, fits: dict) -> dict[str, float]:
    """{coefficient: t} of the pure damping terms whose whole 95 % interval is positive
    (term_report.wrong_sign_damping), on the fits as given (before any model-structure mixture);
    a term without a finite interval is left out."""
    from aerosid.identification.term_report import wrong_sign_damping

    out = {}
    for ch, fit in fits.items():
        ci = fit.conf_int()
        for j, term in enumerate(models[ch].terms):
            if j < len(ci) and np.isfinite(fit.estimate[j]) and wrong_sign_damping(ch, term.expression, ci[j][0]):
                out[fit.names[j]] = float(fit.t_values[j])
    return out


def _with_structure_uncertainty(fd: pd.DataFrame, signals: dict, models: dict, fits: dict,
                                flagged: dict[str, float] | None = None,
                                covered: dict[str, tuple[str, ...]] | None = None) -> dict:
    """The fits whose sigma include the model-structure part of a term whose interval holds 0, or
    of a damping term whose whole interval is positive (wrong_sign_terms: the flight says it is
    there, with a sign damping seldom has, so the model without it is taken as likely).  For a
    wrong-sign term the mixture is always applied, so its own interval includes the model without
    it (it then holds 0 unless t > ~9.9); a term whose interval holds 0 changes the fit only where
    a partner's sigma moves by more than 5 %.  flagged: wrong_sign_terms(models, fits) when the
    caller has it already (None: computed here); covered: {channel: coefficients} a prior already
    holds the model without (with_pitch_damping_prior): their "interval holds 0" is left to it (a
    wrong-sign mark still takes the mixture)."""
    from aerosid.identification.regression import with_added_covariance
    from aerosid.identification.structure_uncertainty import structure_covariance
    from aerosid.identification.term_report import _is_constant, damping_signal, interval_includes_zero

    flagged = wrong_sign_terms(models, fits) if flagged is None else flagged
    out = {}
    for ch, fit in fits.items():
        est = np.asarray(fit.estimate, float)
        if not np.all(np.isfinite(est)) or len(est) < 2:
            out[ch] = fit
            continue
        ci = fit.conf_int()
        exprs = [t.expression for t in models[ch].terms]
        holds0 = np.array([interval_includes_zero(*ci[j]) and not _is_constant(exprs[j]) for j in range(len(est))])
        signs = np.array([fit.names[j] in flagged for j in range(len(est))])
        # a prior that holds the model without the term covers "its interval holds 0"; a damping of
        # the wrong sign the flight pins down is the data's, and keeps its mixture
        holds0 &= ~np.array([fit.names[j] in (covered or {}).get(ch, ()) for j in range(len(est))])
        weak = holds0 | signs
        if not weak.any():
            out[ch] = fit
            continue
        X = models[ch].regressors(signals).to_numpy(float)
        extra, changes = structure_covariance(X, fd[ch].to_numpy(float), est, weak)
        se = np.sqrt(np.clip(np.diag(fit.cov + extra), 0.0, None))
        moved = [fit.names[k] for k in range(len(est)) if not weak[k] and se[k] > 1.05 * fit.std_error[k]]
        if not moved and not signs.any():
            out[ch] = fit
            continue
        why = []
        if holds0.any():
            why.append(f"{', '.join(fit.names[j] for j in np.flatnonzero(holds0))}: not determined by this flight "
                       "(95 % interval holds 0)")
        for j in np.flatnonzero(signs):
            rate = damping_signal(ch, exprs[j])
            cause = ("alpha-dot read off noisy angles" if rate == "alpha_dot_hat" else f"the noise in {rate}")
            why.append(f"{fit.names[j]}: positive at 95 % (t = {fit.t_values[j]:.2g}), a sign damping seldom has "
                       f"(suspect {cause} or its collinearity with the other regressors); its own interval includes "
                       "the model without it")
        note = "; ".join(why) + (f"; the sigma of {', '.join(moved)} include how their estimates change when "
                                 f"{'it is' if len(changes) == 1 else 'each is'} dropped" if moved else "")
        out[ch] = with_added_covariance(fit, extra, note + " (model-structure uncertainty, "
                                        "aerosid.identification.structure_uncertainty)")
    return out


def identify(flight_data: pd.DataFrame, vehicle: Vehicle, models: dict[str, ChannelModel] | None = None,
             mach_half_width: float | None = 0.5, cov: str = "morelli_klein",
             gyro_eiv: bool = GYRO_EIV_DEFAULT, bias_pairs: int | None = None,
             instrumental: bool | None = None, control_eiv: bool = CONTROL_EIV_DEFAULT) -> Identification:
    """Fit every channel's model on the samples with |M - M_ref| <= mach_half_width.
    Pooled flights (several values of ``flight``: manoeuvres of one aircraft) are fitted
    together; the coloured-residual correction treats each flight as its own record
    (``fit_linear(groups=...)``).  The estimates are corrected for the noise in the angles
    and (gyro_eiv, the flight data's eiv_sigma_p/q/r columns) in the rates by SIMEX
    (aerosid.identification.eiv); gyro_eiv=False (the default, GYRO_EIV_DEFAULT): the angles only.
    control_eiv (default CONTROL_EIV_DEFAULT, True): the same for the controls' surface-sensor
    noise (the flight data's eiv_sigma_delta_*_rad; zero for quantised or held surfaces).
    bias_pairs: +/- pairs of re-draws of the parametric check of the estimator's own bias at this
    flight's noise, counted in the sigma (aerosid.identification.bias_check); 0: no check; None:
    default_bias_pairs().  instrumental: the flight was flown in turbulent air: every channel but the
    identities is fitted by instrumental variables, the controls as instruments, in place of least
    squares and SIMEX (aerosid.identification.instrumental); None: the vehicle file's
    ``[estimation] turbulent_air`` (default false)."""
    models = models or default_models(vehicle)
    fd = flight_data.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    mask = mach_window_mask(fd["mach"].to_numpy(), vehicle.mach_reference, mach_half_width)
    span = (f"the flight data's {len(fd)} samples span Mach {fd['mach'].min():.3g}..{fd['mach'].max():.3g}"
            if len(fd) else "the flight data is empty")
    fd = fd.loc[mask].reset_index(drop=True)
    if len(fd) < MIN_FIT_SAMPLES:
        window = ("the whole flight (no Mach window)" if mach_half_width is None else
                  f"the Mach window |M - {vehicle.mach_reference:g}| <= mach_half_width = {mach_half_width:g} "
                  f"(mach_reference from [aero] of {vehicle.source}; widen it with --mach-half-width on aerosid "
                  "run, fit or diagnose)")
        raise ValueError(f"only {len(fd)} samples inside {window}: too few to fit the models, at least "
                         f"{MIN_FIT_SAMPLES} are needed ({span})")
    bias_pairs = default_bias_pairs() if bias_pairs is None else _checked_bias_pairs(bias_pairs)
    instrumental = vehicle.turbulent_air if instrumental is None else bool(instrumental)
    identities = identity_channels(vehicle, models)
    signals = vehicle_signals(fd, vehicle)
    corrected = _corrected_fits(fd, vehicle, models, cov, gyro_eiv, signals, instrumental, control_eiv)
    fits, wrong_sign = _with_prior_and_structure(fd, signals, vehicle, models, corrected, identities,
                                                 control_eiv and not instrumental)
    if bias_pairs:
        from aerosid.identification.bias_check import with_estimator_bias

        # the check runs on the estimator before the prior: the world's coefficients are the flight's
        # own, so a prior applied again would count as bias (its own spread is in the posterior)
        fits = with_estimator_bias(fd, vehicle, models, corrected, fits,
                                   lambda f: _corrected_fits(f, vehicle, models, cov, gyro_eiv,
                                                             instrumental=instrumental, control_eiv=control_eiv),
                                   bias_pairs,
                                   skip=identities)
    refs = AeroModel.preflight(vehicle).linear_truth() if vehicle.preflight is not None else {}
    window = (float(fd["mach"].min()), float(fd["mach"].max()))
    crb = identification_bounds(fd, vehicle, models, fits, identities)
    return Identification(fits, dict(models), refs, len(fd), window, identities, vehicle.envelope.preflight_factor,
                          crb.std, wrong_sign, bias_pairs)


def _corrected_fits(fd: pd.DataFrame, vehicle: Vehicle, models: dict, cov: str, gyro_eiv: bool,
                    signals: dict | None = None, instrumental: bool = False,
                    control_eiv: bool = CONTROL_EIV_DEFAULT) -> dict[str, LinearFit]:
    """Every channel's fit on the window's flight data ``fd`` (sorted, inside the Mach window):
    least squares with the coloured-residual sigma and the errors-in-variables correction, or,
    with ``instrumental``, the instrumental-variable fit (aerosid.identification.instrumental,
    consistent under the regressors' noise too: no SIMEX) of every channel but the identities.
    signals: vehicle_signals(fd, vehicle) when the caller has them (None: computed here)."""
    signals = vehicle_signals(fd, vehicle) if signals is None else signals
    flights = fd["flight"].astype(str).to_numpy()
    fits: dict[str, LinearFit] = {}
    designs: dict[str, tuple] = {}  # channel -> (regressors, notes)
    for channel, model in models.items():
        X, notes = designs[channel] = model.design(signals)
        try:
            fit = fit_linear(fd[channel].to_numpy(float), X, names=model.names, channel=channel, cov=cov,
                             groups=flights)
        except ValueError as exc:
            raise ValueError(f"[{channel}] the fit of {', '.join(model.names)} on {len(fd)} samples failed: {exc}"
                             + (f" ({'; '.join(notes)})" if notes else "")) from None
        fits[channel] = replace(fit, warnings=tuple(fit.warnings) + notes) if notes else fit
    if instrumental:
        from aerosid.identification.instrumental import control_instruments, instrumental_fit

        Z = control_instruments(fd)
        skip = identity_channels(vehicle, fits)
        return {ch: fit if ch in skip else
                instrumental_fit(fit, fd[ch].to_numpy(float), designs[ch][0].to_numpy(float), Z, flights)
                for ch, fit in fits.items()}
    sigma = angle_eiv_sigma(fd, vehicle)
    band_limited = "band_hz" in fd.columns and bool(np.all(np.isfinite(fd["band_hz"].to_numpy(float))))
    rate_sigma = _rate_eiv_sigma(fd) if gyro_eiv and band_limited else None
    control_sigma = _control_eiv_sigma(fd) if control_eiv and band_limited else None
    if sigma is not None or rate_sigma is not None or control_sigma is not None:
        fits = _eiv_corrected(fd, vehicle, models, fits, sigma, rate_sigma, control_sigma)
    return fits


def _with_prior_and_structure(fd: pd.DataFrame, signals: dict, vehicle: Vehicle, models: dict,
                              fits: dict[str, LinearFit], identities: tuple[str, ...],
                              controls_corrected: bool = False) -> tuple[dict[str, LinearFit], dict[str, float]]:
    """(fits, wrong-sign damping terms): the corrected fits with the controls' noise warnings (not on
    the ``identities``), the pitch-damping prior and the model-structure mixture."""
    for ch, text in control_noise_warnings(fd, models, skip=identities, corrected=controls_corrected).items():
        if ch in fits:
            fits = {**fits, ch: replace(fits[ch], warnings=tuple(fits[ch].warnings) + (text,))}
    wrong_sign = wrong_sign_terms(models, fits)  # on the flight's own estimates, before the prior
    fits, covered = with_pitch_damping_prior(vehicle, models, fits)
    if STRUCTURE_UNCERTAINTY:
        fits = _with_structure_uncertainty(fd, signals, models, fits, wrong_sign, covered)
    return fits, wrong_sign
