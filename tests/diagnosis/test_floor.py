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


def _band_frame(n: int, fs: float, band: float, wide: dict, y: np.ndarray, channel: str) -> pd.DataFrame:
    """A band-path flight-data frame of one run: every regressor signal the band's low-pass of
    its wide-band column (given in `wide`, SI), alpha_r and phi_r formed after the low-pass, as
    the band path does; `channel` = y."""
    from aerosid.identification.band import low_pass_runs
    from aerosid.identification.flight_data import WIDEBAND_COLUMNS
    from aerosid.identification.inversion import total_angles

    lp = {c: low_pass_runs(np.asarray(x, float), fs, band, [slice(0, n)]) for c, x in wide.items()}
    fd = pd.DataFrame({"t_s": np.arange(n) / fs, "flight": "f", "segment": "s", "band_hz": band,
                       "mach": lp["V_m_s"] / 300.0, "qbar_pa": 0.5 * 1.2 * lp["V_m_s"] ** 2, channel: y, **lp,
                       **{WIDEBAND_COLUMNS[c]: np.asarray(x, float) for c, x in wide.items()}})
    fd["alpha_r_rad"], fd["phi_r_rad"] = total_angles(fd["alpha_rad"], fd["beta_rad"])
    return fd


def test_band_nonlinearity_of_a_square_closed_form(vehicle):
    """Cm = k alpha^2 with alpha a slow swing plus a tone far above the band whose amplitude
    A(t) varies slowly: the band path squares the low-passed alpha (the tone gone) where the
    coefficient holds the low-pass of the square, which keeps k A(t)^2 / 2.  The part is what
    a refit cannot take of that (its projection off the model's columns: a constant would go
    into Cm_0); a model linear in alpha has none."""
    from aerosid.diagnosis.floor import band_nonlinearity_rms
    from aerosid.modelling.models import ChannelModel, parse_term

    n, fs, band, amp, k = 6000, 100.0, 1.0, 0.05, 2.0
    t = np.arange(n) / fs
    a_t = amp * (1.0 + 0.5 * np.cos(2 * np.pi * 0.13 * t))
    wide = {"alpha_rad": 0.1 + 0.05 * np.sin(2 * np.pi * 0.05 * t) + a_t * np.sin(2 * np.pi * 8.0 * t),
            "beta_rad": np.zeros(n), **{c: np.zeros(n) for c in ("p_rad_s", "q_rad_s", "r_rad_s", "delta_p_rad",
                                                                  "delta_y_rad", "delta_r_rad")},
            "V_m_s": np.full(n, 300.0)}
    fd = _band_frame(n, fs, band, wide, np.zeros(n), "Cm")
    fd["Cm"] = k * fd["alpha_rad"] ** 2 + 0.01  # the model fits the band path's own columns exactly
    square = ChannelModel("Cm", (parse_term("Cm_0 = 1", "Cm"), parse_term("Cm_a2 = alpha**2", "Cm")))
    linear = ChannelModel("Cm", (parse_term("Cm_0 = 1", "Cm"), parse_term("Cm_a = alpha", "Cm")))
    edge = int(np.ceil(fs / band))
    inner = slice(edge, n - edge)
    c = (k * a_t ** 2 / 2)[inner]
    A = np.column_stack([np.ones(n), fd["alpha_rad"] ** 2])[inner]
    expected = np.sqrt(np.mean((c - A @ np.linalg.lstsq(A, c, rcond=None)[0]) ** 2))
    assert expected > 0.2 * np.std(c)  # the refit does not take it all
    assert band_nonlinearity_rms(fd, vehicle, {"Cm": square}, ["Cm"])["Cm"] == pytest.approx(expected, rel=0.03)
    assert band_nonlinearity_rms(fd, vehicle, {"Cm": linear}, ["Cm"])["Cm"] < 1e-9
    # pooled with a flight written before the wide-band columns (NaN there): that flight is left out
    old = fd.assign(flight="older", **{c: np.nan for c in fd.columns if "wideband" in c})
    pooled = pd.concat([fd, old], ignore_index=True)
    assert band_nonlinearity_rms(pooled, vehicle, {"Cm": square}, ["Cm"])["Cm"] == pytest.approx(expected, rel=0.03)
    # without the wide-band columns (smoother path, older files) there is no such part
    assert band_nonlinearity_rms(fd.drop(columns=["alpha_wideband_rad"]), vehicle, {"Cm": square}, ["Cm"]) == {}


