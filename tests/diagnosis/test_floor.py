"""The floor of the error (aerosid.diagnosis.floor; issue 18 item 3): the band path's
coefficient sigma against the band path itself, and the floor of a complete model against
its residual."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from aerosid.diagnosis import diagnose
from aerosid.diagnosis.floor import band_sigmas, floors
from aerosid.diagnosis.synthetic import MEASURED_NOISE, flight_data_from_truth
from aerosid.identification.band import band_limited_signals, band_noise_gain
from aerosid.vehicles.vehicle import load_vehicle


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle("seed-rlv")


def test_band_sigmas_are_the_band_paths_own_noise(vehicle):
    """White gyro and accelerometer noise, no motion, through the band path: the spread of the
    coefficients it makes is what band_sigmas predicts (MC tolerance 5 %: ~4e3 effective samples)."""
    rng = np.random.default_rng(11)
    n, fs, band, qbar = 100000, 100.0, 2.0, 4.0e4
    t = np.arange(n) / fs
    sg, sa = np.array([0.02, 0.01, 0.005]), np.array([0.3, 0.4, 0.5])
    inertia = (vehicle.Ixx_kg_m2, vehicle.Iyy_kg_m2, vehicle.Izz_kg_m2, vehicle.Ixz_kg_m2)
    bl = band_limited_signals(t, rng.standard_normal((n, 3)) * sg, rng.standard_normal((n, 3)) * sa, inertia,
                              vehicle.accel_offset_m, band_hz=band)
    m = bl.used
    qs = qbar * vehicle.S_m2
    made = {"Cl": bl.ang_accel_rad_s2[m, 0] * vehicle.Ixx_kg_m2 / (qs * vehicle.length_lateral_m),
            "Cm": bl.ang_accel_rad_s2[m, 1] * vehicle.Iyy_kg_m2 / (qs * vehicle.length_pitch_m),
            "Cn": bl.ang_accel_rad_s2[m, 2] * vehicle.Izz_kg_m2 / (qs * vehicle.length_lateral_m),
            "CN": -bl.accel_cg_m_s2[m, 2] * vehicle.mass_kg / qs, "CY": bl.accel_cg_m_s2[m, 1] * vehicle.mass_kg / qs}
    fd = pd.DataFrame({"t_s": t, "band_hz": band, "qbar_pa": qbar,
                       **{f"eiv_sigma_{c}_rad_s": sg[j] for j, c in enumerate("pqr")},
                       **{f"R_sigma_a{c}_m_s2": sa[j] for j, c in enumerate("xyz")}})
    predicted = band_sigmas(fd, vehicle)
    for ch, x in made.items():
        assert float(np.std(x)) == pytest.approx(float(predicted[ch][0]), rel=0.05), ch
    # without the gyros' sigma (the smoother path writes 0) there is no band floor
    assert band_sigmas(fd.assign(eiv_sigma_q_rad_s=0.0, eiv_sigma_p_rad_s=0.0, eiv_sigma_r_rad_s=0.0),
                       vehicle) is None


def test_floors_falls_back_to_the_sigma_columns(vehicle):
    fd = pd.DataFrame({"sigma_Cm": np.full(50, 3.0)})
    f = floors({"Cm": np.full(50, 5.0)}, fd, {"Cm": 4.0}, vehicle)["Cm"]
    assert (f.coefficient_floor_rms, f.angle_floor_rms, f.floor_rms) == pytest.approx((3.0, 4.0, 5.0))
    assert f.excess_rms == 0.0 and f.method == "smoother sigma"


def test_a_complete_model_sits_on_its_floor(reference_flight, vehicle):
    """No hidden effect, so the default models are complete: the residual is the coefficient's
    own error and the angles' error through the fit, which the floor adds in quadrature.  The
    angles' part is measured by refits with one more draw of their noise (white sigma given
    per sample, through the band as the data's own)."""
    noise = MEASURED_NOISE.scaled(0.25)
    fd = flight_data_from_truth(reference_flight.truth, noise, seed=3)
    fs = 1.0 / float(np.median(np.diff(fd["t_s"].to_numpy(float))))
    gain = band_noise_gain(fs, noise.cutoff_hz)
    fd["band_hz"] = noise.cutoff_hz
    fd["eiv_sigma_alpha_rad"] = noise.alpha_rad / gain
    fd["eiv_sigma_beta_rad"] = noise.beta_rad / gain
    f = diagnose(fd, vehicle).floor["Cm"]
    assert f.coefficient_floor_rms == pytest.approx(noise.Cm)  # no R columns: the sigma column
    assert f.angle_floor_rms > 0.3 * f.coefficient_floor_rms  # the angles matter on this flight
    assert f.residual_rms == pytest.approx(f.floor_rms, rel=0.15)
    # without the angles' part the floor would leave a large "excess" on a complete model
    assert f.residual_rms > 1.1 * f.coefficient_floor_rms
