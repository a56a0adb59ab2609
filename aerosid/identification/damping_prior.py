"""A physical prior on how an aircraft's pitch damping splits between q and alpha-dot.

Why
---
The flight determines the pitch damping C_m,q + C_m,alpha_dot well, but hardly its split:
alpha-dot = q - gamma-dot, and gamma-dot is nearly a multiple of alpha (the lift), so
alpha_dot_hat is close to a combination of q_hat and alpha.  What the fit cannot tell between
C_m,alpha_dot and C_m,q it moves into C_m,alpha (docs/estimation.md, "The pitch-damping split").
With vanes, alpha-dot is also read off a noisy angle through a derivative, whose in-band
attenuation and noise bias the split further.  Measured on JSBSim aircraft: C_m,alpha -15 % on
the p51d, -4 % on pa28 and F4N, with C_m,alpha_dot estimates of the wrong sign.

What
----
The field's remedy is a priori information in the regression (Theil-Goldberger mixed
estimation; Morelli & Klein, *Aircraft System Identification*, ch. 5): a pseudo-observation
of the split with its own uncertainty, combined with the flight's estimate by their
precisions.  The split is written as the share of the total damping,

    f = C_m,alpha_dot / (C_m,q + C_m,alpha_dot),

whose textbook value follows from the tail's downwash lag: C_m,alpha_dot = C_m,q,tail x
d(epsilon)/d(alpha), and the tail gives ~90 % of C_m,q, so f = (d eps/d alpha) / (1.1 + d
eps/d alpha).  With d eps/d alpha ~ 2 C_L,alpha,wing / (pi AR) = 0.6 ... 0.28 for aspect ratios
5 ... 12, f = 0.2 ... 0.35: centre PRIOR_SHARE = 0.25.  Its 1-sigma PRIOR_SHARE_SIGMA = 0.2
widens that range so the 95 % interval (-0.15 ... 0.65) also holds a tailless or canard layout
(f ~ 0) and a doubled downwash ratio.  The prior is one row r theta = 0 with
r = (1 - f0) e_alpha_dot - f0 e_q and variance sigma_f^2 (D^2 + var D), D = C_m,q + C_m,alpha_dot as
estimated, so it constrains the split; the total damping moves only through its correlation with
the split.  The update is the exact Gaussian posterior of the flight's estimate and covariance
(a scalar Kalman measurement update).

When
----
Only for an aircraft (``vehicle_class = "aircraft"``) whose C_m model has one pure q_hat and one
pure alpha_dot_hat term (``q_hat``, ``(q_hat)``, ``2*q_hat`` ...).  The model-structure mixture
(aerosid.identification.structure_uncertainty) then leaves their "interval holds 0" to the prior,
which already holds the model without C_m,alpha_dot (f = 0, at 1.25 sigma); a C_m,alpha_dot of the
wrong sign that the flight pins down still takes the mixture.  A flight that determines
the split keeps its own answer (its precision outweighs the prior's); one that does not gets the
prior's share and an interval that says so.  What the flight seems to know of the split can be
the angles' noise: a noisy alpha_dot_hat is decorrelated from q_hat and alpha by its noise, so the
fit's covariance calls the split determined where the noise-free regressors do not determine it.
The errors-in-variables correction measures that share (``reliability``: the signal's share of
the apparent information along r, aerosid.identification.eiv.information_reliability); the
posterior's variance of r theta is then the one the signal's share and the prior give, mapped into
the other coefficients along the noise-free regressors' omitted-variable direction (``coupling``),
and the estimate is left as the update gives it (moving it to the prior's split was measured and
was worse on pa28 and T37: docs/estimation.md).  A vehicle file sets its own prior
(``[estimation] pitch_damping_split = [f0, sigma]``) or turns it off (``pitch_damping_split =
false``).  Measured on the generalisation bench and on
aircraft the project had never flown: docs/estimation.md.

numpy only.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from aerosid.identification.term_report import damping_term

#: Prior share of the pitch damping carried by C_m,alpha_dot (the tail's downwash lag), f0.
PRIOR_SHARE = 0.25
#: Its 1-sigma: 95 % interval -0.15 ... 0.65 (tailless/canard layouts to a doubled downwash ratio).
PRIOR_SHARE_SIGMA = 0.2
#: Below this reliability (the signal's share of the flight's information on the split) the
#: summary says how much of it is noise.
RELIABILITY_SAID = 0.99


@dataclass(frozen=True)
class SplitUpdate:
    """The split prior applied to one fit.

    estimate, cov: the posterior (k,), (k, k) (NaN where the fit had none); share_data,
    share_data_sigma: the split f = C_m,alpha_dot / (C_m,q + C_m,alpha_dot) the flight alone
    gives and its 1-sigma (delta method); share_post: the posterior's; prior: (f0, sigma_f)."""

    estimate: np.ndarray
    cov: np.ndarray
    share_data: float
    share_data_sigma: float
    share_post: float
    prior: tuple[float, float]
    reliability: float = 1.0

    def summary(self) -> str:
        f0, sf = self.prior
        text = (f"pitch-damping split: C_m,alpha_dot / (C_m,q + C_m,alpha_dot) = {self.share_data:.2f} "
                f"+- {self.share_data_sigma:.2f} from this flight, prior {f0:.2f} +- {sf:.2f} (downwash lag, "
                f"mixed estimation), combined {self.share_post:.2f}; the other estimates and sigma include the "
                "prior (aerosid.identification.damping_prior)")
        if self.reliability < RELIABILITY_SAID:
            text += (f"; only {self.reliability:.0%} of this flight's information on the split is signal, the rest "
                     "is the regressors' noise (the vane angles' through alpha_dot_hat): sigma counts the split "
                     "as uncertain as that share and the prior leave it (C_m,q, C_m,alpha_dot and the terms that "
                     "trade with them, C_m,alpha first, widen; a manoeuvre that "
                     "separates alpha-dot from q and alpha, or angles with less noise, would determine it)")
        return text


