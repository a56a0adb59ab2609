"""Failures announce themselves and cost only what they touch (issue 16): a run of gated
samples and an end-of-flight excursion out of the force database are each reported with
their span, cut, and the rest of the segment is used."""
import numpy as np
import pandas as pd
import pytest

from aerosid.ebm import process_telemetry
from aerosid.estimation.findings import Finding, dilate, true_runs
from aerosid.vehicles.vehicle import load_vehicle


def _run(telemetry):
    return process_telemetry(telemetry, load_vehicle("seed-rlv"), flight="f")


def _kept(run, t0, t1):
    t = run.flight_data["t_s"].to_numpy()
    return np.count_nonzero((t >= t0) & (t <= t1))


def test_a_sensor_step_is_a_gated_span_cut_whole_and_the_rest_is_used(reference_flight, reference_run):
    tel = reference_flight.telemetry.copy()
    t = tel["t_s"].to_numpy()
    step = (t > 30.0) & (t < 31.5)
    tel.loc[step, "az_m_s2"] += 25.0  # a 1.5 s accelerometer bias jump: not a spike, not the vehicle
    run = _run(tel)
    gated = [Finding(**f) for f in run.findings if f["kind"] == "gated" and f["channel"] == "az"]
    assert gated, [Finding(**f).summary() for f in run.findings]
    g = gated[0]
    assert g.cut and g.t0_s <= 30.05 and g.t1_s >= 31.45  # the whole step, not only its two edges
    assert "30.0" in g.summary() and "az" in g.summary()
    assert _kept(run, 30.0, 31.5) == 0
    # the rest of the segment is kept: at most a few seconds of the ~40 s before the sync gap go
    assert len(run.flight_data) > 0.9 * len(reference_run.flight_data)
    tab = run.identification.table().set_index("coefficient")
    ref = reference_run.identification.table().set_index("coefficient")
    for name in ("Cm_alpha", "Cm_delta_p"):  # the fault costs less than the estimate's own uncertainty
        assert abs(tab.loc[name, "estimate"] - ref.loc[name, "estimate"]) <= 2 * ref.loc[name, "std_error"]


def test_a_gated_span_on_a_sensor_that_feeds_no_fitted_channel_costs_only_that_channel(reference_flight,
                                                                                       reference_run):
    """a_x feeds only C_A, which no default model fits: its gated run is reported, the other
    channels keep its samples, and a model of C_A leaves them out (JSBSim F4N at 50 Hz: a_x gated
    through the rudder doublet once took the doublet from C_n's regression)."""
    from aerosid.estimation.findings import CUT_COLUMN
    from aerosid.identification.identify import identify
    from aerosid.modelling.models import ChannelModel, default_models, parse_terms

    tel = reference_flight.telemetry.copy()
    t = tel["t_s"].to_numpy()
    step = (t > 30.0) & (t < 31.5)
    tel.loc[step, "ax_m_s2"] += 25.0  # the same bias jump as above, on the axial accelerometer
    run = _run(tel)
    gated = [Finding(**f) for f in run.findings if f["kind"] == "gated" and f["channel"] == "ax"]
    assert gated, [Finding(**f).summary() for f in run.findings]
    assert not any(g.cut for g in gated) and all("feeds only CA" in g.detail for g in gated)
    assert any(g.t0_s <= 30.05 and g.t1_s >= 31.45 for g in gated)
    assert not any(f["cut"] and f["t0_s"] <= 31.5 and f["t1_s"] >= 30.0 for f in run.findings), run.findings
    fd = run.flight_data
    assert _kept(run, 30.0, 31.5) == _kept(reference_run, 30.0, 31.5) > 0  # the other channels keep them
    inside = (fd["t_s"] > 30.05) & (fd["t_s"] < 31.45)
    assert fd.loc[inside, CUT_COLUMN["CA"]].all() and fd[CUT_COLUMN["CA"]].mean() < 0.1
    assert not fd[CUT_COLUMN["CN"]].any() and not fd[CUT_COLUMN["CY"]].any()
    vehicle = load_vehicle("seed-rlv")
    models = {**default_models(vehicle), "CA": ChannelModel("CA", parse_terms(["CA_0 = 1", "CA_alpha = alpha"], "CA"))}
    with_ca = identify(fd, vehicle, models=models, bias_pairs=0)
    without = identify(fd, vehicle, bias_pairs=0)
    # C_A's fit leaves the marked rows out, every other channel's is the fit without a C_A model
    assert with_ca.fits["Cm"].n_obs - with_ca.fits["CA"].n_obs == int(fd[CUT_COLUMN["CA"]].sum())
    assert with_ca.n_samples == without.n_samples == without.fits["Cm"].n_obs
    for ch in without.fits:
        assert np.allclose(with_ca.fits[ch].estimate, without.fits[ch].estimate, rtol=1e-9, atol=0), ch


