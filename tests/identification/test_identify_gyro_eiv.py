"""identify() with the gyro part of the SIMEX correction (aerosid.identification.eiv): the
switch off, a flight data frame without the eiv_sigma_p/q/r columns (written before them) and
one with zero gyro noise all give the angle-only answer bit for bit; gyro noise moves it, by
default only in the channels whose model reads no angle rate."""
from __future__ import annotations

import numpy as np
import pytest

from aerosid.diagnosis.synthetic import MEASURED_NOISE, flight_data_from_truth
from aerosid.identification.eiv_fit import RATE_EIV_COLUMNS
from aerosid.identification.identify import identify
from aerosid.modelling.models import default_models, parse_term

COLUMNS = ("estimate", "std_error", "ci_low", "ci_high")


@pytest.fixture(scope="module")
def frames(clean_truth):
    """(vehicle, flight data without the gyro columns, with zero gyro noise, with the noise)."""
    veh, tr, _ = clean_truth
    fd = flight_data_from_truth(tr, MEASURED_NOISE, seed=0)
    fd["band_hz"] = 2.0
    fd["eiv_sigma_alpha_rad"] = fd["eiv_sigma_beta_rad"] = MEASURED_NOISE.alpha_rad
    zero, noisy = fd.copy(), fd.copy()
    for c in RATE_EIV_COLUMNS:
        zero[c] = 0.0
        noisy[c] = MEASURED_NOISE.rates_rad_s
    models = default_models(veh)
    models["Cm"] = models["Cm"].with_term(parse_term("Cm_q = q_hat", "Cm"))  # a rate regressor
    return veh, models, fd, zero, noisy


def _same(a, b) -> bool:
    ta, tb = a.table(), b.table()
    return (all(np.array_equal(ta[c].to_numpy(), tb[c].to_numpy(), equal_nan=True) for c in COLUMNS)
            and list(ta["warnings"]) == list(tb["warnings"]))


def test_zero_gyro_noise_and_the_switch_off_are_bit_identical_to_the_angle_only_correction(frames):
    veh, models, without, zero, noisy = frames
    before = identify(without, veh, models)
    assert _same(identify(zero, veh, models), before)
    assert _same(identify(noisy, veh, models, gyro_eiv=False), before)
    assert "gyro noise" not in " ".join(before.table()["warnings"])
    on = identify(noisy, veh, models, gyro_eiv=True)  # the comparisons above can fail: the gyro noise moves the rate terms
    est_on = on.table().set_index("coefficient")["estimate"]
    est_off = before.table().set_index("coefficient")["estimate"]
    # the move undoes the attenuation the DECLARED rate noise would make (eiv_sigma_q, white, through
    # the 2 Hz band; the frame's own q noise is other and larger): about var(that noise) / var(q), one
    # noisy regressor's closed form, in the de-attenuating direction (measured move 8.6e-4 against
    # 6.8e-4 when written: q correlates with the other C_m regressors; the earlier independent
    # draws' Monte-Carlo error gave more)
    from aerosid.identification.band import band_noise_gain

    fs = 1.0 / float(np.median(np.diff(noisy["t_s"].to_numpy(float))))
    expected = (band_noise_gain(fs, 2.0) * MEASURED_NOISE.rates_rad_s / noisy["q_rad_s"].std()) ** 2
    assert 0.5 * expected < est_on["Cm_q"] / est_off["Cm_q"] - 1 < 2.0 * expected
    assert "gyro noise in the band-limited rates" in " ".join(on.table()["warnings"])
    # the default ("auto", identify.GYRO_EIV_DEFAULT) corrects the channels whose model reads no angle
    # rate: here every one (C_m reads q_hat, not alpha_dot_hat)
    assert _same(identify(noisy, veh, models), on)


def test_by_default_the_gyro_correction_leaves_out_the_channels_that_read_an_angle_rate(frames):
    """gyro_eiv="auto": a C_m with an alpha_dot_hat term gets the angles' correction alone (as
    gyro_eiv=False), the other channels the rates' too (as gyro_eiv=True), row for row."""
    from aerosid.identification.eiv_fit import angle_rate_free_channels

    veh, models, _, _, noisy = frames
    models = dict(models)
    models["Cm"] = models["Cm"].with_term(parse_term("Cm_alpha_dot = alpha_dot_hat", "Cm"))
    models["Cn"] = models["Cn"].with_term(parse_term("Cn_r = r_hat", "Cn"))  # a rate regressor outside C_m
    assert "Cm" not in angle_rate_free_channels(models) and "Cn" in angle_rate_free_channels(models)
    _same_by_channel(*(identify(noisy, veh, models, gyro_eiv=g).table().set_index("coefficient")
                       for g in ("auto", False, True)))


