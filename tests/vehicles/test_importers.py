"""aerosid import: the SIDPAC and CSV importers on the shipped Twin Otter files, checked
against the files' own values, SIDPAC's published estimates and physics; the CSV round
trip; bad input named by file and column."""
from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
import scipy.io as sio
from click.testing import CliRunner

from aerosid.io import telemetry_vehicle
from aerosid.vehicles.rigid_body import lever_arm_acceleration
from aerosid.vehicles.vehicle import load_vehicle
from aerosid.vehicles.accel import recover_accel_offset
from aerosid.vehicles.csv_import import import_csv, load_csv_map
from aerosid.vehicles.importers import ImportDataError
from aerosid.vehicles.sidpac import import_sidpac, noise_sigma
from tests.vehicles.twin_otter_csv import CSV_COLUMNS, write_twin_otter_csv

ROOT = Path(__file__).parents[2]
#: shared/ sits beside the checkout (CI, /work/main) or beside its parent (a worktree in /work/wt/NAME)
DATA = next((d for d in (ROOT / "tests" / "data" / "sidpac-twin-otter",  # public NASA data, copied with its README
                         ROOT.parent / "shared" / "data" / "sidpac-twin-otter",
                         ROOT.parents[1] / "shared" / "data" / "sidpac-twin-otter") if d.is_dir()),
            ROOT.parent / "shared" / "data" / "sidpac-twin-otter")
F018, F017 = DATA / "lon_020213f1_018.mat", DATA / "lon_020213f1_017.mat"
EXAMPLE_MAP = ROOT / "aerosid" / "data" / "examples" / "twin-otter-018.map.toml"
G0 = 9.80665
D2R = math.pi / 180
pytestmark = pytest.mark.skipif(not F018.is_file(), reason=f"shared Twin Otter data not found ({DATA})")


@pytest.fixture(scope="module")
def to18():
    return import_sidpac(F018)


@pytest.fixture(scope="module")
def fdata18():
    return sio.loadmat(F018, squeeze_me=True, struct_as_record=False)["fdata"]


@pytest.fixture(scope="module")
def written18(to18, tmp_path_factory):
    out = tmp_path_factory.mktemp("to18")
    return to18.write(out)


def test_sidpac_vehicle_file_holds_the_files_own_values(written18):
    veh = load_vehicle(written18["vehicle"])
    assert veh.vehicle_class == "aircraft" and veh.air_data_source == "vanes"
    assert veh.mass_kg == pytest.approx(4944, abs=1)
    assert (veh.Ixx_kg_m2, veh.Iyy_kg_m2, veh.Izz_kg_m2) == pytest.approx((28353, 32910, 52168), abs=1)
    assert veh.Ixz_kg_m2 == pytest.approx(+1528, abs=1)  # SIDPAC's L = Ixx pdot - Ixz rdot: same sign as aerosid
    assert veh.S_m2 == pytest.approx(39.25, abs=0.005)
    assert veh.chord_m == pytest.approx(1.98, abs=0.001) and veh.span_m == pytest.approx(19.81, abs=0.005)
    assert veh.accel_offset_m == pytest.approx((0.325, -0.421, 0.625), abs=1e-3)
    assert veh.mach_reference == pytest.approx(0.216, abs=0.002)
    assert veh.surfaces == ("elevator", "left_aileron", "right_aileron", "rudder")
    doc = tomllib.loads(written18["vehicle"].read_text())
    assert "estimation" not in doc  # smoother settings are the run's, not the vehicle's
    assert 0 < veh.vane_noise_rad < 0.01 * D2R  # SIDPAC's corrected angles: ~0.003 deg of noise


