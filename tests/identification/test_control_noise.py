"""The controls are regressors taken as exact: their surface sensors' white noise is measured
(aerosid.identification.flight_data._control_noise) and identify warns where it is a sizeable
share of a control's variation in the band (control_noise_warnings)."""
import numpy as np
import pandas as pd
import pytest

from aerosid.identification.band import band_noise_gain, low_pass_runs
from aerosid.identification.identify import CONTROL_NOISE_SHARE, control_noise_warnings
from aerosid.modelling.models import default_models
from aerosid.vehicles.vehicle import load_vehicle


class _Band:  # what _control_noise reads of the band-limited signals
    def __init__(self, n):
        self.filter_runs = ((0, n),)


def test_control_noise_is_the_fins_white_noise_through_the_mixing():
    from aerosid.identification.flight_data import CONTROL_NOISE_COLUMNS, FIN_COLUMNS, _control_noise

    vehicle = load_vehicle("seed-rlv")
    rng = np.random.default_rng(5)
    n, fs = 20000, 100.0
    t = np.arange(n) / fs
    sigma = np.array([0.001, 0.002, 0.0005, 0.0015])
    raw = {c: 0.05 * np.sin(2 * np.pi * 0.3 * t + j) + sigma[j] * rng.standard_normal(n)
           for j, c in enumerate(FIN_COLUMNS)}
    got = _control_noise(raw, vehicle, _Band(n), 7)
    # each control's weight on each fin, from the vehicle's own mix of unit deflections
    unit = [dict(zip(("delta_r", "delta_p", "delta_y"), vehicle.mix(*np.eye(4)[j]))) for j in range(4)]
    for c, col in CONTROL_NOISE_COLUMNS.items():
        expected = np.sqrt(sum((unit[j][c] * sigma[j]) ** 2 for j in range(4)))
        assert got[col].shape == (7,)
        assert got[col][0] == pytest.approx(expected, rel=0.05), c
    # a surface quantised far above its noise (held between steps) has none
    held = {c: np.round(x, 2) for c, x in raw.items()}
    assert all(v[0] == 0.0 for v in _control_noise(held, vehicle, _Band(n), 1).values())


def _flight_data(n, fs, band, spread, noise_white):
    rng = np.random.default_rng(2)
    x = low_pass_runs(rng.standard_normal(n), fs, band, [slice(0, n)])
    fd = pd.DataFrame({"t_s": np.arange(n) / fs, "band_hz": band,
                       "delta_p_rad": spread * x / x.std(), "delta_y_rad": 0.1 * x / x.std(),
                       "delta_r_rad": 0.1 * x / x.std()})
    for c in ("delta_p", "delta_y", "delta_r"):
        fd[f"eiv_sigma_{c}_rad"] = noise_white
    return fd


def test_identify_warns_where_a_controls_noise_is_a_sizeable_share_of_its_variation():
    vehicle = load_vehicle("seed-rlv")
    models = default_models(vehicle)
    n, fs, band = 5000, 100.0, 1.0
    in_band = 1e-3 / band_noise_gain(fs, band)  # white noise that is 1e-3 rad through the band
    # delta_p moving 2 x its noise (share 25 %): every term that reads it is named, in its channels
    warned = control_noise_warnings(_flight_data(n, fs, band, 2e-3, in_band), models)
    assert set(warned) == {"CN", "Cm"}
    assert "Cm_delta_p" in warned["Cm"] and "about 25%" in warned["Cm"]
    # but not on an identity channel (alpha, beta inverted from C_N, C_Y): identify skips those
    assert set(control_noise_warnings(_flight_data(n, fs, band, 2e-3, in_band), models, skip=("CN", "CY"))) == {"Cm"}
    # two segments pooled, the second at half the rate: each through its own band gain
    a, b = _flight_data(n, fs, band, 2e-3, in_band), _flight_data(n, fs / 2, band, 2e-3, in_band)
    b["t_s"] = 1000.0 + b["t_s"]  # (already at half the rate)
    pooled = pd.concat([a.assign(flight="f", segment="a"), b.assign(flight="f", segment="b")], ignore_index=True)
    share = (1e-3 ** 2 + (in_band * band_noise_gain(fs / 2, band)) ** 2) / 2 / np.var(pooled["delta_p_rad"])
    assert f"about {share:.0%}" in control_noise_warnings(pooled, models)["Cm"]
    # 10 x its noise (share 1 % < CONTROL_NOISE_SHARE): nothing
    assert 0.01 < CONTROL_NOISE_SHARE
    assert control_noise_warnings(_flight_data(n, fs, band, 1e-2, in_band), models) == {}
    # flight data without the columns (smoother path, older files): nothing
    fd = _flight_data(n, fs, band, 2e-3, in_band).drop(columns=["eiv_sigma_delta_p_rad"])
    assert control_noise_warnings(fd, models) == {}
