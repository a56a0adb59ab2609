"""Shared flights of the identification tests."""
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from aerosid.identification.identified import IdentifiedModel
from aerosid.identification.output_prediction import prediction_inputs
from aerosid.modelling.models import default_models
from aerosid.simulation import load_case, simulate
from aerosid.vehicles.vehicle import load_vehicle


@pytest.fixture(scope="session")
def clean_truth():
    """seed-rlv, 24 s, no sensor noise and no faults: (vehicle, truth frame from 10 s on,
    the true linear model).  The first 12 s hold no manoeuvre; 12..24 s a pitch doublet,
    a 3-2-1-1 start and a yaw pulse."""
    case = load_case("seed-rlv", duration_s=24.0)
    case = replace(case, faults=case.faults.without_faults(), sensors=case.sensors.scaled(0.0))
    with np.errstate(divide="ignore"):  # SNR of a noise-free flight is infinite
        flight = simulate(case, seed=0)
    tr = flight.truth[flight.truth["t_s"] >= 10.0].reset_index(drop=True)
    veh = load_vehicle("seed-rlv")
    model = IdentifiedModel(default_models(veh), dict(flight.coefficients), "truth.json")
    return veh, tr, model


@pytest.fixture(scope="session")
def clean_flight(clean_truth):
    """(vehicle, prediction inputs, measured outputs, true model) of the clean flight."""
    veh, tr, model = clean_truth
    inputs = prediction_inputs(tr, veh, tr["phi_rad"], tr["theta_rad"], np.zeros(len(tr), int))
    measured = pd.DataFrame({"alpha_rad": tr["alpha_rad"], "q_rad_s": tr["q_rad_s"], "az_m_s2": tr["az_sensor_m_s2"],
                             "beta_rad": tr["beta_rad"], "p_rad_s": tr["p_rad_s"], "r_rad_s": tr["r_rad_s"],
                             "ay_m_s2": tr["ay_sensor_m_s2"]})
    return veh, inputs, measured, model