def test_sidpac_telemetry_is_the_file_in_si(to18, fdata18):
    tel = to18.telemetry
    assert tel["t_s"].iloc[0] == 0.0 and np.diff(tel["t_s"]) == pytest.approx(0.02, abs=1e-9)
    assert tel["V_m_s"].mean() == pytest.approx(71.9, abs=0.05)
    assert tel["rho_kg_m3"].mean() == pytest.approx(1.028, abs=0.0005)
    assert tel["h_m"].mean() == pytest.approx(2196, abs=1)
    np.testing.assert_allclose(tel["q_rad_s"], fdata18[:, 5] * D2R, rtol=1e-14)
    np.testing.assert_allclose(tel["d1_rad"], fdata18[:, 13] * D2R, rtol=1e-14)
    np.testing.assert_allclose(tel["V_m_s"], fdata18[:, 1] * 0.3048, rtol=1e-14)
    np.testing.assert_allclose(tel["alpha_vane_rad"], fdata18[:, 3] * D2R, rtol=1e-14)
    # level flight: a_z ~ -1 g, the same sign as aerosid's specific force along body z (down)
    assert tel["az_m_s2"].mean() == pytest.approx(-G0, rel=0.02)
    # three units converted independently (lbf/ft^2, slug/ft^3, ft/s) agree: qbar = rho V^2 / 2
    np.testing.assert_allclose(tel["qbar_pa"], 0.5 * tel["rho_kg_m3"] * tel["V_m_s"] ** 2, rtol=0.01)


def test_sensor_accelerations_moved_to_the_cg_are_sidpacs(to18, fdata18):
    """Physics: the telemetry holds the sensor's accelerations; minus the lever arm of the
    recovered offset they are SIDPAC's corrected CG accelerations (fdata 11-13)."""
    tel, r = to18.telemetry, load_vehicle_from_text(to18.vehicle_toml).accel_offset_m
    rates = [fdata18[:, i] * D2R for i in (4, 5, 6, 41, 42, 43)]
    lever = lever_arm_acceleration(*rates, r)
    for axis, col in enumerate(("ax_m_s2", "ay_m_s2", "az_m_s2")):
        np.testing.assert_allclose(tel[col] - lever[axis], fdata18[:, 10 + axis] * G0, atol=1e-4)


def load_vehicle_from_text(text: str):
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "vehicle.toml"
        p.write_text(text)
        return load_vehicle(p)


def test_control_signs_reproduce_sidpacs_estimates(to18, fdata18):
    """Known answer: SIDPAC's own Cm (fdata 65) regressed on the imported alpha, q c/(2V) and
    delta_p (through the vehicle's mixing) gives SIDPAC's published equation-error
    estimates; Cl_delta_r comes out positive (aerosid's convention: right wing down)."""
    res = sio.loadmat(DATA / "sidpac_results_018.mat", squeeze_me=True)
    veh = load_vehicle_from_text(to18.vehicle_toml)
    tel = to18.telemetry
    d = [tel[f"d{i}_rad"].to_numpy() for i in range(1, 5)]
    delta_r, delta_p, delta_y = veh.mix(*d)
    V = tel["V_m_s"].to_numpy()
    X = np.column_stack([np.ones(len(V)), tel["alpha_vane_rad"], tel["q_rad_s"] * veh.chord_m / (2 * V), delta_p])
    coef, *_ = np.linalg.lstsq(X, fdata18[:, 64], rcond=None)
    cm_alpha, cm_q, cm_de = res["p0"][3:6]
    assert coef[1:] == pytest.approx([cm_alpha, cm_q, cm_de], rel=1e-3)
    b = veh.span_m
    X = np.column_stack([np.ones(len(V)), tel["beta_vane_rad"], tel["p_rad_s"] * b / (2 * V),
                         tel["r_rad_s"] * b / (2 * V), delta_r, delta_y])
    coef, *_ = np.linalg.lstsq(X, fdata18[:, 63], rcond=None)
    assert coef[4] > 0.1  # Cl_delta_r ~ +0.14: positive delta_r rolls the right wing down


def test_the_two_manoeuvres_give_the_same_sensor_position():
    to17 = import_sidpac(F017)
    veh = load_vehicle_from_text(to17.vehicle_toml)
    assert veh.accel_offset_m == pytest.approx((0.325, -0.421, 0.625), abs=5e-3)  # 017: z 0.6223 m
    assert veh.mass_kg == pytest.approx(4957, abs=1)  # flown earlier: more fuel


