"""The band order of a model's non-linear columns (aerosid.identification.band_order): the
band path forms a term from the low-passed signals, f(LP(x)), where the flight-derived
coefficient holds LP(f(x)); the fit's columns are now LP(f(x_wide))."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from aerosid.diagnosis.lookalikes import scaled_lstsq
from aerosid.identification.band import low_pass_runs
from aerosid.identification.band_order import WIDEBAND_COLUMNS, band_order, flight_data_runs
from aerosid.identification.inversion import total_angles
from aerosid.modelling.models import ChannelModel, default_models, parse_term, vehicle_signals
from aerosid.vehicles.vehicle import load_vehicle

N, FS, BAND = 6000, 100.0, 1.0
EDGE = int(np.ceil(FS / BAND))
INNER = slice(EDGE, N - EDGE)


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle("seed-rlv")


def _band_frame(n: int, fs: float, band: float, wide: dict) -> pd.DataFrame:
    """A band-path flight-data frame of one run: every regressor signal the band's low-pass of
    its wide-band column (given in `wide`, SI), alpha_r and phi_r formed after the low-pass, as
    the band path does."""
    lp = {c: low_pass_runs(np.asarray(x, float), fs, band, [slice(0, n)]) for c, x in wide.items()}
    fd = pd.DataFrame({"t_s": np.arange(n) / fs, "flight": "f", "segment": "s", "band_hz": band,
                       "mach": lp["V_m_s"] / 300.0, "qbar_pa": 0.5 * 1.2 * lp["V_m_s"] ** 2, **lp,
                       **{WIDEBAND_COLUMNS[c]: np.asarray(x, float) for c, x in wide.items()}})
    fd["alpha_r_rad"], fd["phi_r_rad"] = total_angles(fd["alpha_rad"], fd["beta_rad"])
    return fd


ZEROS = ("p_rad_s", "q_rad_s", "r_rad_s", "delta_p_rad", "delta_y_rad", "delta_r_rad")


def _square_flight():
    """alpha: a slow swing plus a 0.7 Hz tone inside the 1 Hz band whose amplitude varies slowly:
    the low-pass attenuates the tone (|H| = 0.90) and alpha^2's 1.4 Hz harmonic (|H| = 0.45), so
    LP(alpha)^2 is not LP(alpha^2)."""
    t = np.arange(N) / FS
    a_t = 0.05 * (1.0 + 0.5 * np.cos(2 * np.pi * 0.13 * t))
    alpha = 0.1 + 0.05 * np.sin(2 * np.pi * 0.05 * t) + a_t * np.sin(2 * np.pi * 0.7 * t)
    wide = {"alpha_rad": alpha, "beta_rad": np.zeros(N), **{c: np.zeros(N) for c in ZEROS}, "V_m_s": np.full(N, 300.0)}
    return _band_frame(N, FS, BAND, wide), alpha


def _fit(fd, vehicle, y, expression, with_band_order=True):
    """(coefficient of the term, residual RMS / std(y)) of Cm = c0 + c1 expression inside the runs."""
    model = ChannelModel("Cm", (parse_term("Cm_0 = 1", "Cm"), parse_term(f"Cm_x = {expression}", "Cm")))
    A = model.design(vehicle_signals(fd, vehicle, with_band_order=with_band_order))[0].to_numpy(float)[INNER]
    theta = scaled_lstsq(A, y[INNER])
    return theta[1], float(np.sqrt(np.mean((y[INNER] - A @ theta) ** 2)) / np.std(y[INNER]))


def test_a_square_is_low_passed_after_it_is_formed(vehicle):
    """Cm = 0.01 + k LP(alpha^2): in the band's order the model [1, alpha^2] recovers k and leaves
    (almost) nothing inside the runs; formed from the low-passed alpha (the order before) it
    leaves 6 % of Cm's spread, which a refit cannot take.  A term linear in the signals has no
    correction."""
    fd, alpha = _square_flight()
    k = 2.0
    y = 0.01 + k * low_pass_runs(alpha ** 2, FS, BAND, [slice(0, N)])
    k_new, res_new = _fit(fd, vehicle, y, "alpha**2")
    k_old, res_old = _fit(fd, vehicle, y, "alpha**2", with_band_order=False)
    assert k_new == pytest.approx(k, rel=1e-4)
    assert res_old > 0.03 and res_new < 0.02 * res_old
    bo = band_order(fd, vehicle)
    assert np.max(np.abs(bo.correction("alpha"))) < 1e-12 and np.max(np.abs(bo.correction("delta_p/2"))) < 1e-15
    assert bo.correction("1") is None
    d = bo.correction("alpha**2")
    assert not np.any(d[:EDGE]) and not np.any(d[-EDGE:])  # the filter's transients keep the old column


def test_sensor_noise_is_not_rectified_into_a_kink(vehicle, monkeypatch):
    """C = 0.01 + 0.4 LP(|beta|), beta swinging through 0 by +-0.02 rad and its vane adding white
    noise of 0.005 rad: formed from the raw vane, |beta + n| > |beta| near the kink and the slope
    came out +6.6 %; with the wide-band signal first low-passed at WIDE_BAND_FACTOR x the band
    (the noise far above the band out) it is within 1 %."""
    import aerosid.identification.band_order as band_order_module

    t = np.arange(N) / FS
    beta = 0.02 * np.sin(2 * np.pi * 0.2 * t) * (1 + 0.5 * np.sin(2 * np.pi * 0.03 * t))
    vane = beta + 0.005 * np.random.default_rng(1).standard_normal(N)
    wide = {"alpha_rad": np.full(N, 0.05), "beta_rad": vane, **{c: np.zeros(N) for c in ZEROS},
            "V_m_s": np.full(N, 300.0)}
    fd = _band_frame(N, FS, BAND, wide)
    y = 0.01 + 0.4 * low_pass_runs(np.abs(beta), FS, BAND, [slice(0, N)])
    assert _fit(fd, vehicle, y, "abs(beta)")[0] == pytest.approx(0.4, rel=0.01)
    monkeypatch.setattr(band_order_module, "WIDE_BAND_FACTOR", None)
    assert _fit(fd, vehicle, y, "abs(beta)")[0] > 1.04 * 0.4


def test_a_row_subset_of_the_signals_keeps_its_rows_corrections(vehicle):
    """Windows (the diagnosis' held-out windows, a designed flight's window) subset the signals'
    arrays: each kept sample keeps its own row's correction."""
    from aerosid.modelling.expressions import evaluate

    fd, _ = _square_flight()
    sig = vehicle_signals(fd, vehicle)
    full = evaluate("alpha**2", sig)
    keep = np.zeros(N, bool)
    keep[1000:1500] = keep[4000:4100] = True
    sub = {k: np.asarray(v)[keep] if np.ndim(v) else v for k, v in sig.items()}
    np.testing.assert_array_equal(evaluate("alpha**2", sub), full[keep])
    # a signal a caller added has no wide-band form: its terms keep f(x)
    extra = {**sig, "extra": np.full(N, 2.0)}
    np.testing.assert_array_equal(evaluate("extra*alpha**2", extra), 2.0 * sig["alpha"] ** 2)


