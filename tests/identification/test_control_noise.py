"""The controls' surface sensors' white noise is measured (aerosid.identification.flight_data.
_control_noise), identify corrects the estimates for it by SIMEX (control_eiv, the default) and
warns where it is a sizeable share of a control's variation in the band (control_noise_warnings)."""
import numpy as np
import pandas as pd
import pytest

from aerosid.identification.band import band_noise_gain, low_pass_runs
from aerosid.identification.eiv_fit import CONTROL_NOISE_SHARE, control_noise_warnings
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
    # with the estimates corrected for it (identify's control_eiv), the warning says so
    both = control_noise_warnings(_flight_data(n, fs, band, 2e-3, in_band), models, corrected=("Cm",))
    assert "corrected for it by SIMEX" in both["Cm"] and "not corrected" not in both["Cm"]
    assert "not corrected" in both["CN"]  # a channel the correction left alone keeps "low by"
    # flight data without the columns (smoother path, older files): nothing
    fd = _flight_data(n, fs, band, 2e-3, in_band).drop(columns=["eiv_sigma_delta_p_rad"])
    assert control_noise_warnings(fd, models) == {}


def test_identify_corrects_for_the_controls_noise_by_default_and_zero_noise_changes_nothing(clean_truth):
    """identify's controls' part of SIMEX (control_eiv, on by default): flight data without the
    eiv_sigma_delta columns, with them zero (quantised surfaces), or with the switch off give the
    same answer bit for bit.  With one draw of white surface noise through the band actually added
    to delta_p and declared, the naive C_m_delta_p is attenuated (delta_p and alpha move together in
    this flight, so by several times the one-regressor share) and the correction takes most of it
    back toward the fit on the exact controls; the fit says what it corrected."""
    from aerosid.diagnosis.synthetic import MEASURED_NOISE, flight_data_from_truth
    from aerosid.identification.eiv import filtered_noise
    from aerosid.identification.flight_data import CONTROL_NOISE_COLUMNS
    from aerosid.identification.identify import identify

    veh, tr, _ = clean_truth
    fd = flight_data_from_truth(tr, MEASURED_NOISE, seed=0)
    fd["band_hz"] = 2.0
    fd["eiv_sigma_alpha_rad"] = fd["eiv_sigma_beta_rad"] = MEASURED_NOISE.alpha_rad
    models = default_models(veh)
    t = fd["t_s"].to_numpy(float)
    fs = 1.0 / float(np.median(np.diff(t)))
    sigma = 0.15 * float(fd["delta_p_rad"].std()) / band_noise_gain(fs, 2.0)  # 15 % of delta_p's std in the band
    zero, noisy = fd.copy(), fd.copy()
    noisy["delta_p_rad"] += filtered_noise(np.random.default_rng(11), np.zeros(len(t)), t, sigma, 2.0)
    for c, col in CONTROL_NOISE_COLUMNS.items():
        zero[col] = 0.0
        noisy[col] = sigma if c == "delta_p" else 0.0

    def table(ident):
        return ident.table().set_index("coefficient")

    declared = fd.copy()  # the noise declared, not added
    for col in CONTROL_NOISE_COLUMNS.values():
        declared[col] = noisy[col]
    exact = table(identify(fd, veh, models))
    for same in (identify(zero, veh, models), identify(declared, veh, models, control_eiv=False)):
        for c in ("estimate", "std_error"):
            np.testing.assert_array_equal(table(same)[c].to_numpy(float), exact[c].to_numpy(float))
        assert list(table(same)["warnings"]) == list(exact["warnings"])
    naive = table(identify(noisy, veh, models, control_eiv=False))
    on = table(identify(noisy, veh, models))
    assert "in the band-limited controls" not in " ".join(naive["warnings"].astype(str))
    b0, b_naive, b_on = (x.loc["Cm_delta_p", "estimate"] for x in (exact, naive, on))
    assert abs(b_naive / b0 - 1) > 0.05  # the noise's attenuation (the comparison below can fail)
    assert abs(b_on - b0) < 0.5 * abs(b_naive - b0)
    assert on.loc["Cm_delta_p", "std_error"] > naive.loc["Cm_delta_p", "std_error"]
    assert "surface-sensor noise in the band-limited controls" in on.loc["Cm_delta_p", "warnings"]


def test_the_controls_sigma_come_in_the_order_simex_adds_them():
    """identify's control_eiv_sigma reads (delta_p, delta_y, delta_r), eiv.CONTROL_COLUMNS' order, and
    gives None (the controls taken as exact) for zero or non-finite noise or no columns."""
    from aerosid.identification.eiv import CONTROL_COLUMNS
    from aerosid.identification.eiv_fit import control_eiv_sigma
    from aerosid.identification.flight_data import CONTROL_NOISE_COLUMNS

    fd = pd.DataFrame({CONTROL_NOISE_COLUMNS[c]: [v, v] for c, v in (("delta_p", 1e-3), ("delta_y", 2e-3),
                                                                     ("delta_r", 3e-3))})
    got = control_eiv_sigma(fd)
    assert [float(x[0]) for x in got] == [1e-3, 2e-3, 3e-3]
    assert [c.replace("_rad", "") for c in CONTROL_COLUMNS] == ["delta_p", "delta_y", "delta_r"]
    assert control_eiv_sigma(fd * 0.0) is None
    assert control_eiv_sigma(fd.assign(**{CONTROL_NOISE_COLUMNS["delta_y"]: np.nan})) is None
    assert control_eiv_sigma(fd.drop(columns=[CONTROL_NOISE_COLUMNS["delta_r"]])) is None