def test_recover_accel_offset_known_answer_and_refusal():
    rng = np.random.default_rng(0)
    n = 300
    w = [rng.normal(0, 0.2, n) for _ in range(6)]
    r_true, bias = (0.5, -0.2, 0.3), np.array([0.05, 0.0, -0.03])
    a_cg = rng.normal(0, 1, (n, 3))
    a_sensor = a_cg + np.column_stack(lever_arm_acceleration(*w, r_true)) + bias
    fit = recover_accel_offset(*w, a_sensor, a_cg)
    assert fit.trusted and fit.offset_m == pytest.approx(r_true, abs=1e-9)
    assert fit.bias_m_s2 == pytest.approx(bias, abs=1e-9)
    unrelated = recover_accel_offset(*w, a_sensor, rng.normal(0, 1, (n, 3)))
    assert not unrelated.trusted and "residual" in unrelated.reason


def test_noise_sigma_of_white_noise_on_a_smooth_signal():
    rng = np.random.default_rng(1)
    t = np.linspace(0, 8, 401)
    x = 0.01 * np.sin(2 * np.pi * 0.7 * t) + rng.normal(0, 1e-4, t.size)
    assert noise_sigma(x) == pytest.approx(1e-4, rel=0.15)


def test_written_telemetry_names_its_vehicle_and_passes_the_run_preflight(written18, to18):
    from aerosid.cli.run import _preflight

    tel = written18["telemetry"]
    assert telemetry_vehicle(tel) == str(written18["vehicle"].resolve())
    meta = {k.decode(): v.decode() for k, v in pq.read_schema(tel).metadata.items() if k.startswith(b"aerosid")}
    assert meta["aerosid.vehicle_file"] == "vehicle.toml"
    conv = {c["column"]: c for c in json.loads(meta["aerosid.conversions"])}
    assert conv["ax_m_s2"]["factor"] == pytest.approx(G0, rel=1e-12) and conv["ax_m_s2"]["from_unit"] == "g"
    assert conv["V_m_s"]["factor"] == pytest.approx(0.3048, rel=1e-12)
    assert conv["d2_rad"]["sign"] == -1.0
    assert float(meta["aerosid.time_origin_s"]) == pytest.approx(53550.06)
    _preflight(tel, telemetry_vehicle(tel), None)  # raises on anything aerosid run would refuse


def test_csv_round_trip_reproduces_the_sidpac_import(to18, tmp_path):
    csv = write_twin_otter_csv(F018, tmp_path / "to18.csv")
    head = pd.read_csv(csv, nrows=1).columns
    assert {"tas_kt", "alt_ft", "az_g", "q_dps"} <= set(head)
    imp = import_csv(csv, EXAMPLE_MAP)
    a = to18.telemetry.sort_index(axis=1)
    b = imp.telemetry.sort_index(axis=1)
    assert list(a.columns) == list(b.columns)
    pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=1e-12, atol=1e-12)
    kt = {c.column: c for c in imp.conversions}["V_m_s"]
    assert kt.from_unit == "kt" and kt.factor == pytest.approx(1852 / 3600, rel=1e-12)
    paths = imp.write(tmp_path / "out")
    veh_csv, veh_mat = load_vehicle(paths["vehicle"]), load_vehicle_from_text(to18.vehicle_toml)
    for key in ("mass_kg", "Ixx_kg_m2", "Iyy_kg_m2", "Izz_kg_m2", "Ixz_kg_m2", "S_m2", "chord_m", "span_m",
                "mach_reference", "vane_noise_rad"):
        assert getattr(veh_csv, key) == pytest.approx(getattr(veh_mat, key), rel=1e-6), key
    assert veh_csv.accel_offset_m == pytest.approx(veh_mat.accel_offset_m, abs=1e-6)
    assert veh_csv.mixing == veh_mat.mixing
    assert telemetry_vehicle(paths["telemetry"]) == str(paths["vehicle"].resolve())


def _map_text(drop: str | None = None, replace: tuple[str, str] | None = None) -> str:
    lines = EXAMPLE_MAP.read_text().splitlines()
    if drop:
        lines = [ln for ln in lines if not ln.startswith(f"{drop} =")]
    text = "\n".join(lines) + "\n"
    if replace:
        assert replace[0] in text
        text = text.replace(*replace)
    return text


