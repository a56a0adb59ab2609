"""alpha/beta inversion from the preflight force database, against the simulator's truth."""
import numpy as np
import pytest

from aerosid.vehicles.aerodb import AeroDatabase
from aerosid.modelling.aeromodel import AeroModel
from aerosid.identification.inversion import invert_alpha_beta
from aerosid.vehicles.vehicle import load_vehicle

VEH = load_vehicle("seed-rlv")
DB = AeroDatabase.load(VEH.database_path)


def forward(alpha_r, phi_r, mach, dp, dy):
    c = AeroModel.preflight(VEH).coefficients(alpha_r, phi_r, mach, dp, dy, 0.0)
    return c["CN"], c["CY"]


def test_inversion_is_exact_on_database_forces_across_the_envelope():
    rng = np.random.default_rng(3)
    n = 5000
    alpha_r = rng.uniform(0.001, np.deg2rad(19.0), n)
    phi_r = rng.uniform(-np.pi, np.pi, n)
    mach = rng.uniform(5.0, 19.0, n)  # includes Mach-dependent slopes
    dp, dy = rng.uniform(-0.3, 0.3, n), rng.uniform(-0.1, 0.1, n)
    cn, cy = forward(alpha_r, phi_r, mach, dp, dy)
    inv = invert_alpha_beta(cn, cy, mach, dp, dy, DB, VEH.preflight)
    np.testing.assert_allclose(inv.alpha_r_rad, alpha_r, atol=1e-12)
    np.testing.assert_allclose(np.angle(np.exp(1j * (inv.phi_r_rad - phi_r))), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.tan(inv.alpha_rad), np.tan(alpha_r) * np.cos(phi_r), atol=1e-12)
    np.testing.assert_allclose(np.tan(inv.beta_rad), np.tan(alpha_r) * np.sin(phi_r), atol=1e-12)
    assert np.max(inv.J) < 1e-20 and not inv.clipped.any()


def test_outside_the_table_is_clipped_and_reported_with_positive_J():
    cn, cy = forward(np.deg2rad(25.0), 0.0, 12.4, 0.0, 0.0)  # beyond the 20 deg table edge
    inv = invert_alpha_beta(np.atleast_1d(cn), np.atleast_1d(cy), [12.4], [0.0], [0.0], DB, VEH.preflight)
    assert inv.clipped[0] and inv.J[0] > 1e-3
    assert inv.alpha_r_rad[0] == pytest.approx(np.deg2rad(20.0))


def test_recovered_alpha_beta_match_simulator_truth(reference_flight):
    tr = reference_flight.truth
    inv = invert_alpha_beta(tr.CN, tr.CY, tr.mach, tr.delta_p_rad, tr.delta_y_rad, DB, VEH.preflight)
    assert np.max(np.abs(inv.alpha_rad - tr.alpha_rad)) < 1e-10
    assert np.max(np.abs(inv.beta_rad - tr.beta_rad)) < 1e-10


def test_nan_forces_give_nan_angles_not_a_crash():
    inv = invert_alpha_beta([np.nan, 0.05], [0.0, 0.0], [12.4, 12.4], [0.0, 0.0], [0.0, 0.0], DB, VEH.preflight)
    assert np.isnan(inv.alpha_rad[0]) and np.isfinite(inv.alpha_rad[1])
