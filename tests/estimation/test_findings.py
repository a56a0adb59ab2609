"""The mean-NIS finding names the channels off their own NIS and, below its band, the cause
when their noise is not white (a recording low-passed before it was stored)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from aerosid.estimation.findings import nis_mean_cause, smoother_findings

NAMES = ("ax", "ay", "az", "p", "q", "r")


def _mean_nis_finding(mean_nis, chan, white):
    t = np.arange(400) * 0.02
    none = {m: np.zeros(t.size, bool) for m in NAMES}
    found, cut = smoother_findings(t, none, np.zeros(t.size, bool), mean_nis, (5.66, 6.34), "seg00",
                                   dict(zip(NAMES, chan)), dict(zip(NAMES, white)), 4.0)
    assert not cut.any()  # reported, never cut
    return [f for f in found if f.kind == "nis_mean"]


def test_below_the_band_with_low_passed_channels_names_them_and_the_cause():
    (f,) = _mean_nis_finding(3.4, (0.07, 0.9, 0.06, 1.0, 0.26, 1.2), (15, 17, 13, 19, 34, 18))
    assert "ax 0.07, az 0.06, q 0.26" in f.detail and "ay" not in f.detail.split("not white")[0]
    assert "low-pass filtered" in f.detail and "15x, 13x, 34x" in f.detail and "above 4 Hz" in f.detail


def test_below_the_band_with_white_noise_names_the_channels_but_no_low_pass():
    (f,) = _mean_nis_finding(3.4, (0.3, 0.9, 0.3, 1.0, 0.4, 1.2), (1.0, 1.0, 1.05, 0.98, 1.0, 1.0))
    assert "ax 0.30, az 0.30, q 0.40" in f.detail and "low-pass" not in f.detail


def test_above_the_band_names_the_channels_above_two():
    (f,) = _mean_nis_finding(9.0, (1.0, 1.1, 4.5, 1.0, 1.2, 1.0), (30,) * 6)
    assert "az 4.50" in f.detail and "low-pass" not in f.detail and "q 1.20" not in f.detail


def test_only_the_low_channels_whose_noise_is_not_white_are_given_the_cause_and_nan_is_skipped():
    (f,) = _mean_nis_finding(3.0, (0.07, 0.9, 0.2, float("nan"), 0.26, 1.2), (15, 17, 1.0, 19, 34, float("nan")))
    named, cause = f.detail.split("not white")
    assert "ax 0.07, az 0.20, q 0.26" in named and " p " not in named
    assert "The noise of ax, q above" in named and "15x, 34x" in cause


def test_without_the_channel_facts_the_message_is_the_plain_one():
    t = np.arange(400) * 0.02
    none = {m: np.zeros(t.size, bool) for m in NAMES}
    (f,) = smoother_findings(t, none, np.zeros(t.size, bool), 3.4, (5.66, 6.34), "seg00")[0]
    assert f.detail == ("mean NIS 3.40 below its band 5.66..6.34: the noise model does not fit this flight (the "
                        "innovations spread 0.75 x what the filter assumes), the smoother's sigma are off by about "
                        "that factor")


def test_a_mean_nis_finding_names_a_stated_chain_scale():
    """A q_chain_scale copied into a vehicle file (c172x's old 1e3, as the first 737 check did) sets
    the chains' process noise: the mean-NIS finding says so and how to undo it; without one, or on
    another kind of finding, nothing is added."""
    from aerosid.estimation.smoothing import _with_stated_chain_scale

    t = np.arange(400) * 0.02
    none = {m: np.zeros(t.size, bool) for m in NAMES}
    gated = {**none, "q": np.r_[np.zeros(100, bool), np.ones(50, bool), np.zeros(250, bool)]}
    found = smoother_findings(t, gated, np.zeros(t.size, bool), 3.4, (5.66, 6.34), "seg00")[0]
    assert {f.kind for f in found} == {"gated", "nis_mean"}
    stated = _with_stated_chain_scale(found, {"q_chain_scale": (1e3,) * 6})
    nis = next(f for f in stated if f.kind == "nis_mean")
    assert nis.detail.endswith("q_chain_scale = [1000.0, 1000.0, 1000.0, 1000.0, 1000.0, 1000.0]: leave it out "
                               "to have the flight choose it")
    assert [f for f in stated if f.kind == "gated"] == [f for f in found if f.kind == "gated"]
    assert _with_stated_chain_scale(found, {"band_hz": 2.0}) == found


def test_a_gated_finding_names_the_controls_that_moved_over_its_span():
    """One channel gated reads as a sensor fault and is cut from every regression; when a surface
    moved over the span (or within the lead before it) the finding says so, and which; a gated
    span over still controls, and the other findings, are left as they were."""
    from aerosid.estimation.smoothing import _with_manoeuvre_hint

    t = np.arange(1000) * 0.02  # 20 s at 50 Hz
    none = {m: np.zeros(t.size, bool) for m in NAMES}
    gated = {**none, "ax": (t >= 12.0) & (t < 13.5)}
    found = smoother_findings(t, gated, np.zeros(t.size, bool), 3.4, (5.66, 6.34), "seg00")[0]
    controls = np.zeros((t.size, 2))
    controls[:, 1] = np.where((t >= 11.0) & (t < 12.5), 0.03, np.where((t >= 12.5) & (t < 14.0), -0.03, 0.0))
    hinted = _with_manoeuvre_hint(found, t, controls, ["d1_rad", "d4_rad"])
    g = next(f for f in hinted if f.kind == "gated")
    assert "d4_rad moved during it" in g.detail and "d1_rad" not in g.detail and "in ax alone" in g.detail
    assert [f for f in hinted if f.kind != "gated"] == [f for f in found if f.kind != "gated"]
    still = np.zeros((t.size, 2))
    still[(t >= 2.0) & (t < 3.0), 1] = 0.03  # a doublet long before the span, beyond the lead
    assert _with_manoeuvre_hint(found, t, still, ["d1_rad", "d4_rad"]) == found
    assert _with_manoeuvre_hint(found, t, None, []) == found


def test_inside_the_band_there_is_no_finding_and_no_channel_no_cause():
    assert _mean_nis_finding(6.0, (0.07,) * 6, (30,) * 6) == []
    assert nis_mean_cause("below", {"q": 0.9}, {"q": 30.0}, 4.0) == ""


DATA = Path(__file__).parents[1] / "data" / "sidpac-twin-otter" / "lon_020213f1_018.mat"


@pytest.mark.skipif(not DATA.is_file(), reason=f"Twin Otter data not found ({DATA})")
def test_the_twin_otters_low_passed_imu_is_named_as_the_cause_of_its_low_nis():
    """Real data: the Twin Otter's IMU was low-passed before it was stored (its spectra fall by
    ~1000x from 4-8 Hz to 20-25 Hz); the smoother's mean NIS is below its band, and the finding
    says which channels and why. The white floor is at the sensors' resolution, not the dispersion."""
    import tempfile

    from aerosid.ebm import preprocess_and_plan
    from aerosid.estimation.smoothing import smooth_segment_frame
    from aerosid.vehicles.sidpac import import_sidpac
    from aerosid.vehicles.vehicle import load_vehicle

    flight = import_sidpac(DATA)
    vehicle = load_vehicle(flight.write(Path(tempfile.mkdtemp()))["vehicle"])
    pre, segments = preprocess_and_plan(flight.telemetry, vehicle)
    seg = segments[0]
    out = smooth_segment_frame(pre.frame.iloc[seg.start:seg.stop], vehicle)
    (f,) = [f for f in out.findings if f.kind == "nis_mean"]
    assert "below" in f.detail and "low-pass filtered" in f.detail
    for ch in ("ax", "az", "q"):
        assert f" {ch} 0." in f.detail.split("not white")[0]
    white = out.result.whiteness()
    assert np.all(white > 5)  # every IMU channel low-passed; simulated white noise gives 0.9-1.05
    # the floor: the noise left near Nyquist, far below the dispersion (gyros at their 0.001 deg/s steps)
    assert np.all(out.result.R_sigma_white_floor[:3] < 1e-3) and np.all(out.result.R_sigma_white_floor[3:] < 3e-5)


def test_a_segment_with_states_that_are_not_finite_is_lost_with_the_reason_and_span():
    """No Parquet of smoothed states may hold a NaN (schemas.smoothed): a segment whose filter ran
    off numerically is failed in the core with that reason, not at the schema check."""
    from types import SimpleNamespace

    import pandas as pd

    from aerosid.estimation.smoothing import SmoothedSegmentResult

    n = 200
    t = np.arange(n) * 0.01
    x = np.zeros((n, 3))
    res = SimpleNamespace(t_s=t, x_smooth=x, sigma_smooth=np.ones((n, 3)), diverged=False)
    frame = pd.DataFrame({"t_s": t, "suspect": np.zeros(n, bool)})
    ok = SmoothedSegmentResult("seg00", frame, res, (), "process noise: spectral")
    assert not ok.lost
    x[150:, 1] = np.nan
    bad = SmoothedSegmentResult("seg00", frame, res, (), "process noise: spectral")
    assert bad.lost
    assert "not finite at 50 of 200 samples, t = 1.50..1.99 s" in bad.lost_reason()
