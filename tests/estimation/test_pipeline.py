"""End to end: smooth_flight on a synthetic 21-state truth with the seed's noise levels."""
import dataclasses

import numpy as np
import pytest

from aerosid.estimation import MEAS_NAMES, STATE_NAMES, EBMOptions, EBMResult, smooth_flight


@pytest.fixture(scope="module")
def clean(flight):
    valid = np.ones_like(flight.z, bool)
    m = flight.model
    return smooth_flight(flight.t_s, flight.z, valid, m.inertia_kg_m2, m.sensor_offset_m)


@pytest.fixture(scope="module")
def dirty(flight):
    """Dropouts in all channels at once, a one-channel dropout and outliers."""
    rng = np.random.default_rng(11)
    z = flight.z.copy()
    valid = np.ones_like(z, bool)
    for start in rng.choice(np.arange(200, 7700), 12, replace=False):
        valid[start:start + rng.integers(3, 30)] = False
    valid[5000:5100, 2] = False
    out_k = rng.choice(np.arange(300, 7900), 15, replace=False)
    out_j = rng.integers(0, 6, 15)
    keep = valid[out_k, out_j]
    out_k, out_j = out_k[keep], out_j[keep]
    z[out_k, out_j] += 15.0 * flight.noise_sigma[out_j] * rng.choice([-1, 1], out_k.size)
    z[~valid] = np.nan
    m = flight.model
    res = smooth_flight(flight.t_s, z, valid, m.inertia_kg_m2, m.sensor_offset_m)
    return res, valid, out_k, out_j


def test_public_names():
    assert STATE_NAMES[:3] == ("p", "q", "r") and STATE_NAMES[-1] == "N3" and len(STATE_NAMES) == 21
    assert MEAS_NAMES == ("ax", "ay", "az", "p", "q", "r")


def test_result_is_frozen_and_summarises(clean):
    assert isinstance(clean, EBMResult)
    with pytest.raises(dataclasses.FrozenInstanceError):
        clean.diverged = True
    text = clean.summary()
    for word in ("NIS EKF", "NIS smoother", "ax", "r", "band", "q_scale"):
        assert word in text


def test_noise_sigma_recovered_within_15_percent(clean, flight):
    err = clean.R_sigma_dispersion / flight.noise_sigma - 1.0
    assert np.all(np.abs(err) < 0.15), err
    assert np.all(np.abs(clean.R_sigma / flight.noise_sigma - 1.0) < 0.15)
    assert np.all(clean.R_sigma_seed_rule > clean.R_sigma_dispersion)   # the (dy/3) rule is biased high


def test_nis_means_in_chi_square_band(clean):
    lo, hi = clean.nis_band
    assert hi - lo == pytest.approx(2 * 1.96 * np.sqrt(12 / clean.t_s.size), rel=1e-9)
    assert lo <= clean.mean_nis_filter <= hi
    assert lo <= clean.mean_nis_smoother <= hi
    assert clean.mean_residual_r < clean.mean_nis_smoother       # e'R^-1e sits below dof
    assert not clean.diverged
    rec = clean.tuning_history
    assert len(rec) >= 1 and rec[-1].mean_nis_filter == pytest.approx(clean.mean_nis_filter)


def test_errors_consistent_with_sigma(clean, flight):
    err = clean.x_smooth - flight.x_true
    cover = np.mean(np.abs(err) < 2 * clean.sigma_smooth, axis=0)
    # value states of every chain and the rates: close to the nominal 95 %
    for i in (0, 1, 2, 3, 6, 9, 12, 15, 18):
        assert 0.88 <= cover[i] <= 0.995, (STATE_NAMES[i], cover[i])
    assert np.all(clean.sigma_smooth <= clean.sigma_filter * (1 + 1e-9))
    rms = np.sqrt(np.mean(err**2, axis=0))
    assert np.all(rms[[3, 6, 9]] < 0.35 * flight.noise_sigma[:3])       # accelerations well below noise
    assert np.all(rms[:3] < 0.35 * flight.noise_sigma[3:])


