"""Responses of a JSBSim aircraft at its trim point, for the flight design (`jsbsim_design`):
the two-degree-of-freedom approximations (the short-period and Dutch-roll frequencies that
time the inputs, the sideslip of a rudder doublet with a yaw damper in the loop) and the same
doublet flown in JSBSim.  Inputs are JSBSim's properties at trim (`base`, English units as
JSBSim names them) and the linear truth `d` (coefficients per rad and per normalised rate)."""
from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm

from aerosid.simulation.jsbsim_columns import FT, PSF, SLUG, SLUG_FT2
from aerosid.simulation.jsbsim_trim import initialise


def mode_frequencies(d: dict, base: dict) -> dict[str, float]:
    """Short-period and Dutch-roll natural frequencies [rad/s] and the roll-mode time
    constant [s] from the linear truth (the classical two-degree-of-freedom
    approximations)."""
    q_S = base["aero/qbar-psf"] * PSF * base["metrics/Sw-sqft"] * FT**2
    c, b = base["metrics/cbarw-ft"] * FT, base["metrics/bw-ft"] * FT
    V = base["velocities/vt-fps"] * FT
    m = base["inertia/mass-slugs"] * SLUG
    Ixx, Iyy, Izz = (base[f"inertia/i{k}-slugs_ft2"] * SLUG_FT2 for k in ("xx", "yy", "zz"))
    M_a = q_S * c * d["Cm_alpha"] / Iyy
    M_q = q_S * c * d["Cm_q"] * c / (2 * V) / Iyy
    M_ad = q_S * c * d["Cm_alpha_dot"] * c / (2 * V) / Iyy
    Z_a = -q_S * d["CN_alpha"] / (m * V)
    # alpha' = Z_a alpha + q, q' = M_a alpha + M_q q + M_ad alpha': the determinant is
    # Z_a M_q - M_a (M_ad cancels out of it) and the trace Z_a + M_q + M_ad
    w_sp2 = Z_a * M_q - M_a
    w_sp = math.sqrt(max(w_sp2, 1e-6))
    # s^2 - trace s + w_sp^2 = 0: when overdamped, the pitch response is as slow as
    # the slower real root, and that sets the manoeuvre's time unit
    two_zeta_w = -(Z_a + M_q + M_ad)
    disc = two_zeta_w**2 - 4 * w_sp2
    w_design = (two_zeta_w - math.sqrt(disc)) / 2 if disc > 0 and w_sp2 > 0 else w_sp
    N_b = q_S * b * d["Cn_beta"] / Izz
    L_p = q_S * b * d["Cl_p"] * b / (2 * V) / Ixx
    return {"omega_sp_rad_s": w_sp, "zeta_sp": two_zeta_w / (2 * w_sp), "omega_pitch_design_rad_s": w_design,
            "omega_dr_rad_s": math.sqrt(max(N_b, 1e-6)),
            "tau_roll_s": -1.0 / L_p if L_p < 0 else float("inf"), "M_alpha_s2": M_a, "M_q_s": M_q,
            "M_alpha_dot_s": M_ad, "Z_alpha_s": Z_a}


def doublet_shape(half_s: float, rise_s: float, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(t [s], u): a unit doublet, +1 for `half_s`, -1 for `half_s`, linear ramps of `rise_s`,
    then zero for as long again (the free response)."""
    t = np.arange(0.0, 4.0 * half_s + 2.0 * rise_s, dt_s)
    ramp = max(rise_s, dt_s)
    u = (np.clip(t / ramp, 0.0, 1.0) - 2.0 * np.clip((t - half_s) / ramp, 0.0, 1.0)
         + np.clip((t - 2.0 * half_s) / ramp, 0.0, 1.0))
    return t, u


def flown_doublet_sideslip_peak(fdm, point, command_norm: float, half_s: float, rise_s: float,
                                dt_s: float) -> float:
    """Peak |beta| [rad] of a rudder doublet of `command_norm` (normalised rudder command)
    flown in JSBSim from `point` (a TrimPoint; `fdm` loaded, engines started, stepping dt_s),
    with everything the FCS does: a yaw damper's authority limit, washout, actuator."""
    initialise(fdm, point)
    beta0 = fdm["aero/beta-rad"]
    _, u = doublet_shape(half_s, rise_s, dt_s)
    peak = 0.0
    for uk in u:
        fdm["fcs/rudder-cmd-norm"] = point.rudder_cmd + command_norm * uk
        fdm.run()
        peak = max(peak, abs(fdm["aero/beta-rad"] - beta0))
    return peak


def doublet_sideslip_peak(d: dict, base: dict, half_s: float, rise_s: float, k_r: float = 0.0,
                          k_beta: float = 0.0, dt_s: float = 0.005) -> float:
    """Peak |beta| [rad] of the Dutch-roll approximation to a unit rudder doublet (1 rad of
    rudder, :func:`doublet_shape`), with the FCS's static feedback on the rudder: k_r [rad per rad/s] (a yaw
    damper) and k_beta [rad per rad].
    beta' = Y_beta beta - r + Y_delta delta, r' = N_beta beta + N_r r + N_delta delta with
    delta = u + k_beta beta + k_r r (roll and gravity left out, as in the classical approximation)."""
    q_S = base["aero/qbar-psf"] * PSF * base["metrics/Sw-sqft"] * FT**2
    b = base["metrics/bw-ft"] * FT
    V = base["velocities/vt-fps"] * FT
    m = base["inertia/mass-slugs"] * SLUG
    Izz = base["inertia/izz-slugs_ft2"] * SLUG_FT2
    Y_b, Y_d = q_S * d["CY_beta"] / (m * V), q_S * d["CY_delta_y"] / (m * V)
    N_b, N_d = q_S * b * d["Cn_beta"] / Izz, q_S * b * d["Cn_delta_y"] / Izz
    N_r = q_S * b * d["Cn_r"] * b / (2.0 * V) / Izz
    A = np.array([[Y_b + Y_d * k_beta, -1.0 + Y_d * k_r],
                  [N_b + N_d * k_beta, N_r + N_d * k_r]])
    B = np.array([Y_d, N_d])
    # zero-order hold: x[k+1] = Phi x[k] + Gamma u[k]
    M = expm(np.block([[A, B[:, None]], [np.zeros((1, 3))]]) * dt_s)
    Phi, Gamma = M[:2, :2], M[:2, 2]
    _, u = doublet_shape(half_s, rise_s, dt_s)
    x = np.zeros(2)
    peak = 0.0
    for uk in u:
        x = Phi @ x + Gamma * uk
        peak = max(peak, abs(x[0]))
    return peak