@pytest.mark.parametrize("edit, words", [
    ({"drop": "q_rad_s"}, ["map.toml", "q_rad_s", "no entry"]),
    ({"replace": ('unit = "deg/s" }\nr_rad_s', 'unit = "blargs" }\nr_rad_s')}, ["q_rad_s", "blargs", "not a unit"]),
    ({"replace": ('unit = "deg/s" }\nr_rad_s', 'unit = "ft" }\nr_rad_s')}, ["q_rad_s", "'ft'", "rad/s"]),
    ({"replace": ('{ column = "q_dps", unit = "deg/s" }', '{ column = "q_dps", units = "deg/s" }')},
     ["q_rad_s", "column ="]),
    ({"replace": ("alpha_vane_rad = {", "alpha_vain_rad = {")}, ["alpha_vain_rad", "not a raw telemetry column"]),
    ({"replace": ('[vehicle]\nname = "twin-otter"', '[vehicle_x]\nname = "twin-otter"')}, ["unknown top-level"]),
])
def test_bad_map_is_named(tmp_path, edit, words):
    bad = tmp_path / "map.toml"
    bad.write_text(_map_text(**edit))
    with pytest.raises(ImportDataError) as err:
        load_csv_map(bad)
    for word in words:
        assert word in str(err.value), str(err.value)


def test_map_without_vehicle_and_copy_of_a_vehicle_file(tmp_path, written18):
    text = _map_text()
    no_vehicle = text[:text.index("[vehicle]")]
    (tmp_path / "a.toml").write_text(no_vehicle)
    with pytest.raises(ImportDataError, match="no vehicle"):
        load_csv_map(tmp_path / "a.toml")
    (tmp_path / "v.toml").write_text(written18["vehicle"].read_text())
    (tmp_path / "b.toml").write_text('vehicle = "v.toml"\n' + no_vehicle)
    cmap = load_csv_map(tmp_path / "b.toml")
    assert cmap.vehicle_origin == str(tmp_path / "v.toml")
    assert "accel_offset_m = [0.3251304, -0.4210393, 0.6248924]" in cmap.vehicle_toml  # comments and all
    (tmp_path / "c.toml").write_text('vehicle = "nowhere.toml"\n' + no_vehicle)
    with pytest.raises(ImportDataError, match="nowhere.toml"):
        load_csv_map(tmp_path / "c.toml")


def test_bad_csv_is_named_by_file_column_and_row(tmp_path):
    csv = write_twin_otter_csv(F018, tmp_path / "to18.csv")
    frame = pd.read_csv(csv)
    frame.drop(columns=["q_dps"]).to_csv(tmp_path / "noq.csv", index=False)
    with pytest.raises(ImportDataError) as err:
        import_csv(tmp_path / "noq.csv", EXAMPLE_MAP)
    assert "noq.csv" in str(err.value) and "'q_dps'" in str(err.value) and "q_rad_s" in str(err.value)
    text = frame.astype(object)
    text.loc[7, "az_g"] = "n/a?"
    text.loc[9, "alt_ft"] = ""  # an empty cell is a dropout, not an error
    text.to_csv(tmp_path / "text.csv", index=False)
    with pytest.raises(ImportDataError) as err:
        import_csv(tmp_path / "text.csv", EXAMPLE_MAP)
    assert "'az_g'" in str(err.value) and "[7]" in str(err.value)
    text.loc[7, "az_g"] = frame.loc[7, "az_g"]
    text.to_csv(tmp_path / "gap.csv", index=False)
    assert np.isnan(import_csv(tmp_path / "gap.csv", EXAMPLE_MAP).telemetry["h_m"].iloc[9])


