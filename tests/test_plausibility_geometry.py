"""The vehicle file's reference geometry against itself (aerosid/plausibility/geometry.py): a
chord or span in ft, or a wing area in ft^2, is named; the shipped and generated files pass."""
from __future__ import annotations

import dataclasses

import pytest

from aerosid.plausibility.geometry import chord_ratio, geometry_findings
from aerosid.vehicles.vehicle import load_vehicle

FT = 0.3048
T_S = [0.0, 10.0, 20.0]


def test_the_shipped_aircraft_pass_and_a_length_in_feet_is_named():
    c172x = load_vehicle("c172x")
    assert 1.0 <= chord_ratio(c172x) <= 1.1 and geometry_findings(c172x, T_S) == []
    for change, named in ((dict(chord_m=c172x.chord_m / FT), "chord_m in ft or span_m in ft"),
                          (dict(span_m=c172x.span_m / FT), "chord_m in ft or span_m in ft"),
                          (dict(S_m2=c172x.S_m2 / FT**2), "S_m2 in ft^2")):
        (found,) = geometry_findings(dataclasses.replace(c172x, **change), T_S)
        assert found["kind"] == "vehicle_geometry" and named in found["detail"], found["detail"]
        assert found["t0_s"] == 0.0 and found["t1_s"] == 20.0 and "[plausibility] chord_ratio" in found["detail"]
    # a stated range accepts it (an unusual planform); a finned vehicle has no such check
    wide = dataclasses.replace(c172x, chord_m=c172x.chord_m / FT,
                               plausibility=dataclasses.replace(c172x.envelope, chord_ratio=(0.4, 5.0)))
    assert geometry_findings(wide, T_S) == []
    assert geometry_findings(load_vehicle("seed-rlv"), T_S) == []


def test_a_generated_file_states_jsbsims_own_odd_metrics():
    """minisgs: JSBSim's wing area is 9 x its span times its chord (ratio 0.108); the generated
    file widens its chord_ratio and says why, so its runs do not report a unit slip."""
    try:
        from aerosid.simulation.jsbsim_aircraft import simulate_aircraft
        text = simulate_aircraft("minisgs", 0, faults=False).files["vehicle.toml"]
    except ImportError as exc:  # jsbsim is an optional extra
        pytest.skip(f"jsbsim: {exc}")
    assert "chord / (S / span) = 0.108" in text and "chord_ratio = [" in text
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "v.toml").write_text(text)
        veh = load_vehicle(Path(d) / "v.toml")
    assert geometry_findings(veh, T_S) == []
