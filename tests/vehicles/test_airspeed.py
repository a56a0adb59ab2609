"""Airspeed conversions (aerosid/vehicles/airspeed.py): closed forms and invariants."""
from __future__ import annotations

import numpy as np
import pytest

from aerosid.vehicles.airspeed import (A0_M_S, QC_OVER_P_SONIC, _mach_from_qc_over_p, _qc_over_p,
                                       calibrated_from_true_m_s, true_airspeed_m_s)
from aerosid.vehicles.atmosphere import density_kg_m3, pressure_pa, speed_of_sound_m_s, temperature_K

SPEEDS = np.array([5.0, 50.0, 150.0, 250.0, 340.0, 420.0, 600.0, 800.0])  # sub- and supersonic [m/s]


def test_at_sea_level_calibrated_is_true():
    np.testing.assert_allclose(calibrated_from_true_m_s(SPEEDS, 0.0), SPEEDS, rtol=1e-6)
    np.testing.assert_allclose(true_airspeed_m_s(SPEEDS, 0.0), SPEEDS, rtol=1e-6)


@pytest.mark.parametrize("h_m", [1500.0, 6000.0, 12000.0, 20000.0])
def test_true_to_calibrated_and_back(h_m):
    cas = calibrated_from_true_m_s(SPEEDS, h_m)
    np.testing.assert_allclose(true_airspeed_m_s(cas, h_m), SPEEDS, rtol=1e-6)
    assert np.all(cas < SPEEDS)  # thinner air: less impact pressure for the same true speed


def test_the_two_pitot_formulas_meet_at_mach_1_and_invert():
    assert _qc_over_p(np.array([1.0 - 1e-9]))[0] == pytest.approx(_qc_over_p(np.array([1.0 + 1e-9]))[0], rel=1e-6)
    assert _qc_over_p(np.array([1.0]))[0] == pytest.approx(QC_OVER_P_SONIC, rel=1e-9)
    mach = np.array([0.1, 0.5, 0.99, 1.01, 1.6, 2.5, 4.0])
    np.testing.assert_allclose(_mach_from_qc_over_p(_qc_over_p(mach)), mach, rtol=1e-7)


def test_at_low_mach_calibrated_is_equivalent_and_equivalent_is_the_density_ratio():
    h = 9000.0
    sigma = float(density_kg_m3(h) / density_kg_m3(0.0))
    assert true_airspeed_m_s(3.0, h, "equivalent") == pytest.approx(3.0 / np.sqrt(sigma), rel=1e-6)
    assert true_airspeed_m_s(3.0, h, "calibrated") == pytest.approx(3.0 / np.sqrt(sigma), rel=1e-4)
    # compressibility: at speed a calibrated airspeed reads above the equivalent one (q_c > q-bar)
    V = 250.0
    eas = V * np.sqrt(sigma)
    assert calibrated_from_true_m_s(V, h) > eas
    assert true_airspeed_m_s(V, h, "indicated") == true_airspeed_m_s(V, h, "calibrated")


def test_measured_static_pressure_and_total_temperature_of_the_standard_day_give_the_same():
    h, V = 7000.0, np.array([120.0, 260.0, 500.0])
    mach = V / speed_of_sound_m_s(h)
    T_total = temperature_K(h) * (1.0 + 0.2 * mach**2)
    cas = calibrated_from_true_m_s(V, h)
    got = true_airspeed_m_s(cas, h, "calibrated", p_static_pa=np.full(3, pressure_pa(h)), T_total_K=T_total)
    np.testing.assert_allclose(got, V, rtol=1e-6)
    eas = V * np.sqrt(density_kg_m3(h) / density_kg_m3(0.0))
    got = true_airspeed_m_s(eas, h, "equivalent", p_static_pa=np.full(3, pressure_pa(h)), T_total_K=T_total)
    np.testing.assert_allclose(got, V, rtol=1e-4)