def test_clock_time_stamps_are_read_as_seconds(tmp_path):
    """A data system's time column as times of day, IRIG day-of-year times or ISO dates: seconds
    since midnight / since 1970 (UTC), the same record as the numeric one."""
    csv = write_twin_otter_csv(F018, tmp_path / "to18.csv")
    frame = pd.read_csv(csv)
    ref = import_csv(csv, EXAMPLE_MAP).telemetry["t_s"].to_numpy()
    ns = np.round(frame["time"].to_numpy() * 1e9).astype("int64")  # seconds since midnight, as written
    stamps = {
        "tod": pd.to_datetime(ns, unit="ns").strftime("%H:%M:%S.%f"),
        "irig": pd.to_datetime(ns, unit="ns").strftime("044:%H:%M:%S.%f"),  # 13 Feb = day 44
        "iso": pd.to_datetime(ns + np.int64(1013558400) * 10**9, unit="ns").strftime("%Y-%m-%dT%H:%M:%S.%fZ"),
    }
    offset = {"tod": 0.0, "irig": 43 * 86400.0, "iso": 1013558400.0}  # 2002-02-13 00:00 UTC
    for kind, text in stamps.items():
        frame.assign(time=text).to_csv(tmp_path / f"{kind}.csv", index=False)
        t = import_csv(tmp_path / f"{kind}.csv", EXAMPLE_MAP).telemetry["t_s"].to_numpy()
        np.testing.assert_allclose(t - offset[kind], ref, rtol=0, atol=2e-6, err_msg=kind)
    bad = tmp_path / "s_unit.toml"
    bad.write_text(_map_text(replace=('t_s = { column = "time", unit = "s" }', 't_s = { column = "time", unit = "ms" }')))
    with pytest.raises(ImportDataError, match="times of day.*must be"):
        import_csv(tmp_path / "tod.csv", bad)


def test_a_csv_with_decimal_commas_reads_as_the_same_record(tmp_path):
    csv = write_twin_otter_csv(F018, tmp_path / "to18.csv")
    ref = import_csv(csv, EXAMPLE_MAP).telemetry
    pd.read_csv(csv).to_csv(tmp_path / "eu.csv", index=False, sep=";", decimal=",")
    eu_map = tmp_path / "eu.toml"
    eu_map.write_text(_map_text(replace=('delimiter = ","', 'delimiter = ";"\ndecimal = ","')))
    pd.testing.assert_frame_equal(import_csv(tmp_path / "eu.csv", eu_map).telemetry, ref)
    bad = tmp_path / "bad.toml"
    bad.write_text(_map_text(replace=('delimiter = ","', 'delimiter = ","\ndecimal = ","')))
    with pytest.raises(ImportDataError, match="another delimiter"):
        load_csv_map(bad)


def test_bad_mat_files_are_named(tmp_path, fdata18):
    sio.savemat(tmp_path / "nofdata.mat", {"x": np.zeros(3)})
    with pytest.raises(ImportDataError, match=r"nofdata\.mat.*'fdata'"):
        import_sidpac(tmp_path / "nofdata.mat")
    no_mass = fdata18.copy()
    no_mass[:, 47] = 0.0
    sio.savemat(tmp_path / "nomass.mat", {"fdata": no_mass, "sarea": 422.483473, "bspan": 64.993436,
                                          "cbar": 6.496063})
    with pytest.raises(ImportDataError, match=r"nomass\.mat: column 'fdata:48': mass"):
        import_sidpac(tmp_path / "nomass.mat")
    (tmp_path / "text.mat").write_text("not matlab")
    with pytest.raises(ImportDataError, match="text.mat"):
        import_sidpac(tmp_path / "text.mat")


def test_fdata_alone_imports_with_standard_units_and_cg_accelerations(tmp_path, fdata18):
    """No fds labels, no fdatao, no measured accelerations: SIDPAC's standard units, the CG
    accelerations and offset 0, each said in the notes."""
    f = fdata18.copy()
    f[:, 52:55] = 0.0
    sio.savemat(tmp_path / "bare.mat", {"fdata": f})
    imp = import_sidpac(tmp_path / "bare.mat")
    np.testing.assert_allclose(imp.telemetry["az_m_s2"], f[:, 12] * G0, rtol=1e-14)
    veh = load_vehicle_from_text(imp.vehicle_toml)
    assert veh.accel_offset_m == (0.0, 0.0, 0.0) and veh.S_m2 == pytest.approx(39.25, abs=0.005)
    assert any("CG" in n for n in imp.notes)