def test_flight_data_without_wide_band_values_keep_the_old_columns(vehicle):
    """A flight pooled with one written before the wide-band columns (NaN there) keeps f(x) on
    that flight's rows and is corrected on its own; flight data without the columns (the smoother
    path, older files) have no band order."""
    fd, _ = _square_flight()
    old = fd.assign(flight="older", **{c: np.nan for c in fd.columns if "wideband" in c})
    pooled = pd.concat([fd, old], ignore_index=True)
    d = band_order(pooled, vehicle).correction("alpha**2")
    assert not np.any(d[N:])
    np.testing.assert_allclose(d[:N], band_order(fd, vehicle).correction("alpha**2"), atol=1e-12)
    assert band_order(fd.drop(columns=["alpha_wideband_rad"]), vehicle) is None


def test_a_complete_model_on_noise_free_band_limited_truth_leaves_almost_nothing(reference_flight, vehicle):
    """No noise, no hidden effect, the default models complete: formed after the low-pass, the
    Cl model's non-linear roll terms (cos 4 phi_r, alpha_r near alpha_r = 0) left a residual of
    their own (4.4-4.8e-5, 1.1-1.5 x the Cl floor on noisy flights); in the band's order the
    residual is a small fraction of it.  Cm's model is linear and unchanged."""
    from aerosid.identification.identify import mach_window_mask

    tr = reference_flight.truth
    tr = tr.loc[mach_window_mask(tr["mach"].to_numpy(float), vehicle.mach_reference, 0.5)].reset_index(drop=True)
    n = len(tr)
    fs, band = 1.0 / float(np.median(np.diff(tr["t_s"]))), 0.75
    cols = ("alpha_rad", "beta_rad", "p_rad_s", "q_rad_s", "r_rad_s", "delta_p_rad", "delta_y_rad", "delta_r_rad",
            "V_m_s")
    fd = _band_frame(n, fs, band, {c: tr[c].to_numpy(float) for c in cols})
    fd["t_s"] = tr["t_s"].to_numpy(float)
    for c in ("mach", "qbar_pa", "Cl", "Cm"):
        fd[c] = low_pass_runs(tr[c].to_numpy(float), fs, band, [slice(0, n)])
    models = default_models(vehicle)
    edge = int(np.ceil(fs / band))
    inner = slice(edge, n - edge)
    resid = {}
    for order in (True, False):
        sig = vehicle_signals(fd, vehicle, with_band_order=order)
        for ch in ("Cl", "Cm"):
            A = models[ch].design(sig)[0].to_numpy(float)[inner]
            y = fd[ch].to_numpy(float)[inner]
            resid[ch, order] = float(np.sqrt(np.mean((y - A @ scaled_lstsq(A, y)) ** 2)))
    assert resid["Cl", False] > 1e-5  # the old order's own error is real here ...
    assert resid["Cl", True] < 0.3 * resid["Cl", False]  # ... and the band's order removes most of it
    assert resid["Cm", True] == pytest.approx(resid["Cm", False], rel=0.02)


