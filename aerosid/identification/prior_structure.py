"""What identify adds to the fits after the regression and its errors-in-variables correction:
the controls' noise warnings, the prior on an aircraft's pitch-damping split
(aerosid.identification.damping_prior) and the model-structure uncertainty of terms the flight
does not determine or gives a sign damping seldom has
(aerosid.identification.structure_uncertainty)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd

from aerosid.identification.damping_prior import (PRIOR_SHARE, PRIOR_SHARE_SIGMA, damping_terms, split_row,
                                                   split_update)
from aerosid.identification.eiv import information_reliability, profile_direction
from aerosid.identification.eiv_fit import control_noise_warnings
from aerosid.identification.regression import LinearFit, with_posterior
from aerosid.vehicles.vehicle import Vehicle


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


def with_structure_uncertainty(fd: pd.DataFrame, signals: dict, models: dict, fits: dict,
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


def with_prior_and_structure(fd: pd.DataFrame, signals: dict, vehicle: Vehicle, models: dict,
                              fits: dict[str, LinearFit], identities: tuple[str, ...],
                              controls_corrected: tuple[str, ...] = ()) -> tuple[dict[str, LinearFit], dict[str, float]]:
    """(fits, wrong-sign damping terms): the corrected fits with the controls' noise warnings (not on
    the ``identities``; controls_corrected: the channels the controls' SIMEX corrected, whose warning
    says so), the pitch-damping prior and the model-structure mixture."""
    for ch, text in control_noise_warnings(fd, models, skip=identities, corrected=controls_corrected).items():
        if ch in fits:
            fits = {**fits, ch: replace(fits[ch], warnings=tuple(fits[ch].warnings) + (text,))}
    wrong_sign = wrong_sign_terms(models, fits)  # on the flight's own estimates, before the prior
    fits, covered = with_pitch_damping_prior(vehicle, models, fits)
    if STRUCTURE_UNCERTAINTY:
        fits = with_structure_uncertainty(fd, signals, models, fits, wrong_sign, covered)
    return fits, wrong_sign