def test_an_excursion_out_of_the_database_at_the_end_is_cut_and_named(reference_flight, reference_run):
    tel = reference_flight.telemetry.copy()
    t = tel["t_s"].to_numpy()
    late = t > 86.0  # a high-qbar transient in the last 4 s drives alpha past the table's 20 deg
    tel.loc[late, "az_m_s2"] -= 60.0 * (t[late] - 86.0)
    run = _run(tel)
    edge = [Finding(**f) for f in run.findings if f["kind"] == "database_edge"]
    assert edge and edge[-1].cut and edge[-1].t1_s >= 89.4 and 86.0 <= edge[-1].t0_s <= 88.5  # (the last 0.5 s are the band filter's edge)
    assert np.degrees(run.flight_data["alpha_r_rad"].max()) < 20.0  # nothing pinned at the edge is used
    assert _kept(run, edge[-1].t0_s, edge[-1].t1_s) == 0
    assert _kept(run, 43.0, 85.0) == _kept(reference_run, 43.0, 85.0)  # the segment before is all kept
    assert run.findings and all("cut" in f for f in run.findings)


def test_timestamps_off_the_grid_are_a_finding_of_the_in_memory_run(reference_flight):
    tel = reference_flight.telemetry.copy()
    t = tel["t_s"].to_numpy().copy()
    late = (t > 60.0) & (t < 60.8)  # 0.8 s of timestamps 0.4 step late: left empty, cut
    t[late] += 0.004
    tel["t_s"] = t
    run = _run(tel)
    jitter = [Finding(**f) for f in run.findings if f["kind"] == "time_jitter"]
    assert len(jitter) == 1 and jitter[0].cut and jitter[0].segment == "preprocess"
    assert abs(jitter[0].t0_s - 60.0) < 0.05 and abs(jitter[0].t1_s - 60.8) < 0.05
    assert "time_jitter at t = 60.0" in run.summary()
    assert _kept(run, 60.05, 60.75) == 0


def test_a_clean_reference_flight_has_no_finding(reference_run):
    assert reference_run.findings == []


def test_true_runs_and_dilate_agree():
    m = np.zeros(50, bool)
    m[[3, 4, 5, 20, 48, 49]] = True
    assert true_runs(m) == [(3, 6), (20, 21), (48, 50)]
    d = dilate(m, 2)
    assert true_runs(d) == [(1, 8), (18, 23), (46, 50)]


def test_rows_at_a_fraction_of_the_flight_s_dynamic_pressure_are_cut_and_said():
    from aerosid.identification.low_qbar import LOW_QBAR_SHARE, low_qbar_rows

    taxi = pd.DataFrame({"t_s": np.arange(300) * 0.01 - 10.0, "segment": "seg00", "qbar_pa": 10.0 + np.arange(300)})
    flight = pd.DataFrame({"t_s": np.arange(2000) * 0.01, "segment": "seg01",
                           "qbar_pa": 1300.0 + 50.0 * np.sin(np.arange(2000) * 0.01)})
    low, found = low_qbar_rows(pd.concat([taxi, flight], ignore_index=True))
    q95 = np.percentile(np.r_[taxi.qbar_pa, flight.qbar_pa], 95)
    assert np.array_equal(low, np.r_[taxi.qbar_pa < LOW_QBAR_SHARE * q95, np.zeros(2000, bool)]) and low[:300].all()
    (f,) = found
    assert (f["kind"], f["segment"], f["n_samples"], f["cut"]) == ("low_qbar", "seg00", 300, True)
    assert f["t0_s"] == -10.0 and "95th percentile" in f["detail"]
    low, found = low_qbar_rows(flight)  # a flight at its manoeuvre speed loses nothing
    assert not low.any() and found == []
