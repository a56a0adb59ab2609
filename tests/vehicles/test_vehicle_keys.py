"""Vehicle files are checked key by key (aerosid/vehicles/keys.py): unknown keys refused
with the valid ones listed, every number finite and in range, the database a bounded
regular file beside the vehicle file, deep nesting a clear error."""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import pytest

from aerosid.vehicles import vehicle as vehicle_module
from aerosid.vehicles.vehicle import VehicleError, builtin_vehicles, load_vehicle
from aerosid.vehicles.keys import TABLES

SEED = Path(vehicle_module.DATA_DIR) / "seed-rlv" / "vehicle.toml"


def edited(tmp_path: Path, old: str, new: str, database: bool = True) -> Path:
    text = SEED.read_text()
    assert old in text, old
    out = tmp_path / "vehicle.toml"
    out.write_text(text.replace(old, new, 1))
    if database:
        (tmp_path / "aerodb.csv").symlink_to(SEED.parent / "aerodb.csv")
    return out


def refused(path: Path, *expected: str) -> str:
    with pytest.raises(VehicleError) as ei:
        load_vehicle(path)
    msg = str(ei.value)
    assert msg.startswith(str(path)), msg
    for e in expected:
        assert e in msg, f"{e!r} not in {msg!r}"
    return msg


@pytest.mark.parametrize("name", builtin_vehicles())
def test_shipped_vehicle_files_pass_the_key_check(name):
    veh = load_vehicle(name)
    assert veh.envelope.rate_rad_s > 0


@pytest.mark.parametrize("old, new, key, expected", [
    ("x_cg_m = 1.675", "x_cg_m = nan", "[reference.x_cg_m]", "must be a finite number, got nan"),
    ("mach_reference = 12.4", "mach_reference = inf", "[aero.mach_reference]", "must be a finite number, got inf"),
    ("accel_offset_m = [0.85, 0.02, -0.03]", "accel_offset_m = [1e300, 0.02, -0.03]",
     "[sensors.accel_offset_m[0]]", "outside the range [-100, 100]"),
    ("mass_kg = 1100.0", "mass_kg = true", "[mass.mass_kg]", "must be a number"),
    ("Cl_0 = 0.0002", "Cl_0 = -inf", "[aero.preflight.Cl_0]", "finite"),
    ("fin_limit_rad = 0.40", "fin_limit_rad = 40.0", "[controls.fin_limit_rad]", "outside the range (0, 3.14159]"),
    ("mixing = [[1.0, 1.0, 1.0, 1.0], [0.0, -1.0, 0.0, 1.0], [-1.0, 0.0, 1.0, 0.0]]",
     "mixing = [[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]]",
     "[controls.mixing]", "row 1, delta_r (roll), is all zero"),
    ("mixing = [[1.0, 1.0, 1.0, 1.0], [0.0, -1.0, 0.0, 1.0], [-1.0, 0.0, 1.0, 0.0]]",
     "mixing = [[1.0, 1.0, 1.0, 1.0], [2.0, 2.0, 2.0, 2.0], [-1.0, 0.0, 1.0, 0.0]]",
     "[controls.mixing]", "linearly dependent"),
    ("mach_breakpoints = [2.0, 3.0,", "mach_breakpoints = [3.0, 2.0,", "[aero.preflight.mach_breakpoints]",
     "must increase strictly"),
])
def test_non_finite_or_out_of_range_numbers_are_refused(tmp_path, old, new, key, expected):
    refused(edited(tmp_path, old, new), key, expected)


@pytest.mark.parametrize("old, new, key, valid", [
    ("[aero]\n", "[estimation]\nq_chain_scal = 2.0\n\n[aero]\n", "[estimation.q_chain_scal]", "q_chain_scale"),
    ("[mass]\n", "[mass]\nmass_lb = 2425.0\n", "[mass.mass_lb]", "mass_kg, Ixx_kg_m2"),
    ("[aero]\n", "[aerodynamics]\nx = 1\n[aero]\n", "[aerodynamics]", "[aero]"),
    ('name = "seed-rlv"', 'name = "seed-rlv"\nclas = "finned"', "[clas]", "class"),
    ("CA_0 = 0.05", "CA_0 = 0.05\nCA_1 = 0.5", "[aero.preflight.CA_1]", "CA_alpha2"),
])
def test_unknown_keys_are_refused_with_the_valid_ones_listed(tmp_path, old, new, key, valid):
    msg = refused(edited(tmp_path, old, new), key, "unknown key", "valid:", valid)
    assert "q_chain_scale" in msg or "estimation" not in key


def test_the_estimation_keys_are_the_smoother_options():
    """[estimation] holds EBMOptions defaults (plus band_hz): the table and the dataclass agree."""
    from aerosid.estimation import EBMOptions

    fields = {f.name for f in dataclasses.fields(EBMOptions)}
    assert set(TABLES["estimation"]) - {"band_hz", "pitch_damping_split", "turbulent_air"} == fields


def test_a_new_table_is_one_entry(tmp_path, monkeypatch):
    """Extending the table: a [preprocess]-like table with its own keys."""
    path = edited(tmp_path, "[aero]\n", "[preprocess.q_rad_s]\nfrozen_max_still_s = 8.0\n[aero]\n")
    load_vehicle(path)  # [preprocess] is checked by its owner (None: any key)
    from aerosid.vehicles import keys

    monkeypatch.setitem(keys.TABLES, "preprocess", {"spike_sigma": keys.pos(100.0)})
    refused(path, "[preprocess.q_rad_s]", "valid: spike_sigma")


def test_database_must_be_a_bounded_regular_file_beside_the_vehicle_file(tmp_path, monkeypatch):
    for name, expected in (("/dev/zero", "outside the vehicle file's folder"),
                           ("../elsewhere/aerodb.csv", "outside the vehicle file's folder"),
                           ("missing.csv", "No such file")):
        d = tmp_path / name.replace("/", "_")
        d.mkdir()
        refused(edited(d, 'database = "aerodb.csv"', f'database = "{name}"'), "[aero.database]", expected)
    # a symbolic link beside the vehicle file to a device is not a regular file: refused, not read
    d = tmp_path / "link"
    d.mkdir()
    path = edited(d, 'database = "aerodb.csv"', 'database = "zero.csv"')
    os.symlink("/dev/zero", d / "zero.csv")
    refused(path, "[aero.database]", "not a regular file")
    # a folder under the database's name
    d = tmp_path / "folder"
    d.mkdir()
    path = edited(d, 'database = "aerodb.csv"', 'database = "db"')
    (d / "db").mkdir()
    refused(path, "[aero.database]", "not a regular file")
    # too large
    monkeypatch.setattr(vehicle_module, "MAX_DATABASE_BYTES", 1000)
    d = tmp_path / "large"
    d.mkdir()
    refused(edited(d, "x_cg_m", "x_cg_m"), "[aero.database]", "more than the 1000")


def test_deeply_nested_toml_is_a_clear_error(tmp_path):
    path = tmp_path / "vehicle.toml"
    path.write_text("x = " + "[" * 5000 + "]" * 5000 + "\n")
    refused(path, "nested deeper")
    path.write_text("".join(f"[{'a.' * 3000}b]\n"))
    with pytest.raises(VehicleError):
        load_vehicle(path)


def test_vehicle_file_that_is_not_a_regular_file_or_too_large(tmp_path):
    big = tmp_path / "big.toml"
    big.write_text("# " + "x" * 1_100_000 + "\n")
    refused(big, "larger than")