def _share(theta: np.ndarray, cov: np.ndarray, iq: int, ia: int, cq: float, ca: float) -> tuple[float, float]:
    """f = ca theta_a / (cq theta_q + ca theta_a) and its delta-method 1-sigma."""
    d = cq * theta[iq] + ca * theta[ia]
    if d == 0 or not math.isfinite(d):
        return float("nan"), float("nan")
    f = ca * theta[ia] / d
    g = np.zeros(theta.size)
    g[iq], g[ia] = -ca * theta[ia] * cq / d**2, ca * cq * theta[iq] / d**2
    return float(f), float(math.sqrt(max(g @ cov @ g, 0.0)))


def split_row(k: int, iq: int, ia: int, share: float, factors: tuple[float, float]) -> np.ndarray:
    """The prior's row r (length k): r theta = (1 - share) C_m,alpha_dot - share C_m,q, zero at the
    prior's split."""
    cq, ca = (float(c) for c in factors)
    r = np.zeros(k)
    r[iq], r[ia] = -share * cq, (1.0 - share) * ca
    return r


def split_update(estimate, cov, iq: int, ia: int, share: float = PRIOR_SHARE,
                 share_sigma: float = PRIOR_SHARE_SIGMA, factors: tuple[float, float] = (1.0, 1.0),
                 reliability: float = 1.0, coupling=None) -> SplitUpdate | str:
    """The posterior of (estimate, cov) given the prior C_m,alpha_dot = share x D +- share_sigma x D,
    D = C_m,q + C_m,alpha_dot (the damping as estimated; its own variance is added to the
    prior's, so a damping the flight hardly determines does not turn the prior into a constraint).

    iq, ia: the positions of the q_hat and alpha_dot_hat terms; factors: their expressions'
    factors (a term ``2*q_hat`` has C_m,q = 2 x its coefficient).  Terms whose estimate is not
    finite (not identifiable) are left as they are.  A string saying why when the prior cannot
    be applied (those two not finite, or a damping of exactly zero with no uncertainty).

    reliability (in [0, 1]): the share of the flight's information on the split that is signal
    (aerosid.identification.eiv.information_reliability; the rest is the regressors' noise,
    which decorrelates alpha_dot_hat from q_hat and alpha and so makes the split look
    determined).  The estimate is the update above, but its covariance is widened along the
    split to the posterior variance the flight's *signal* information and the prior give,
    1 / (reliability / v + 1 / s2) (v, s2: the flight's and the prior's variance of r theta;
    reliability 0: the prior's alone), mapped into the other coefficients through the
    posterior's own correlation with r theta, or along ``coupling`` when given: a direction in
    the coefficients (full length k, any scale; aerosid.identification.eiv.profile_direction,
    how the others follow C_m,alpha_dot on the noise-free regressors), used unless it is not
    finite or nearly orthogonal to r (r . c a near-cancellation: |r . c| <= 0.1 sum |r_i c_i|).
    A reliability that is not finite is taken as 1 (nothing known against the flight's own
    information)."""
    theta = np.array(estimate, float)
    P = np.array(cov, float)
    cq, ca = (float(c) for c in factors)
    ok = np.isfinite(theta) & np.isfinite(np.diag(P))
    if not (ok[iq] and ok[ia]):
        return "C_m,q or C_m,alpha_dot has no finite estimate"
    sub = np.flatnonzero(ok)
    Ps = P[np.ix_(sub, sub)]
    if not np.all(np.isfinite(Ps)):
        return "the fit's covariance is not finite"
    if not share_sigma > 0:
        return f"the prior's sigma {share_sigma!r} is not positive"
    jq, ja = int(np.searchsorted(sub, iq)), int(np.searchsorted(sub, ia))
    th = theta[sub]
    w = np.zeros(sub.size)
    w[jq], w[ja] = cq, ca
    damping = float(w @ th)
    r = split_row(sub.size, jq, ja, share, (cq, ca))
    s2 = share_sigma ** 2 * (damping ** 2 + float(w @ Ps @ w))
    if not s2 > 0:
        return "the estimated pitch damping is zero with no uncertainty (nothing to scale the prior by)"
    Pr = Ps @ r
    den = float(r @ Pr) + s2
    post = th - Pr * float(r @ th) / den
    P_post = Ps - np.outer(Pr, Pr) / den
    reliability = float(np.clip(reliability, 0.0, 1.0)) if math.isfinite(reliability) else 1.0
    v_data = float(r @ Pr)
    if reliability < 1.0 and v_data > 0:
        # widen along r theta to the variance the flight's signal information and the prior give
        v_post = 1.0 / (1.0 / v_data + 1.0 / s2)
        extra = 1.0 / (reliability / v_data + 1.0 / s2) - v_post
        g = P_post @ r / float(r @ P_post @ r)
        if coupling is not None:
            c = np.asarray(coupling, float)[sub]
            rc = float(r @ c)
            if np.all(np.isfinite(c)) and abs(rc) > 0.1 * float(np.abs(r * c).sum()):  # not a near-cancellation
                g = c / rc
        P_post = P_post + extra * np.outer(g, g)
    else:
        reliability = 1.0  # nothing widened: the summary says nothing of it
    P_post = 0.5 * (P_post + P_post.T)  # symmetric to rounding
    est_out, cov_out = theta.copy(), P.copy()
    est_out[sub] = post
    cov_out[np.ix_(sub, sub)] = P_post
    f_data, sf_data = _share(th, Ps, jq, ja, cq, ca)
    f_post, _ = _share(post, P_post, jq, ja, cq, ca)
    return SplitUpdate(est_out, cov_out, f_data, sf_data, f_post, (float(share), float(share_sigma)), reliability)


def damping_terms(expressions) -> tuple[tuple[int, float], tuple[int, float]] | None:
    """((position, factor) of the C_m model's pure q_hat term, same of its pure alpha_dot_hat term),
    or None unless it has exactly one of each (aerosid.identification.term_report.damping_term)."""
    found: dict[str, list] = {"q_hat": [], "alpha_dot_hat": []}
    for j, e in enumerate(expressions):
        t = damping_term("Cm", e)
        if t is not None:
            found[t[0]].append((j, t[1]))
    if len(found["q_hat"]) != 1 or len(found["alpha_dot_hat"]) != 1:
        return None
    return found["q_hat"][0], found["alpha_dot_hat"][0]
