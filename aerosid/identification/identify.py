"""Regression stage: fit each channel's model to the flight data (method.md §11).

Produces the coefficients table (``coefficients.parquet``) and a Table-3-style
report: preflight vs flight estimate vs sigma (coloured-residual corrected, and
plain least squares) vs F, printed per degree as the seed does.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from aerosid.estimation.findings import CUT_COLUMN
from aerosid.modelling.aeromodel import AeroModel
from aerosid.identification.crb import identification_bounds
from aerosid.identification.eiv_fit import (angle_eiv_sigma, angle_rate_free_channels, control_eiv_sigma,
                                            eiv_corrected, rate_eiv_sigma, simex_channels)
from aerosid.identification.prior_structure import with_prior_and_structure
from aerosid.modelling.models import ChannelModel, default_models, vehicle_signals
from aerosid.plausibility.estimates import physical_range_departure, preflight_departure
from aerosid.identification.regression import LinearFit, fit_linear
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
    #: coefficient -> Cramér-Rao bound on its std (aerosid.identification.crb), NaN where none
    crb_std: dict = field(default_factory=dict)
    #: coefficient -> its t before the model-structure mixture, for the damping terms whose whole 95 %
    #: interval was positive (term_report.wrong_sign_damping); the table's ``wrong_sign`` column
    wrong_sign: dict = field(default_factory=dict)
    #: +/- pairs of the estimator-bias check counted in the sigma (aerosid.identification.bias_check); 0: none
    bias_pairs: int = 0
    #: the vehicle's [plausibility] envelope: its preflight_factor (estimates beyond preflight x/÷ it are
    #: reported) and, for an aircraft, the ranges its lift slope and roll damping are checked against where
    #: no preflight value says more (aerosid.plausibility.estimates); None: the factor 3, no ranges
    envelope: object = None

    @property
    def preflight_factor(self) -> float:
        return 3.0 if self.envelope is None else float(self.envelope.preflight_factor)

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
                expression = next((t.expression for t in self.models[channel].terms
                                   if t.coefficient == rec["coefficient"]), "")
                if not departure and self.envelope is not None:
                    departure = physical_range_departure(channel, expression, (rec["ci_low"], rec["ci_high"]),
                                                         self.envelope)
                rows.append({
                    "channel": channel, "coefficient": rec["coefficient"],
                    "estimate": float(rec["estimate"]), "std_error": float(rec["std_error"]),
                    "std_error_ols": float(rec["std_error_ols"]),
                    "crb_std": float(self.crb_std.get(rec["coefficient"], np.nan)) if ident else np.nan,
                    "ci_low": float(rec["ci_low"]),
                    "ci_high": float(rec["ci_high"]), "reference": float(self.references.get(rec["coefficient"], np.nan)),
                    "t_value": float(rec["t_value"]), "p_value": float(rec["p_value"]),
                    "identifiable": ident, "note": IDENTITY_NOTE if identity else "",
                    "expression": expression,
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


#: Fewest flight-data samples (inside the Mach window) a fit accepts.
MIN_FIT_SAMPLES = 50


def mach_window_mask(mach: np.ndarray, reference: float, half_width: float | None) -> np.ndarray:
    if half_width is None:
        return np.ones(len(mach), dtype=bool)
    return np.abs(mach - reference) <= half_width


def window_rows(fd: pd.DataFrame, vehicle, half_width: float | None, channels) -> np.ndarray:
    """The flight-data rows a fit of ``channels`` (names, or a dict keyed by them) reads: inside
    the Mach window, and not marked (CUT_COLUMN) as reading a sample condemned on a sensor that
    feeds one of those channels alone (the flight data keep such rows for the other channels)."""
    rows = mach_window_mask(fd["mach"].to_numpy(float), vehicle.mach_reference, half_width)
    for ch in channels:
        if CUT_COLUMN.get(ch) in fd.columns:
            rows &= ~fd[CUT_COLUMN[ch]].to_numpy(bool)
    return rows


#: The rates' part of SIMEX by default ("auto") only in the channels whose model reads no angle
#: rate (eiv_fit.angle_rate_free_channels: the lateral-directional ones).  Right in isolation (it
#: moves C_m_alpha toward the true-rates answer on F4N, OV10 and pa28, bench/results/gyro_simex.md),
#: but joined to the angles' SIMEX, which under-corrects the vane noise in alpha_dot_hat, it made
#: C_m_alpha worse on three of the four aircraft measured (generalisation bench, 10 seeds, mean
#: error off -> on: OV10 +3.0 -> +0.9 %, T37 -1.4 -> -5.2 %, F4N -4.6 -> -6.1 %, pa28 -4.0 -> -4.6 %),
#: and still did on 2026-11-28 (cached flights: F4N -5.9 -> -7.8 %, J3Cub -8.7 -> -9.7 %); in the
#: channels without alpha_dot_hat it removes the gyro noise's attenuation (minisgs C_l_p, C_n_r;
#: docs/estimation.md, "Errors in the rates").  True: every channel; False: none.
GYRO_EIV_DEFAULT = "auto"
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


def identify(flight_data: pd.DataFrame, vehicle: Vehicle, models: dict[str, ChannelModel] | None = None,
             mach_half_width: float | None = 0.5, cov: str = "morelli_klein",
             gyro_eiv: bool | str = GYRO_EIV_DEFAULT, bias_pairs: int | None = None,
             instrumental: bool | None = None, control_eiv: bool = CONTROL_EIV_DEFAULT) -> Identification:
    """Fit every channel's model on the samples with |M - M_ref| <= mach_half_width.
    Pooled flights (several values of ``flight``: manoeuvres of one aircraft) are fitted
    together; the coloured-residual correction treats each flight as its own record
    (``fit_linear(groups=...)``).  The estimates are corrected for the noise in the angles
    and (gyro_eiv, the flight data's eiv_sigma_p/q/r columns) in the rates by SIMEX
    (aerosid.identification.eiv); gyro_eiv: "auto" (the default, GYRO_EIV_DEFAULT) the rates' noise in
    the channels whose model reads no angle rate, True in every channel, False in none.
    control_eiv (default CONTROL_EIV_DEFAULT, True): the same for the controls' surface-sensor
    noise (the flight data's eiv_sigma_delta_*_rad; zero for quantised or held surfaces).
    bias_pairs: +/- pairs of re-draws of the parametric check of the estimator's own bias at this
    flight's noise, counted in the sigma (aerosid.identification.bias_check); 0: no check; None:
    default_bias_pairs().  instrumental: the flight was flown in turbulent air: every channel but the
    identities is fitted by instrumental variables, the controls as instruments, in place of least
    squares and SIMEX (aerosid.identification.instrumental); None: the vehicle file's
    ``[estimation] turbulent_air`` (default false)."""
    if gyro_eiv not in (True, False, "auto"):
        raise ValueError(f"gyro_eiv={gyro_eiv!r}: True, False or 'auto'")
    models = models or default_models(vehicle)
    fd = flight_data.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    groups = channel_groups(fd, vehicle, mach_half_width, models)
    if len(groups) > 1:  # a finding condemned rows of one channel only: each group on its own rows
        plain = fd.drop(columns=[c for c in CUT_COLUMN.values() if c in fd.columns])
        return _merged([identify(plain.loc[rows], vehicle, {ch: models[ch] for ch in chs}, mach_half_width, cov,
                                 gyro_eiv, bias_pairs, instrumental, control_eiv) for rows, chs in groups], models)
    mask = window_rows(fd, vehicle, mach_half_width, models)
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
    controls = (simex_channels(corrected, identities)
                if control_eiv and not instrumental and _band_limited(fd) and control_eiv_sigma(fd) is not None else ())
    fits, wrong_sign = with_prior_and_structure(fd, signals, vehicle, models, corrected, identities, controls)
    if bias_pairs:
        from aerosid.identification.bias_check import with_estimator_bias

        # the check runs on the estimator before the prior: the world's coefficients are the flight's
        # own, so a prior applied again would count as bias (its own spread is in the posterior)
        fits = with_estimator_bias(fd, vehicle, models, corrected, fits,
                                   lambda f: _corrected_fits(f, vehicle, models, cov, gyro_eiv,
                                                             instrumental=instrumental, control_eiv=control_eiv),
                                   bias_pairs,
                                   skip=identities)
    if vehicle.vehicle_class == "aircraft":
        from aerosid.identification.term_report import control_sign_warnings

        fits = {**fits, **{ch: replace(fits[ch], warnings=tuple(fits[ch].warnings) + (text,))
                           for ch, text in control_sign_warnings(fits, models).items()}}
    refs = AeroModel.preflight(vehicle).linear_truth() if vehicle.preflight is not None else {}
    window = (float(fd["mach"].min()), float(fd["mach"].max()))
    crb = identification_bounds(fd, vehicle, models, fits, identities)
    return Identification(fits, dict(models), refs, len(fd), window, identities, crb_std=crb.std,
                          wrong_sign=wrong_sign, bias_pairs=bias_pairs, envelope=vehicle.envelope)


def channel_groups(fd: pd.DataFrame, vehicle, half_width: float | None, models) -> list[tuple[np.ndarray, list]]:
    """[(rows, channels)]: the channels of ``models`` grouped by the rows their fit reads
    (window_rows), in the models' order; one group unless a finding condemned a sensor that
    feeds one channel alone (aerosid.estimation.findings.kept_sensors)."""
    groups: dict[bytes, tuple[np.ndarray, list]] = {}
    for ch in models:
        rows = window_rows(fd, vehicle, half_width, [ch])
        groups.setdefault(rows.tobytes(), (rows, []))[1].append(ch)
    return list(groups.values())


def _merged(parts: list[Identification], models: dict) -> Identification:
    """One Identification of the channel groups' (each fitted on its own rows): the fits in the
    models' order; n_samples and the Mach window those of the largest group."""
    fits = {ch: p.fits[ch] for ch in models for p in parts if ch in p.fits}
    main = max(parts, key=lambda p: p.n_samples)
    merged = lambda name: {k: v for p in parts for k, v in getattr(p, name).items()}  # noqa: E731
    return replace(main, fits=fits, models=dict(models), identities=tuple(ch for p in parts for ch in p.identities),
                   crb_std=merged("crb_std"), wrong_sign=merged("wrong_sign"))


def _band_limited(fd: pd.DataFrame) -> bool:
    """The flight data went through the band path (a finite band_hz on every row)."""
    return "band_hz" in fd.columns and bool(np.all(np.isfinite(fd["band_hz"].to_numpy(float))))


def _corrected_fits(fd: pd.DataFrame, vehicle: Vehicle, models: dict, cov: str, gyro_eiv: bool | str,
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
    band_limited = _band_limited(fd)
    rate_sigma = rate_eiv_sigma(fd) if gyro_eiv and band_limited else None
    control_sigma = control_eiv_sigma(fd) if control_eiv and band_limited else None
    if sigma is not None or rate_sigma is not None or control_sigma is not None:
        fits = eiv_corrected(fd, vehicle, models, fits, sigma, rate_sigma, control_sigma,
                             skip=identity_channels(vehicle, fits),
                             rate_channels=angle_rate_free_channels(models) if gyro_eiv == "auto" else None)
    return fits