def test_angular_acceleration_with_sigma(clean, flight):
    from aerosid.estimation.model import rate_rhs
    aa, sig = clean.angular_acceleration()
    prm = flight.model.params
    truth = np.array([rate_rhs(x[:3], x[[12, 15, 18]], prm) for x in flight.x_true])
    cover = np.mean(np.abs(aa - truth) < 2 * sig, axis=0)
    assert np.all((cover > 0.88) & (cover < 0.995)), cover


def test_dropouts_and_outliers(dirty, flight):
    res, valid, out_k, out_j = dirty
    assert res.gate_flags[out_k, out_j].all()                    # every injected outlier flagged
    assert res.gate_flags.sum() <= out_k.size + 3                # and (almost) nothing else
    assert not (res.used & ~valid).any()
    assert np.all(np.abs(res.R_sigma_dispersion / flight.noise_sigma - 1.0) < 0.15)
    lo, hi = res.nis_band
    assert abs(res.mean_nis_filter - np.mean(res.nis_dof[res.nis_dof > 0])) < 2 * (hi - lo)
    assert np.isnan(res.nis_filter[~valid.any(axis=1)]).all()
    err = res.x_smooth - flight.x_true
    cover = np.mean(np.abs(err) < 2 * res.sigma_smooth, axis=0)
    assert np.all(cover[[0, 1, 2, 3, 6, 9, 12, 15, 18]] > 0.85), cover


def test_numpy_path_and_no_tuning_options(short_flight):
    sf = short_flight
    valid = np.ones_like(sf.z, bool)
    m = sf.model
    opt = EBMOptions(auto_tune=False, use_numba=False)
    a = smooth_flight(sf.t_s, sf.z, valid, m.inertia_kg_m2, m.sensor_offset_m, options=opt)
    b = smooth_flight(sf.t_s, sf.z, valid, m.inertia_kg_m2, m.sensor_offset_m,
                      options=dataclasses.replace(opt, use_numba=True))
    assert len(a.tuning_history) == 1
    from .conftest import col_rel_err
    assert col_rel_err(b.x_smooth, a.x_smooth) < 1e-8
    with pytest.raises(ValueError):
        smooth_flight(sf.t_s[::-1], sf.z, valid, m.inertia_kg_m2, m.sensor_offset_m)


def test_a_record_whose_nyquist_frequency_is_below_the_noise_band_is_refused_naming_it(short_flight):
    """At 5 Hz the band above f_max_hz (4 Hz), where each channel's noise is measured, is empty:
    R came out zero and the filter broke down ("division by zero"). Refused, naming the rates."""
    sf = short_flight
    t, z = sf.t_s[::20], sf.z[::20]  # 100 Hz -> 5 Hz
    with pytest.raises(ValueError, match=r"Nyquist frequency 2\.5 Hz \(5 Hz sampling\) is not above \[estimation\] "
                                         r"f_max_hz = 4 Hz"):
        smooth_flight(t, z, np.ones_like(z, bool), sf.model.inertia_kg_m2, sf.model.sensor_offset_m)


def test_a_tuning_step_that_breaks_the_smoother_falls_back_to_the_last_finite_iteration(short_flight, monkeypatch):
    """If an auto-tuning iteration returns a non-finite smoother (seen on JSBSim flights with R at
    its EM bound), the result is the last finite iteration, not NaN states."""
    import aerosid.estimation.pipeline as pl

    real = pl.run_filter_smoother
    calls = []

    def flaky(*args, **kwargs):
        run = real(*args, **kwargs)
        calls.append(1)
        if len(calls) == 2:
            bad = np.full_like(run.x_smooth, np.nan)
            return dataclasses.replace(run, x_smooth=bad, nis_smoother=np.full_like(run.nis_smoother, np.nan))
        return run

    monkeypatch.setattr(pl, "run_filter_smoother", flaky)
    sf = short_flight
    m = sf.model
    res = smooth_flight(sf.t_s, sf.z, np.ones_like(sf.z, bool), m.inertia_kg_m2, m.sensor_offset_m,
                        options=EBMOptions(use_numba=False))
    assert len(calls) == 2 and len(res.tuning_history) == 2
    assert not np.isfinite(res.tuning_history[1].mean_nis_smoother)  # the failed step is on record
    assert np.all(np.isfinite(res.x_smooth)) and np.isfinite(res.mean_nis_smoother)