def test_cli_import_sidpac_and_errors(tmp_path):
    from aerosid.cli import main

    runner = CliRunner()
    out = runner.invoke(main, ["import", "sidpac", str(F017), "--out", str(tmp_path / "to17")])
    assert out.exit_code == 0, out.output
    assert (tmp_path / "to17" / "telemetry.parquet").is_file() and "wrote" in out.output
    (tmp_path / "bad.mat").write_text("nope")
    out = runner.invoke(main, ["import", "sidpac", str(tmp_path / "bad.mat"), "--out", str(tmp_path / "x")])
    assert out.exit_code == 1 and "bad.mat" in out.output and "Traceback" not in out.output
    (tmp_path / "m.toml").write_text(_map_text(drop="h_m"))
    out = runner.invoke(main, ["import", "csv", str(F017), "--map", str(tmp_path / "m.toml"), "--out",
                               str(tmp_path / "y")])
    assert out.exit_code == 1 and "h_m" in out.output and not (tmp_path / "y").exists()


def test_csv_columns_of_the_helper_are_all_mapped():
    cmap = load_csv_map(EXAMPLE_MAP)
    assert {c.column for c in cmap.columns} == set(CSV_COLUMNS)


def test_a_parquet_table_with_its_own_names_units_and_timestamps_reads_as_the_same_record(tmp_path):
    """A data system's Parquet (the CSV's columns, units and a datetime time column) imports with
    the same map: the record of the CSV, times in seconds since 1970 UTC."""
    csv = write_twin_otter_csv(F018, tmp_path / "to18.csv")
    ref = import_csv(csv, EXAMPLE_MAP).telemetry
    frame = pd.read_csv(csv)
    frame.to_parquet(tmp_path / "to18.parquet", index=False)  # numbers as the CSV's
    pd.testing.assert_frame_equal(import_csv(tmp_path / "to18.parquet", EXAMPLE_MAP).telemetry, ref)
    ns = np.round(frame["time"].to_numpy() * 1e9).astype("int64") + np.int64(1013558400) * 10**9
    frame.assign(time=pd.to_datetime(ns, unit="ns", utc=True)).to_parquet(tmp_path / "stamped.parquet", index=False)
    got = import_csv(tmp_path / "stamped.parquet", EXAMPLE_MAP).telemetry
    np.testing.assert_allclose(got["t_s"].to_numpy() - 1013558400.0, ref["t_s"].to_numpy(), rtol=0, atol=2e-6)
    pd.testing.assert_frame_equal(got.drop(columns="t_s"), ref.drop(columns="t_s"))
    gap = pd.Series(pd.to_datetime(ns, unit="ns", utc=True))
    gap.iloc[5] = pd.NaT
    frame.assign(time=gap).to_parquet(tmp_path / "nat.parquet", index=False)
    with pytest.raises(ImportDataError) as err:  # a missing stamp is named, not a conversion error
        import_csv(tmp_path / "nat.parquet", EXAMPLE_MAP)
    assert "'time'" in str(err.value) and "5" in str(err.value), str(err.value)
    (tmp_path / "broken.parquet").write_bytes(b"PAR1 not really")
    with pytest.raises(ImportDataError, match="not a readable Parquet"):
        import_csv(tmp_path / "broken.parquet", EXAMPLE_MAP)