def _same_by_channel(auto, off, on) -> None:
    """auto equals off row for row (estimates, intervals and warnings) on C_m, and on elsewhere; and
    on differs from off on both C_m and C_n (so that each comparison can fail)."""
    for coef in auto.index:
        ref = off if coef.startswith("Cm_") else on
        for c in COLUMNS:
            assert np.array_equal(np.asarray(auto.loc[coef, c], float), np.asarray(ref.loc[coef, c], float),
                                  equal_nan=True), (coef, c)
        assert auto.loc[coef, "warnings"] == ref.loc[coef, "warnings"], coef
    for coef in ("Cn_r", "Cm_alpha_dot"):
        assert not np.isclose(on.loc[coef, "estimate"], off.loc[coef, "estimate"], rtol=1e-6), coef
    assert "gyro noise" in auto.loc["Cn_r", "warnings"] and "gyro noise" not in auto.loc["Cm_alpha_dot", "warnings"]


@pytest.mark.parametrize("kinematic_alpha", [False, True])
def test_the_rate_free_channels_stay_gyro_free_when_alpha_dot_comes_from_the_kinematics(frames, monkeypatch,
                                                                                    kinematic_alpha):
    """With models.KINEMATIC_ALPHA_DOT (off by default) alpha_dot_hat of a vane aircraft reads p, q, r
    (and with KINEMATIC_ALPHA alpha too): the channel left out of the gyros' part must then read them
    from the measured rates."""
    from dataclasses import replace

    from aerosid.modelling import models as model_signals

    veh, models, _, _, noisy = frames
    veh = replace(veh, air_data_source="vanes")
    models = dict(models)
    models["Cm"] = models["Cm"].with_term(parse_term("Cm_alpha_dot = alpha_dot_hat", "Cm"))
    models["Cn"] = models["Cn"].with_term(parse_term("Cn_r = r_hat", "Cn"))
    monkeypatch.setattr(model_signals, "KINEMATIC_ALPHA_DOT", True)
    kin = model_signals.vehicle_signals(noisy, veh)["alpha_dot_hat"]
    monkeypatch.setattr(model_signals, "KINEMATIC_ALPHA_DOT", False)
    assert not np.allclose(kin, model_signals.vehicle_signals(noisy, veh)["alpha_dot_hat"])  # the switch acts
    monkeypatch.setattr(model_signals, "KINEMATIC_ALPHA_DOT", True)
    monkeypatch.setattr(model_signals, "KINEMATIC_ALPHA", kinematic_alpha)
    _same_by_channel(*(identify(noisy, veh, models, gyro_eiv=g).table().set_index("coefficient")
                       for g in ("auto", False, True)))
    with pytest.raises(ValueError, match="gyro_eiv"):
        identify(noisy, veh, models, gyro_eiv="lateral")


def test_the_gyro_noise_is_the_filters_R_else_the_band_estimate_and_zero_for_the_smoothers_rates():
    import pandas as pd

    from aerosid.identification.flight_data import gyro_eiv_sigma

    sm = pd.DataFrame({"R_sigma_p_rad_s": [0.003] * 4, "R_sigma_q_rad_s": [0.002, 0.002, np.nan, 0.0]})
    out = gyro_eiv_sigma(sm, (0.01, 0.02, 0.03))
    assert list(out) == list(RATE_EIV_COLUMNS)
    assert np.array_equal(out["eiv_sigma_p_rad_s"], [0.003] * 4)  # the filter's R
    assert np.array_equal(out["eiv_sigma_q_rad_s"], [0.002, 0.002, 0.02, 0.02])  # R unusable: the band's
    assert np.array_equal(out["eiv_sigma_r_rad_s"], [0.03] * 4)  # no R column: the band's
    assert all(np.array_equal(v, np.zeros(4)) for v in gyro_eiv_sigma(sm, None).values())  # smoother's rates
