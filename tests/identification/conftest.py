"""Shared flights of the identification tests."""
import math
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from aerosid.identification.identified import IdentifiedModel
from aerosid.identification.output_prediction import prediction_inputs
from aerosid.io import write_json_atomic, write_parquet_atomic
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




TWENTY_S = {"duration_s": 20.0, "V0_m_s": 3780.0}  # starts at M 12.5: the whole flight is in the Mach window


def _telemetry(tmp, name, seed, attitude=True, degrees=False):
    """The simulator's telemetry (with its INS attitude, phi_rad and theta_rad); attitude=False:
    without those columns; degrees: those columns in degrees (a unit mistake)."""
    flight = simulate(load_case("seed-rlv", **TWENTY_S), seed=seed)
    tel = flight.telemetry.copy()
    if not attitude:
        tel = tel.drop(columns=["phi_rad", "theta_rad"])
    elif degrees:
        for col in ("phi_rad", "theta_rad"):
            tel[col] = tel[col] * (180 / math.pi)
    path = tmp / name / "telemetry.parquet"
    write_parquet_atomic(tel, path, metadata={"aerosid.case": "seed-rlv"})
    return path


@pytest.fixture(scope="session")
def small_run(tmp_path_factory):
    """RUN_DIR as `aerosid run` lays it out (flight_data.parquet, coefficients.parquet,
    run.json), from the in-memory method on a 20 s seed-rlv flight; plus other manoeuvres."""
    from aerosid.ebm import process_telemetry
    from aerosid.vehicles.vehicle import load_vehicle

    tmp = tmp_path_factory.mktemp("validate")
    own = _telemetry(tmp, "f0", 0)
    run = process_telemetry(pd.read_parquet(own), load_vehicle("seed-rlv"), flight="f0")
    run_dir = tmp / "run"
    write_parquet_atomic(run.flight_data, run_dir / "flight_data.parquet")
    write_parquet_atomic(run.identification.table(), run_dir / "coefficients.parquet")
    write_json_atomic({"vehicle": "seed-rlv", "job": {"vehicle": "seed-rlv", "mach_half_width": 0.5,
                                                      "preprocess_params": {}, "smoothing_options": {},
                                                      "min_segment_s": 5.0}}, run_dir / "run.json")
    return {"run": run_dir, "other": _telemetry(tmp, "f1", 1), "no_attitude": _telemetry(tmp, "f2", 2, False),
            "degrees": _telemetry(tmp, "f3", 3, degrees=True), "tmp": tmp}