def test_a_hot_day_gives_a_higher_true_airspeed_and_an_unknown_kind_is_refused():
    h = 3000.0
    hot = true_airspeed_m_s(100.0, h, "calibrated", T_total_K=temperature_K(h) + 20.0)
    assert hot > true_airspeed_m_s(100.0, h, "calibrated")
    with pytest.raises(ValueError, match="knots"):
        true_airspeed_m_s(100.0, h, "knots")


def test_the_textbook_value():
    """250 kt calibrated at 10 000 ft of the standard atmosphere: about 288.7 kt true (the flight
    computer's figure), and sea level's speed of sound is 661.5 kt."""
    kt = 1852.0 / 3600.0
    assert true_airspeed_m_s(250 * kt, 3048.0) / kt == pytest.approx(288.7, abs=0.5)
    assert A0_M_S / kt == pytest.approx(661.47, abs=0.05)


def test_a_measured_density_gives_the_temperature_and_the_equivalent_airspeeds_density():
    """A day 8 % less dense than the standard at 2200 m (the Twin Otter's was 4 %): the measured
    density makes the conversion exact where the US-1976 one is off by about half of it."""
    h, V = 2200.0, np.array([70.0, 150.0])
    rho = 0.92 * density_kg_m3(h)
    T = pressure_pa(h) / (287.05287 * rho)  # the standard pressure, a warmer day
    cas = calibrated_from_true_m_s(V, h, T_static_K=np.full(2, T))
    np.testing.assert_allclose(true_airspeed_m_s(cas, h, rho_kg_m3=np.full(2, rho)), V, rtol=1e-6)
    assert abs(true_airspeed_m_s(cas, h)[0] / V[0] - 1.0) > 0.03  # what the standard day would have said
    eas = V * np.sqrt(rho / density_kg_m3(0.0))
    np.testing.assert_allclose(true_airspeed_m_s(eas, h, "equivalent", rho_kg_m3=rho), V, rtol=1e-9)


def test_rows_without_an_altitude_are_emptied_and_sentinels_kept():
    """A telemetry's calibrated airspeed converted row by row: a row without an altitude cannot be
    converted (NaN: a dropout the preprocessing fills), a sentinel stays what it is (the
    preprocessing flags it), a missing airspeed stays missing."""
    from aerosid.vehicles.airspeed import true_airspeed_where_known
    from schemas.telemetry import DEFAULT_SENTINELS

    sentinel = float(next(s for s in DEFAULT_SENTINELS if s > 0))
    V = np.array([100.0, sentinel, np.nan, 120.0])
    out, emptied = true_airspeed_where_known(V, np.array([3000.0, 3000.0, 3000.0, np.nan]), "calibrated", {})
    assert out[0] == pytest.approx(true_airspeed_m_s(100.0, 3000.0)) and out[1] == sentinel
    assert np.isnan(out[2]) and np.isnan(out[3]) and emptied == 1


def test_an_impact_pressure_gives_the_dynamic_pressure():
    """q_c = p [(1 + 0.2 M^2)^3.5 - 1] (subsonic) or Rayleigh's (supersonic) against q-bar = 0.7 p M^2:
    at low Mach they agree, at Mach 0.8 q_c is 1.17 x q-bar."""
    from aerosid.vehicles.airspeed import dynamic_from_impact_pressure_pa

    p = 40000.0
    mach = np.array([0.05, 0.5, 0.8, 1.0, 1.6, 2.5])
    qbar = 0.7 * p * mach**2
    qc = p * _qc_over_p(mach)
    np.testing.assert_allclose(dynamic_from_impact_pressure_pa(qc, p), qbar, rtol=1e-7)
    assert qc[0] / qbar[0] == pytest.approx(1.0 + 0.05**2 / 4, rel=1e-4)
    assert qc[2] / qbar[2] == pytest.approx(1.17, abs=0.01)