def test_flight_data_runs_keep_each_flights_rate_and_cut_at_holes_and_invalid_rows():
    """Two flights pooled, 100 Hz and 50 Hz, band 1 Hz: each run gets its own flight's rate
    (and so its own edge of one band period); a time hole, a change of segment and a row
    without its wide-band values each end a run; runs of two band periods or less are dropped."""
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


def test_a_trial_term_not_kept_gives_the_same_column_and_keeps_the_model_terms(vehicle):
    """A scan's trial terms (the localisation's kink positions) are corrected like any term but not
    kept: the flight data's kept corrections (the model's own terms) are not pushed out by them."""
    from aerosid.modelling.expressions import evaluate

    fd, _ = _square_flight()
    sig = vehicle_signals(fd, vehicle)
    bo = sig["_band_order"]
    kept = evaluate("alpha**2", sig)
    wide = bo._state["wide"]
    before = list(wide.corrections)
    trials = [evaluate(f"abs(alpha - {float(k)!r})", sig, keep_band_order=False) for k in np.linspace(0.05, 0.15, 100)]
    assert list(wide.corrections) == before and "alpha**2" in wide.corrections
    again = evaluate("abs(alpha - 0.1)", sig)  # the same column whether kept or not
    assert np.array_equal(again, evaluate("abs(alpha - 0.1)", sig, keep_band_order=False))
    assert np.max(np.abs(again - np.abs(fd["alpha_rad"].to_numpy()[sig["_row"]] - 0.1))) > 1e-3  # corrected
    assert np.array_equal(kept, evaluate("alpha**2", sig)) and len(trials) == 100


def test_the_guard_leaves_a_linear_term_and_ordinary_rows_as_they_were():
    from aerosid.identification.band_order import guarded_column

    rng = np.random.default_rng(3)
    t = np.arange(2000) / 100.0
    x = 0.05 * np.sin(2 * np.pi * 0.3 * t)
    low = x + rng.normal(0, 1e-3, t.size)  # f(LP(x_wide)) differs from f(x) by the angles' noise
    d_round = np.full(t.size, 1e-19)  # a linear term: d is rounding
    np.testing.assert_array_equal(guarded_column(x, d_round, low), x + d_round)
    # a non-linear term whose bracket is only noise, 0.3 % of the term's spread
    d = 0.01 * np.cos(2 * np.pi * 0.1 * t)
    noisy = low + rng.normal(0, 1e-4, t.size)
    np.testing.assert_array_equal(guarded_column(noisy, d, low), noisy + d)


def test_the_guard_takes_the_wide_band_column_where_the_column_leaves_the_terms_range():
    from aerosid.identification.band_order import guarded_column

    rng = np.random.default_rng(4)
    t = np.arange(3000) / 100.0
    band = 0.75 + 0.2 * np.sin(2 * np.pi * 0.2 * t)  # LP(f(x_wide)) of cos 4 phi_r
    d = 0.02 * np.sin(2 * np.pi * 0.05 * t)
    f_low = band - d
    values = f_low + rng.normal(0, 0.003, t.size)  # f(x): the flight data's angles, noisy
    bad = np.arange(500, 3000, 250)  # alpha_r ~ 0: phi_r from the noise of x and of LP(x_wide) apart
    f_low[bad], values[bad] = -0.9, 0.95  # f(x) + d = 0.95 + (band + 0.9): beyond any cosine
    col = guarded_column(values, band - f_low, f_low)
    np.testing.assert_allclose(col[bad], band[bad])
    good = np.setdiff1d(np.arange(t.size), bad)
    np.testing.assert_allclose(col[good], values[good] + d[good], atol=1e-15)


def test_on_the_reference_flight_cos_4_phi_r_stays_a_cosine(reference_run, vehicle):
    """Inverted angles: the flight data's x (from low-passed forces) and LP(x_wide) (from the
    smoother's) differ by their noise, and where alpha_r ~ 0 that is all of phi_r.  f(x) + d then
    left cos 4 phi_r's range on ~10 % of the rows (up to 2.6); guarded, only by the bracket's noise."""
    from aerosid.identification.identify import mach_window_mask
    from aerosid.modelling.expressions import evaluate

    fd = reference_run.flight_data.sort_values(["flight", "t_s"], kind="stable")
    fd = fd[mach_window_mask(fd["mach"].to_numpy(float), vehicle.mach_reference, 0.5)].reset_index(drop=True)
    col = evaluate("cos(4*phi_r)", vehicle_signals(fd, vehicle), len(fd))
    assert np.nanmax(np.abs(col)) < 1.25
    unguarded = evaluate("cos(4*phi_r)", vehicle_signals(fd, vehicle, with_band_order=False), len(fd))
    assert np.nanmax(np.abs(unguarded)) <= 1.0 + 1e-12  # f(x) itself is a cosine: the excess was the bracket's