def test_a_calibrated_airspeed_column_is_converted_or_must_say_what_it_holds(to18, tmp_path):
    """A data system's KCAS mapped to V_m_s: with airspeed = "calibrated" the import gives the true
    airspeed (the SIDPAC import's, to 1e-6, the day's temperature from the measured density);
    without the key a header that reads as a calibrated or indicated airspeed is refused (taken for
    the true one it made every coefficient x1.2 at the Twin Otter's 2200 m); the key is V_m_s's
    only and its kinds are named."""
    from aerosid.vehicles.airspeed import calibrated_from_true_m_s
    from aerosid.vehicles.atmosphere import R_AIR_J_KG_K, pressure_pa

    csv = write_twin_otter_csv(F018, tmp_path / "to18.csv")
    frame = pd.read_csv(csv)
    h_m = frame["alt_ft"].to_numpy() * 0.3048
    T_day = pressure_pa(h_m) / (R_AIR_J_KG_K * frame["rho_slug_ft3"].to_numpy() * 515.378818)
    frame["KCAS"] = calibrated_from_true_m_s(frame["tas_kt"].to_numpy() * 1852 / 3600, h_m,
                                             T_static_K=T_day) / (1852 / 3600)
    frame.drop(columns=["tas_kt"]).to_csv(tmp_path / "cas.csv", index=False)
    plain = _map_text(replace=('{ column = "tas_kt", unit = "kt" }', '{ column = "KCAS", unit = "kt" }'))
    (tmp_path / "plain.toml").write_text(plain)
    with pytest.raises(ImportDataError) as err:
        load_csv_map(tmp_path / "plain.toml")
    assert all(w in str(err.value) for w in ("plain.toml", "V_m_s", "'KCAS'", 'airspeed = "calibrated"')), err.value
    (tmp_path / "cas.toml").write_text(plain.replace('unit = "kt" }', 'unit = "kt", airspeed = "calibrated" }', 1))
    imp = import_csv(tmp_path / "cas.csv", tmp_path / "cas.toml")
    np.testing.assert_allclose(imp.telemetry["V_m_s"], to18.telemetry["V_m_s"], rtol=1e-6)
    assert any("calibrated airspeed converted" in n and "rho_kg_m3" in n for n in imp.notes)
    assert float(np.median(frame["KCAS"] / frame["tas_kt"])) < 0.92  # the difference the key makes
    (tmp_path / "bad.toml").write_text(plain.replace('unit = "kt" }', 'unit = "kt", airspeed = "knots" }', 1))
    with pytest.raises(ImportDataError, match="airspeed must be one of true, calibrated, indicated, equivalent, "
                                              "got 'knots'"):
        load_csv_map(tmp_path / "bad.toml")
    (tmp_path / "q.toml").write_text(_map_text(replace=('{ column = "q_dps", unit = "deg/s" }',
                                                        '{ column = "q_dps", unit = "deg/s", airspeed = "true" }')))
    with pytest.raises(ImportDataError, match="q_rad_s: airspeed is a key of V_m_s only"):
        load_csv_map(tmp_path / "q.toml")


def test_an_impact_pressure_column_is_converted_or_must_say_what_it_holds(to18, tmp_path):
    """A pitot-static system's impact pressure q_c mapped to qbar_pa: with pressure = "impact" the
    import gives the dynamic pressure (the SIDPAC file's, to 1e-6, through the US-1976 pressure at
    its altitude); a header that reads as one (qc_psf) is refused without the key."""
    from aerosid.vehicles.airspeed import _qc_over_p
    from aerosid.vehicles.atmosphere import pressure_pa

    csv = write_twin_otter_csv(F018, tmp_path / "to18.csv")
    frame = pd.read_csv(csv)
    p = pressure_pa(frame["alt_ft"].to_numpy() * 0.3048) / 47.880259  # psf
    mach = np.sqrt(frame["qbar_psf"].to_numpy() / (0.7 * p))
    frame["qc_psf"] = p * _qc_over_p(mach)
    frame.drop(columns=["qbar_psf"]).to_csv(tmp_path / "qc.csv", index=False)
    plain = _map_text(replace=('{ column = "qbar_psf"', '{ column = "qc_psf"'))
    (tmp_path / "plain.toml").write_text(plain)
    with pytest.raises(ImportDataError) as err:
        load_csv_map(tmp_path / "plain.toml")
    assert all(w in str(err.value) for w in ("qbar_pa", "'qc_psf'", 'pressure = "impact"')), err.value
    text = plain.replace('{ column = "qc_psf", unit = "lbf/ft^2" }', '{ column = "qc_psf", unit = "lbf/ft^2", '
                                                                    'pressure = "impact" }')
    assert text != plain
    (tmp_path / "qc.toml").write_text(text)
    imp = import_csv(tmp_path / "qc.csv", tmp_path / "qc.toml")
    np.testing.assert_allclose(imp.telemetry["qbar_pa"], to18.telemetry["qbar_pa"], rtol=1e-6)
    assert any("impact pressure converted" in n for n in imp.notes)
    (tmp_path / "q.toml").write_text(_map_text(replace=('{ column = "q_dps", unit = "deg/s" }',
                                                        '{ column = "q_dps", unit = "deg/s", pressure = "impact" }')))
    with pytest.raises(ImportDataError, match="q_rad_s: pressure is a key of qbar_pa only"):
        load_csv_map(tmp_path / "q.toml")
