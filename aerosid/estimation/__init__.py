"""Estimation core of aerosid (method.md §2-§6): filter initialisation, the 21-state
EKF, Bierman's Modified Bryson-Frazier smoother, NIS and automatic tuning.

Imports only numpy, scipy and numba.  Units: SI, radians.  The L, M, N chain
states are moments divided by Ixx, Iyy, Izz [rad/s^2] (aerosid.vehicles.rigid_body).
"""
from .ekf import EKFUpdate, MBFResult, ekf_predict, ekf_update, gate_channels, mbf_smooth, run_reference
from .init import (NoiseDispersion, ParabolaFit, SpectrumNoise, initial_state, measurement_noise_from_dispersion,
                   parabola_init, process_noise_from_spectrum)
from .model import (MEAS_NAMES, MEAS_UNITS, STATE_NAMES, STATE_UNITS, PlantModel, continuous_dynamics,
                    continuous_jacobian, discrete_process_noise, measure, measure_many, measurement_jacobian,
                    propagate)
from .pipeline import (CoreRun, EBMOptions, EBMResult, TuningRecord, chi2_band, divergence_flags,
                       run_filter_smoother, smooth_flight)

__all__ = [
    "smooth_flight", "EBMResult", "EBMOptions", "TuningRecord", "STATE_NAMES", "MEAS_NAMES", "STATE_UNITS",
    "MEAS_UNITS", "parabola_init", "process_noise_from_spectrum", "measurement_noise_from_dispersion",
    "initial_state", "ParabolaFit", "SpectrumNoise", "NoiseDispersion", "ekf_predict", "ekf_update",
    "gate_channels", "EKFUpdate", "mbf_smooth", "MBFResult", "run_reference", "run_filter_smoother", "CoreRun",
    "PlantModel", "propagate", "discrete_process_noise", "measure", "measure_many", "measurement_jacobian",
    "continuous_dynamics", "continuous_jacobian", "chi2_band", "divergence_flags",
]
