"""alpha-dot from the flight-path kinematics (vane aircraft), with the vane angle for the slow part.

Measured, and NOT the default (aerosid.modelling.models.KINEMATIC_ALPHA_DOT, KINEMATIC_ALPHA):
the vane derivative looked like the cause of the C_m_alpha bias on pa28 and F4N (bench/results/
attribution_notes.md, finding 2), but an exact alpha-dot is nearly q + a_n/V + G, i.e. a linear
combination of q, alpha and delta through C_N: with C_m_alpha_dot in the model the design becomes
near-singular (largest VIF pa28 84 -> 222, F4N 86 -> 1595) and C_m_alpha trades with C_m_alpha_dot
(the short period only identifies C_m_alpha - C_m_alpha_dot rho S c C_N_alpha/(4 m)).  The vane
derivative's noise was what kept the split conditioned.  On 10 cached flights each (identify,
SIMEX on) C_m_alpha's mean / RMS error: pa28 -4.0 / 5.7 -> -6.0 / 9.7 %, F4N -4.9 / 5.2 -> -13.1 /
16.7 %, OV10 +3.0 / 3.2 -> -2.3 / 2.6 %; with alpha from the same filter -6.8 / 8.5, +7.6 / 13.1,
-10.7 / 10.8 % (bench/results/kinematic_adot.md, docs/estimation.md).

The construction: flight-path reconstruction takes alpha-dot from the rigid-body kinematics (u = V cos a cos b, w = V sin a cos b, alpha = atan(w/u)):

    alpha_dot = q - tan(b) (p cos a + r sin a)
                + [cos a (a_z + g cos th cos ph) - sin a (a_x - g sin th)] / (V cos b)

with a_x, a_z the specific forces at the CG (what the accelerometers measure, thrust included):
a_x = -C_A qbar S/m, a_z = -C_N qbar S/m (the signs of aerosid.identification.flight_coefficients),
and p, q, r the flight data's (band-limited) rates.  The estimation reads no attitude (the
21-state model carries none, and telemetry need not have it), so the gravity term

    G(t) = g [cos a cos th cos ph + sin a sin th] / (V cos b)        (~ g cos(gamma) / V)

is not known.  It moves with the flight path (gamma, V: the phugoid) and the bank angle, slowly
against a pitch manoeuvre; so it is taken from the vanes below a corner f_c:

    alpha_dot_hat = K + LP_fc[ alpha_dot_vane - K ],     K = the kinematic part without gravity

(a complementary filter: the vanes' derivative enters only below f_c, the kinematics above;
complementary_alpha does it one level up, on the angle, so alpha_hat and its derivative agree).  The
same low-pass also takes out any slow error of K (accelerometer bias, mass, the vane's bias).

f_c is the flight's own band edge (aerosid.identification.band) over KINEMATIC_BAND_FRACTION: the
vane noise, white before the band's low-pass, has a derivative whose power grows as f^2 inside the
band, so the part of it below f_c is (f_c/band)^(3/2) of its rms: 1/5 keeps 9 % of it.  It is not
tuned on any truth, and no fraction wins: seed 0, alpha-dot only, fractions 2.5 / 5 / 10 / 20
gave C_m_alpha pa28 -11.6 / -11.3 / -12.0 / -13.1 %, F4N -19.5 / -26.5 / -36.6 / -45.1 %, OV10
-1.5 / -2.9 / -4.3 / -5.0 % (vane: -5.2, -7.2, +1.4 %): the more of alpha-dot the kinematics
give, the worse, as the confounding above predicts.

beta_dot_hat is left as the vanes' derivative: its gravity term g cos th sin ph / V follows the bank
angle, which moves at the lateral manoeuvre's own frequencies (a roll doublet banks by tens of
degrees), so a low-pass cannot supply it; and no default model uses beta_dot_hat.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
import scipy.integrate
import scipy.signal

#: f_c = band edge / this (see the module's docstring): the vane derivative's noise below f_c is
#: (1/5)^(3/2) = 9 % of its in-band rms.
KINEMATIC_BAND_FRACTION = 5.0
#: Columns the kinematic alpha-dot needs in the flight data (besides alpha, beta, V and the rates).
KINEMATIC_COLUMNS = ("CA", "CN", "qbar_pa")


def kinematic_alpha_dot_no_gravity(alpha, beta, p, q, r, ax_m_s2, az_m_s2, V_m_s) -> np.ndarray:
    """K [rad/s]: alpha-dot from the rates and the CG specific forces, without the gravity term
    G = g [cos a cos th cos ph + sin a sin th] / (V cos b) (so alpha_dot = K + G)."""
    a, b = np.asarray(alpha, float), np.asarray(beta, float)
    return (np.asarray(q, float) - np.tan(b) * (np.asarray(p, float) * np.cos(a) + np.asarray(r, float) * np.sin(a))
            + (np.cos(a) * np.asarray(az_m_s2, float) - np.sin(a) * np.asarray(ax_m_s2, float))
            / (np.asarray(V_m_s, float) * np.cos(b)))


def gravity_alpha_dot(alpha, beta, theta, phi, V_m_s, g_m_s2: float = 9.80665) -> np.ndarray:
    """G [rad/s], the gravity part of alpha-dot (needs the attitude theta, phi)."""
    a = np.asarray(alpha, float)
    return g_m_s2 * (np.cos(a) * np.cos(theta) * np.cos(phi) + np.sin(a) * np.sin(theta)) / (
        np.asarray(V_m_s, float) * np.cos(beta))


def _low_pass_padded(x: np.ndarray, fs: float, cutoff_hz: float) -> np.ndarray:
    """x through a zero-phase 2nd-order Butterworth low-pass; each end padded with the mean of
    its last 1/cutoff_hz seconds (not with the end sample, whose noise would fill the pad)."""
    if cutoff_hz >= 0.5 * fs:
        return x
    w = max(1, min(x.size, int(round(fs / cutoff_hz))))
    pad = 3 * int(round(fs / cutoff_hz))
    ext = np.concatenate([np.full(pad, x[:w].mean()), x, np.full(pad, x[-w:].mean())])
    sos = scipy.signal.butter(2, cutoff_hz, fs=fs, output="sos")
    return scipy.signal.sosfiltfilt(sos, ext, padlen=0)[pad:pad + x.size]


@dataclass(frozen=True)
class KinematicAlpha:
    """alpha [rad] and alpha_dot [rad/s] from the kinematics above cutoff_hz and the vane
    below; kinematic: K [rad/s]; gravity_hat: the low-frequency part d/dt LP[alpha_vane - int K]
    [rad/s] (the gravity term G and any slow error of K)."""

    alpha: np.ndarray
    alpha_dot: np.ndarray
    kinematic: np.ndarray
    gravity_hat: np.ndarray
    cutoff_hz: float

    def summary(self) -> str:
        return (f"alpha and alpha_dot from the kinematics above {self.cutoff_hz:.3g} Hz, from the vane below "
                f"(median gravity part {float(np.nanmedian(self.gravity_hat)):.3g} rad/s)")


def complementary_alpha(t_s, groups, alpha_vane, kinematic, cutoff_hz: float) -> KinematicAlpha:
    """The complementary filter of the module's docstring, per contiguous group (a uniform grid
    of the group's median step, missing rows interpolated, read back at the samples):

        alpha_hat = int K + LP_fc[alpha_vane - int K],   alpha_dot_hat = d alpha_hat / dt

    int K drifts by the missing gravity term (~ g/V t): the straight line through
    alpha_vane - int K is taken out before the low-pass and put back after.  A group of fewer
    than 5 samples or with a non-finite input stays NaN."""
    t_s = np.asarray(t_s, float)
    av, K = np.asarray(alpha_vane, float), np.asarray(kinematic, float)
    alpha, adot, G = (np.full(len(t_s), np.nan) for _ in range(3))
    groups = np.zeros(len(t_s), int) if groups is None else np.asarray(groups)
    for g in pd.unique(groups):
        idx = np.flatnonzero(groups == g)
        if idx.size < 5 or not (np.all(np.isfinite(av[idx])) and np.all(np.isfinite(K[idx]))):
            continue
        idx = idx[np.argsort(t_s[idx], kind="stable")]
        t = t_s[idx]
        dt = float(np.median(np.diff(t)))
        if not dt > 0:
            continue
        grid = np.arange(t[0], t[-1] + 0.5 * dt, dt)
        Kg = np.interp(grid, t, K[idx])
        IK = scipy.integrate.cumulative_trapezoid(Kg, dx=dt, initial=0.0)
        D = np.interp(grid, t, av[idx]) - IK
        slope, icept = np.polyfit(grid - grid[0], D, 1)
        line = icept + slope * (grid - grid[0])
        low = _low_pass_padded(D - line, 1.0 / dt, cutoff_hz)
        g_hat = slope + np.gradient(low, dt)
        alpha[idx] = np.interp(t, grid, IK + line + low)
        adot[idx] = np.interp(t, grid, Kg + g_hat)
        G[idx] = np.interp(t, grid, g_hat)
    return KinematicAlpha(alpha, adot, K, G, cutoff_hz)


def flight_data_alpha(fd: pd.DataFrame, signals: dict, vehicle, band_hz: float,
                      groups: np.ndarray | None) -> KinematicAlpha:
    """complementary_alpha on a FlightData frame at f_c = band_hz / KINEMATIC_BAND_FRACTION:
    K from its rates, alpha, beta, V and the specific forces of its C_A, C_N and qbar with the
    vehicle's mass and S; the vane angle is the signals' alpha."""
    if not (np.isfinite(band_hz) and band_hz > 0):
        raise ValueError(f"the band edge must be a positive frequency [Hz], got {band_hz!r}")
    qs_m = fd["qbar_pa"].to_numpy(float) * vehicle.S_m2 / vehicle.mass_kg
    K = kinematic_alpha_dot_no_gravity(signals["alpha"], signals["beta"], signals["p"], signals["q"], signals["r"],
                                       -fd["CA"].to_numpy(float) * qs_m, -fd["CN"].to_numpy(float) * qs_m,
                                       signals["V"])
    return complementary_alpha(signals["t"], groups, signals["alpha"], K, band_hz / KINEMATIC_BAND_FRACTION)
