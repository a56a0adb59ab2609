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
r = (1 - f0) e_alpha_dot - f0 e_q and variance (sigma_f x |C_m,q + C_m,alpha_dot|)^2, so it
leaves the total damping to the data and constrains only the split; the update is the exact
Gaussian posterior of the flight's estimate and covariance (a scalar Kalman measurement update).

When
----
Only for an aircraft (``vehicle_class = "aircraft"``) whose C_m model has both a pure q_hat and
a pure alpha_dot_hat term.  A flight that determines the split keeps its own answer (its
precision outweighs the prior's); one that does not gets the prior's share and an interval that
says so.  A vehicle file sets its own prior (``[estimation] pitch_damping_split = [f0, sigma]``)
or turns it off (``pitch_damping_split = false``).  Measured on the generalisation bench and on
aircraft the project had never flown: docs/estimation.md.

numpy only.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Prior share of the pitch damping carried by C_m,alpha_dot (the tail's downwash lag), f0.
PRIOR_SHARE = 0.25
#: Its 1-sigma: 95 % interval -0.15 ... 0.65 (tailless/canard layouts to a doubled downwash ratio).
PRIOR_SHARE_SIGMA = 0.2


@dataclass(frozen=True)
class SplitUpdate:
    """The split prior applied to one fit.

    estimate, cov: the posterior (k,), (k, k); share_data, share_data_sigma: the split
    f = C_m,alpha_dot / (C_m,q + C_m,alpha_dot) the flight alone gives and its 1-sigma (delta
    method); share_post: the posterior's; prior: (f0, sigma_f)."""

    estimate: np.ndarray
    cov: np.ndarray
    share_data: float
    share_data_sigma: float
    share_post: float
    prior: tuple[float, float]

    def summary(self) -> str:
        f0, sf = self.prior
        return (f"pitch-damping split: C_m,alpha_dot / (C_m,q + C_m,alpha_dot) = {self.share_data:.2f} "
                f"+- {self.share_data_sigma:.2f} from this flight, prior {f0:.2f} +- {sf:.2f} (downwash lag, "
                f"mixed estimation), combined {self.share_post:.2f}; the other estimates and sigma include the "
                "prior (aerosid.identification.damping_prior)")


def _share(theta: np.ndarray, cov: np.ndarray, iq: int, ia: int) -> tuple[float, float]:
    """f = theta_a / (theta_q + theta_a) and its delta-method 1-sigma."""
    d = theta[iq] + theta[ia]
    if d == 0 or not math.isfinite(d):
        return float("nan"), float("nan")
    f = theta[ia] / d
    g = np.zeros(theta.size)
    g[iq], g[ia] = -theta[ia] / d**2, theta[iq] / d**2
    return float(f), float(math.sqrt(max(g @ cov @ g, 0.0)))


def split_update(estimate, cov, iq: int, ia: int, share: float = PRIOR_SHARE,
                 share_sigma: float = PRIOR_SHARE_SIGMA) -> SplitUpdate | None:
    """The posterior of (estimate, cov) given the prior C_m,alpha_dot = share x (C_m,q +
    C_m,alpha_dot) +- share_sigma x |C_m,q + C_m,alpha_dot| (the damping as estimated).

    iq, ia: the positions of C_m,q and C_m,alpha_dot.  None when the estimate or covariance
    is not finite or the damping is zero (nothing to scale the prior by)."""
    theta = np.asarray(estimate, float)
    P = np.asarray(cov, float)
    if not (np.all(np.isfinite(theta)) and np.all(np.isfinite(P))) or share_sigma <= 0:
        return None
    damping = theta[iq] + theta[ia]
    if damping == 0:
        return None
    r = np.zeros(theta.size)
    r[iq], r[ia] = -share, 1.0 - share
    s2 = (share_sigma * damping) ** 2
    Pr = P @ r
    den = float(r @ Pr) + s2
    post = theta - Pr * float(r @ theta) / den
    P_post = P - np.outer(Pr, Pr) / den
    P_post = 0.5 * (P_post + P_post.T)  # symmetric to rounding
    f_data, sf_data = _share(theta, P, iq, ia)
    f_post, _ = _share(post, P_post, iq, ia)
    return SplitUpdate(post, P_post, f_data, sf_data, f_post, (float(share), float(share_sigma)))


def pure_term_index(expressions, signal: str) -> int | None:
    """Position of the term whose expression is the signal alone (e.g. 'q_hat'), or None."""
    for j, e in enumerate(expressions):
        if str(e).replace(" ", "") == signal:
            return j
    return None
