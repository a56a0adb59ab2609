"""Measured air data (issue 17): density, dynamic pressure, static pressure and total
temperature replace the US-1976 atmosphere when the telemetry carries them, and the
run says where each quantity came from."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from ambiance import Atmosphere

from aerosid.vehicles.atmosphere import (CP_AIR_J_KG_K, GAMMA_AIR, US1976, AirDataError, air_data, air_data_sources,
                                density_kg_m3)
from aerosid.identification.flight_data import build_flight_data_segments, flight_air_data_sources, load_database
from aerosid.preprocess import preprocess
from aerosid.vehicles.vehicle import load_vehicle
from schemas.telemetry import MEASURED_AIR_DATA_CHANNELS, UNITS, PreprocessedTelemetry, RawTelemetry, validate

H = np.array([0.0, 2196.0, 11000.0, 30000.0, 60000.0])
V = np.array([70.0, 72.0, 250.0, 1500.0, 3500.0])


def test_standard_atmosphere_is_the_default_and_says_so():
    air = air_data(V, H)
    atm = Atmosphere(H)
    np.testing.assert_array_equal(air.rho_kg_m3, atm.density)
    np.testing.assert_array_equal(air.mach, V / atm.speed_of_sound)
    np.testing.assert_array_equal(air.qbar_pa, 0.5 * atm.density * V * V)
    assert set(air.sources.values()) == {US1976, f"V_m_s / a, a from {US1976}", "0.5 rho V_m_s^2"}
    assert air.sources == air_data_sources()


def test_gas_law_on_us1976_pressure_and_total_temperature_gives_us1976_back():
    """p and T_t of the standard day in -> the standard density, speed of sound and Mach
    out (same gamma and R as US-1976): the static temperature from T_t - V^2/(2 c_p)
    closes exactly."""
    atm = Atmosphere(H)
    T_total = atm.temperature + V * V / (2 * CP_AIR_J_KG_K)
    air = air_data(V, H, p_static_pa=atm.pressure, T_total_K=T_total)
    np.testing.assert_allclose(air.rho_kg_m3, atm.density, rtol=1e-12)
    np.testing.assert_allclose(air.a_m_s, atm.speed_of_sound, rtol=1e-12)
    np.testing.assert_allclose(air.mach, V / atm.speed_of_sound, rtol=1e-12)
    # T_t = T (1 + (gamma-1)/2 M^2): the isentropic relation holds with the Mach returned
    T = air.a_m_s ** 2 / (GAMMA_AIR * 287.05287)
    np.testing.assert_allclose(T * (1 + 0.5 * (GAMMA_AIR - 1) * air.mach ** 2), T_total, rtol=1e-12)
    assert air.sources["rho_kg_m3"].startswith("gas law: p_static_pa") and "T_total_K" in air.sources["rho_kg_m3"]
    assert air.sources["mach"].endswith("T from T_total_K")


def test_measured_values_take_precedence_in_the_documented_order():
    atm = Atmosphere(H)
    rho = 0.9 * atm.density
    qbar = np.full(H.shape, 1234.5)
    # density measured: it wins over the static pressure; Mach stays US-1976 without T_t
    air = air_data(V, H, rho_kg_m3=rho, p_static_pa=0.5 * atm.pressure)
    np.testing.assert_array_equal(air.rho_kg_m3, rho)
    np.testing.assert_array_equal(air.qbar_pa, 0.5 * rho * V * V)
    np.testing.assert_array_equal(air.mach, V / atm.speed_of_sound)
    assert air.sources["rho_kg_m3"] == "measured: rho_kg_m3" and air.sources["mach"].endswith(US1976)
    # static pressure alone: the gas law at the standard temperature
    air = air_data(V, H, p_static_pa=0.5 * atm.pressure)
    np.testing.assert_allclose(air.rho_kg_m3, 0.5 * atm.density, rtol=1e-12)
    assert air.sources["rho_kg_m3"] == f"gas law: p_static_pa / (R T), T from {US1976}"
    # dynamic pressure measured: used as is, whatever the density
    air = air_data(V, H, rho_kg_m3=rho, qbar_pa=qbar)
    np.testing.assert_array_equal(air.qbar_pa, qbar)
    assert air.sources["qbar_pa"] == "measured: qbar_pa"


@pytest.mark.parametrize("column, values, expected", [
    ("rho_kg_m3", np.array([1.0, 0.0, 1.0, -1.0, 1.0]), "non-positive"),
    ("T_total_K", np.array([300.0, 300.0, 300.0, 300.0, 300.0]), "static temperature"),  # V^2/2c_p: 1120, 6097 K
])
def test_unusable_measured_values_name_the_column_and_samples(column, values, expected):
    with pytest.raises(AirDataError, match=expected) as exc:
        air_data(V, H, **{column: values})
    assert exc.value.column == column and column in str(exc.value)
    assert exc.value.positions.tolist() == ([1, 3] if column == "rho_kg_m3" else [3, 4])


def test_schema_declares_the_measured_columns_optional_with_units_and_ranges():
    cols = RawTelemetry.to_schema().columns
    for c in MEASURED_AIR_DATA_CHANNELS:
        assert not cols[c].required and cols[c].metadata["unit"] == UNITS[c]
        lo, hi = cols[c].metadata["bounds"]
        assert 0 <= lo < hi
    pre = PreprocessedTelemetry.to_schema().columns
    for c in MEASURED_AIR_DATA_CHANNELS:
        assert not pre[f"{c}_clean"].required and not pre[f"flags_{c}"].required


def test_total_temperature_in_celsius_is_refused_as_a_unit_error(reference_flight):
    raw = reference_flight.telemetry.assign(T_total_K=15.0)
    with pytest.raises(Exception, match="T_total_K") as exc:
        validate(raw, RawTelemetry, "celsius.parquet")
    assert "mostly_in_physical_range" in str(exc.value)


def us1976_density(h: np.ndarray) -> np.ndarray:
    """US-1976 density where h is a plausible altitude, NaN elsewhere (dropouts, spikes)."""
    ok = np.isfinite(h) & (h > -5000) & (h < 81000)
    return np.where(ok, density_kg_m3(np.where(ok, h, 0.0)), np.nan)


@pytest.fixture(scope="module")
def low_density(reference_flight, reference_run):
    """The reference flight with a measured density 4.2 % below US-1976 (the size of the
    Twin Otter's discrepancy; its files hold 1.029 kg/m^3 against US-1976's 0.987, i.e.
    4.2 % above), through preprocessing; smoothing does not read air data, so the
    reference run's smoothed segments serve both."""
    raw = reference_flight.telemetry.copy()
    raw["rho_kg_m3"] = 0.958 * us1976_density(raw["h_m"].to_numpy())
    pre = preprocess(raw, source="low-density.parquet")
    return pre, reference_run


