"""No silent default vehicle (issue 17): a telemetry file names its vehicle in its
Parquet metadata (a built-in name, or a vehicle file relative to the telemetry's
folder) or the user gives one; otherwise a clear error lists the built-in vehicles."""
from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from aerosid.cli import main
from aerosid.io import NoVehicleError, telemetry_vehicle
from aerosid.simulation import load_case, simulate
from aerosid.vehicles.vehicle import DATA_DIR, builtin_vehicles


@pytest.fixture(scope="module")
def raw():
    return simulate(load_case("seed-rlv", duration_s=8.0), seed=2).telemetry


def write(frame: pd.DataFrame, path: Path, **meta: str) -> Path:
    table = pa.Table.from_pandas(frame, preserve_index=False)
    table = table.replace_schema_metadata({**(table.schema.metadata or {}),
                                           **{k.encode(): v.encode() for k, v in meta.items()}})
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(table, path)
    return path


def test_simulated_flights_name_their_builtin_vehicle(raw, tmp_path):
    assert telemetry_vehicle(write(raw, tmp_path / "a.parquet", **{"aerosid.case": "seed-rlv"})) == "seed-rlv"
    # aerosid.vehicle (an importer's) comes first
    both = write(raw, tmp_path / "b.parquet", **{"aerosid.vehicle": "c172x", "aerosid.case": "seed-rlv"})
    assert telemetry_vehicle(both) == "c172x"


def test_a_vehicle_file_is_found_relative_to_the_telemetry_folder(raw, tmp_path, monkeypatch):
    folder = tmp_path / "imported"
    path = write(raw, folder / "telemetry.parquet", **{"aerosid.vehicle": "vehicle.toml"})
    shutil.copy(DATA_DIR / "seed-rlv" / "vehicle.toml", folder / "vehicle.toml")
    monkeypatch.chdir(tmp_path)  # not the telemetry's folder: the path is the telemetry's, not the cwd's
    assert telemetry_vehicle(Path("imported") / "telemetry.parquet") == str((folder / "vehicle.toml").resolve())
    absolute = write(raw, tmp_path / "abs.parquet", **{"aerosid.vehicle": str(folder / "vehicle.toml")})
    assert telemetry_vehicle(absolute) == str((folder / "vehicle.toml").resolve())


@pytest.mark.parametrize("meta, expected", [
    ({}, "names no vehicle"),
    ({"aerosid.vehicle": "missing.toml"}, "names neither a built-in vehicle nor an existing vehicle file"),
    ({"aerosid.case": "737"}, "aerosid.case = '737' names neither"),
])
def test_no_usable_vehicle_is_an_error_listing_the_builtin_vehicles(raw, tmp_path, meta, expected):
    path = write(raw, tmp_path / "t.parquet", **meta)
    with pytest.raises(NoVehicleError) as exc:
        telemetry_vehicle(path)
    text = str(exc.value)
    assert expected in text and str(path) in text and "--vehicle" in text
    assert all(name in text for name in builtin_vehicles()) and len(builtin_vehicles()) >= 2
    if "aerosid.vehicle" in meta:
        assert str(tmp_path / "missing.toml") in text


def test_an_unreadable_file_is_left_to_the_preprocessing_stage(tmp_path):
    bad = tmp_path / "corrupt.parquet"
    bad.write_bytes(b"PAR1 not really")
    assert telemetry_vehicle(bad) is None


def test_aerosid_run_without_a_vehicle_fails_before_any_work_and_lists_the_vehicles(raw, tmp_path):
    path = write(raw, tmp_path / "anonymous.parquet")
    out = tmp_path / "run"
    result = CliRunner().invoke(main, ["run", str(path), "--out", str(out)])
    assert result.exit_code != 0 and isinstance(result.exception, SystemExit), result.output
    assert "Traceback" not in result.output
    assert "names no vehicle" in result.output and str(path) in result.output
    assert "seed-rlv" in result.output and "c172x" in result.output and "--vehicle" in result.output
    assert not out.exists()  # the pre-flight check: no flow ran, nothing written


def test_pooled_files_must_name_one_vehicle(raw, tmp_path):
    from flows.pipeline import pooled_vehicle

    a = write(raw, tmp_path / "a.parquet", **{"aerosid.case": "seed-rlv"})
    b = write(raw, tmp_path / "b.parquet", **{"aerosid.vehicle": "c172x"})
    with pytest.raises(ValueError, match="name different vehicles") as exc:
        pooled_vehicle([str(a), str(b)])
    assert "seed-rlv" in str(exc.value) and "c172x" in str(exc.value)
    assert pooled_vehicle([str(a), str(b)], "seed-rlv") == "seed-rlv"  # the user's choice decides
    # the same vehicle named as a built-in and as a copy of its file is one vehicle
    shutil.copy(DATA_DIR / "seed-rlv" / "vehicle.toml", tmp_path / "vehicle.toml")
    c = write(raw, tmp_path / "c.parquet", **{"aerosid.vehicle": "vehicle.toml"})
    assert pooled_vehicle([str(a), str(c)]) == "seed-rlv"