def test_band_nonlinearity_is_what_a_complete_model_leaves_on_noise_free_band_limited_truth(reference_flight,
                                                                                             vehicle):
    """No noise, no hidden effect, the default models complete: on the band path the Cl model's
    residual is its non-linear roll terms formed after the low-pass, which the part predicts
    from the wide-band signals; Cm's model is linear in the signals and leaves (almost) none."""
    from aerosid.diagnosis.floor import band_nonlinearity_rms
    from aerosid.diagnosis.lookalikes import scaled_lstsq
    from aerosid.identification.band import low_pass_runs
    from aerosid.identification.identify import mach_window_mask
    from aerosid.modelling.models import default_models, vehicle_signals

    tr = reference_flight.truth
    tr = tr.loc[mach_window_mask(tr["mach"].to_numpy(float), vehicle.mach_reference, 0.5)].reset_index(drop=True)
    n = len(tr)
    fs, band = 1.0 / float(np.median(np.diff(tr["t_s"]))), 0.75
    cols = ("alpha_rad", "beta_rad", "p_rad_s", "q_rad_s", "r_rad_s", "delta_p_rad", "delta_y_rad", "delta_r_rad",
            "V_m_s")
    fd = _band_frame(n, fs, band, {c: tr[c].to_numpy(float) for c in cols}, np.zeros(n), "Cl")
    fd["t_s"] = tr["t_s"].to_numpy(float)
    fd["mach"] = low_pass_runs(tr["mach"].to_numpy(float), fs, band, [slice(0, n)])
    fd["qbar_pa"] = low_pass_runs(tr["qbar_pa"].to_numpy(float), fs, band, [slice(0, n)])
    for ch in ("Cl", "Cm"):
        fd[ch] = low_pass_runs(tr[ch].to_numpy(float), fs, band, [slice(0, n)])
    models = default_models(vehicle)
    part = band_nonlinearity_rms(fd, vehicle, models, ["Cl", "Cm"])
    edge = int(np.ceil(fs / band))
    inner = slice(edge, n - edge)
    sig = vehicle_signals(fd, vehicle)
    resid = {}
    for ch in ("Cl", "Cm"):
        A = models[ch].design(sig)[0].to_numpy(float)
        y = fd[ch].to_numpy(float)
        e = (y - A @ scaled_lstsq(A, y))[inner]
        resid[ch] = float(np.sqrt(np.mean(e * e)))
    assert resid["Cl"] > 1e-5  # the band path's own error is real here ...
    # ... and the part predicts it, on the low side (seed 0: 0.76 x): it is formed with the fitted
    # coefficients, which the band path itself tilts, not the true ones
    assert 0.6 * resid["Cl"] < part["Cl"] <= 1.05 * resid["Cl"]
    assert part["Cm"] < 0.1 * part["Cl"]


def test_flight_data_runs_keep_each_flights_rate_and_cut_at_holes_and_invalid_rows():
    """Two flights pooled, 100 Hz and 50 Hz, band 1 Hz: each run gets its own flight's rate
    (and so its own edge of one band period); a time hole, a change of segment and a row
    without its wide-band values each end a run; runs of two band periods or less are dropped."""
    from aerosid.diagnosis.floor import flight_data_runs

    t_a = np.r_[np.arange(0, 1000) * 0.01, 12.0 + np.arange(0, 600) * 0.01]  # a 2 s hole
    t_b = np.arange(0, 800) * 0.02
    fd = pd.DataFrame({"t_s": np.r_[t_a, t_b], "flight": ["a"] * t_a.size + ["b"] * t_b.size,
                       "segment": ["s0"] * 1300 + ["s1"] * 300 + ["s0"] * 800, "band_hz": 1.0})
    valid = np.ones(len(fd), bool)
    valid[1600 + 100] = False  # flight b, row 100: the 100 rows before it are too short a run
    runs = [(r.start, r.stop, round(fs), edge) for r, fs, _, edge in flight_data_runs(fd, valid)]
    assert runs == [(0, 1000, 100, 100), (1000, 1300, 100, 100), (1300, 1600, 100, 100), (1701, 2400, 50, 50)]
    # a flight without a band (smoother path) or with a zero band has no runs
    assert flight_data_runs(fd.assign(band_hz=np.where(fd["flight"] == "b", 0.0, 1.0)))[-1][0].stop == 1600