def test_preprocessing_carries_the_measured_density(low_density):
    pre, ref = low_density
    frame = pre.frame
    assert {"rho_kg_m3", "rho_kg_m3_clean", "flags_rho_kg_m3"} <= set(frame.columns)
    # the contract channels are untouched by the extra column
    for c in ref.preprocessed.frame.columns:
        np.testing.assert_array_equal(frame[c].to_numpy(), ref.preprocessed.frame[c].to_numpy(), err_msg=c)
    good = frame["flags_rho_kg_m3"].to_numpy() == 0
    assert good.mean() > 0.9
    np.testing.assert_array_equal(frame["rho_kg_m3_clean"].to_numpy()[good], frame["rho_kg_m3"].to_numpy()[good])


def test_a_constant_measured_density_is_carried_unflagged(reference_flight):
    """SIDPAC's files log one density for the whole manoeuvre: a constant air-data
    column is normal, not a frozen sensor (only the contract channels are checked for
    frozen runs by default)."""
    raw = reference_flight.telemetry.assign(rho_kg_m3=1.0292115)
    frame = preprocess(raw).frame
    present = np.isfinite(frame["t_raw_s"].to_numpy())
    assert (frame["flags_rho_kg_m3"].to_numpy()[present] == 0).all()
    assert (frame["rho_kg_m3_clean"].to_numpy()[present] == 1.0292115).all()


def test_measured_density_scales_every_flight_coefficient_by_exactly_one_over_it(low_density):
    """qbar = 0.5 rho V^2 with rho 0.958 of US-1976's: every coefficient (and its sigma)
    is 1/0.958 of the standard atmosphere's, Mach is unchanged, and the source is named."""
    pre, ref = low_density
    vehicle = load_vehicle("seed-rlv")
    frame = pre.frame.copy()
    # the measured density as the preprocessing would carry it, exactly 0.958 x US-1976 at h_clean
    frame["rho_kg_m3_clean"] = 0.958 * us1976_density(frame["h_m_clean"].to_numpy())
    smoothed = [s.frame for s in ref.smoothed]
    fd = build_flight_data_segments(frame, smoothed, vehicle, load_database(vehicle), "low")
    std = ref.flight_data
    assert len(fd) == len(std) > 1000
    np.testing.assert_allclose(fd["rho_kg_m3"] / std["rho_kg_m3"], 0.958, rtol=1e-12)
    np.testing.assert_array_equal(fd["mach"].to_numpy(), std["mach"].to_numpy())
    for c in ("CA", "CY", "CN", "Cl", "Cm", "Cn", "sigma_CN", "sigma_Cm"):
        np.testing.assert_allclose(fd[c] / std[c], 1 / 0.958, rtol=1e-12, err_msg=c)
    assert flight_air_data_sources(frame.columns)["rho_kg_m3"] == "measured: rho_kg_m3"
    assert flight_air_data_sources(ref.preprocessed.frame.columns)["rho_kg_m3"] == US1976
    # the airspeed's kind is said too: the run prints it with the air data's sources
    assert "taken as the true airspeed" in flight_air_data_sources(frame.columns)["V_m_s"]
    assert "calibrated airspeed, converted" in flight_air_data_sources(frame.columns, "calibrated")["V_m_s"]


def test_a_measured_value_missing_in_a_gap_drops_those_rows_only(low_density):
    pre, ref = low_density
    vehicle = load_vehicle("seed-rlv")
    frame = pre.frame.copy()
    t = frame["t_s"].to_numpy()
    frame.loc[(t > 20.0) & (t < 21.0), "rho_kg_m3_clean"] = np.nan  # an unfilled gap of the density only
    fd = build_flight_data_segments(frame, [s.frame for s in ref.smoothed], vehicle, load_database(vehicle), "gap")
    assert not ((fd["t_s"] > 20.0) & (fd["t_s"] < 21.0)).any()
    assert len(ref.flight_data) - len(fd) == int(((ref.flight_data["t_s"] > 20.0) & (ref.flight_data["t_s"] < 21.0)).sum())
    assert np.isfinite(fd["rho_kg_m3"]).all()


def test_a_non_positive_measured_value_names_segment_column_and_time(low_density):
    pre, ref = low_density
    vehicle = load_vehicle("seed-rlv")
    frame = pre.frame.copy()
    frame.loc[frame["t_s"].between(30.0, 30.05), "rho_kg_m3_clean"] = 0.0
    with pytest.raises(ValueError, match=r"segment seg\d+: column 'rho_kg_m3'.* t = 30\.0"):
        build_flight_data_segments(frame, [s.frame for s in ref.smoothed], vehicle, load_database(vehicle), "x")
