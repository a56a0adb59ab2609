"""Bad input, round two (docs/bad-input.md, rows U1-U16): unit mistakes, vehicle files,
model terms that used to end in a traceback or a misleading error, flights too short or
constant, Prefect that does not start.  Most are answered by `aerosid run`'s pre-flight
check, so the tests call the CLI through click's CliRunner and need no Prefect server."""
from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from aerosid.cli import main
from aerosid.diagnosis.synthetic import MEASURED_NOISE, flight_data_from_truth
from aerosid.identification.identify import format_table, identify
from aerosid.modelling.models import ModelSpecError, load_models
from aerosid.vehicles.vehicle import load_vehicle
from tests.test_bad_input import flight, run_fails, run_fails_fast, vehicle_file, write  # noqa: F401 (fixture)

ROOT = Path(__file__).resolve().parents[1]
DEG = math.pi / 180


def cli(*args: str):
    return CliRunner().invoke(main, list(args))


def clean_failure(result, *expected: str) -> str:
    text = result.output
    assert result.exit_code == 1, text
    assert isinstance(result.exception, SystemExit), f"unexplained exception {result.exception!r}\n{text}"
    assert "Traceback" not in text
    for e in expected:
        assert e in text, f"{e!r} not in:\n{text}"
    return text


# --------------------------------------------------------------------------- U1-U3 unit mistakes
def test_u1_pitch_rate_in_degrees_per_second(flight, tmp_path):
    _, raw = flight
    bad = write(raw.assign(q_rad_s=raw["q_rad_s"] / DEG), tmp_path / "q_deg_s.parquet")
    run_fails_fast([str(bad), "--vehicle", "seed-rlv"], tmp_path / "run", str(bad), "column 'q_rad_s'", "values look like deg/s, not rad/s",
                   "multiply by 0.0174533", "[plausibility]")


def test_u2_altitude_in_kilometres_even_with_a_wide_mach_window(flight, tmp_path):
    _, raw = flight
    bad = write(raw.assign(h_m=raw["h_m"] / 1000.0), tmp_path / "h_km.parquet")
    run_fails_fast([str(bad), "--vehicle", "seed-rlv", "--mach-half-width", "2"], tmp_path / "run", str(bad), "column 'h_m'",
                   "values look like km, not m", "dynamic pressure")


@pytest.mark.parametrize("columns, factor, unit", [
    (["h_m"], 1 / 0.3048, "ft"),
    (["ax_m_s2", "ay_m_s2", "az_m_s2"], 1 / 9.80665, "g"),
    (["V_m_s"], 1 / 0.514444, "kt"),
    (["r_rad_s"], 1 / DEG, "deg/s"),
])
def test_u3_other_unit_mistakes(flight, tmp_path, columns, factor, unit):
    _, raw = flight
    bad = write(raw.assign(**{c: raw[c] * factor for c in columns}), tmp_path / "units.parquet")
    run_fails_fast([str(bad), "--vehicle", "seed-rlv"], tmp_path / "run", str(bad), f"column {columns[0]!r}", f"values look like {unit}")


@pytest.fixture(scope="module")
def synthetic_fd(reference_flight):
    """Flight data built from the reference flight's truth plus measured-size noise (fast)."""
    return flight_data_from_truth(reference_flight.truth, MEASURED_NOISE, seed=0)


def test_u4_an_estimate_far_from_its_preflight_value_is_reported_loudly(synthetic_fd):
    """The pitch gyro read x10 (a unit slip the envelope misses) makes the pitching moment
    x10: Cm_* land beyond the vehicle's preflight_factor and the table says so."""
    veh = load_vehicle("seed-rlv")
    good = identify(synthetic_fd, veh).table()
    assert (good["preflight_warning"] == "").all(), good.loc[good["preflight_warning"] != "", "preflight_warning"]
    bad = identify(synthetic_fd.assign(Cm=synthetic_fd["Cm"] * 10.0), veh).table().set_index("coefficient")
    ratio = good.set_index("coefficient")["preflight_ratio"]
    for name in ("Cm_alpha", "Cm_delta_p"):
        assert "x its preflight value" in bad.loc[name, "preflight_warning"]
        assert bad.loc[name, "preflight_ratio"] == pytest.approx(10.0 * ratio[name], rel=1e-6)
    text = format_table(bad.reset_index())
    assert "!! WARNING Cm_delta_p: estimate" in text and "[plausibility] preflight_factor" in text


# --------------------------------------------------------------------------- U5-U7 vehicle files
def test_u5_vehicle_database_dev_zero_is_refused_at_once(flight, tmp_path):
    veh = vehicle_file(tmp_path, 'database = "aerodb.csv"', 'database = "/dev/zero"')
    run_fails_fast([str(flight[0]), "--vehicle", str(veh)], tmp_path / "run", str(veh), "[aero.database]",
                   "outside the vehicle file's folder")


@pytest.mark.parametrize("old, new, expected", [
    ("x_cg_m = 1.675", "x_cg_m = nan", "[reference.x_cg_m] must be a finite number, got nan"),
    ("mach_reference = 12.4", "mach_reference = inf", "[aero.mach_reference] must be a finite number, got inf"),
    ("accel_offset_m = [0.85, 0.02, -0.03]", "accel_offset_m = [1e300, 0.0, 0.0]",
     "[sensors.accel_offset_m[0]] 1e+300 is outside the range [-100, 100]"),
    ("mixing = [[1.0, 1.0, 1.0, 1.0], [0.0, -1.0, 0.0, 1.0], [-1.0, 0.0, 1.0, 0.0]]",
     "mixing = [[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]]", "[controls.mixing] row 1"),
])
def test_u6_vehicle_numbers_not_finite_or_out_of_range(flight, tmp_path, old, new, expected):
    veh = vehicle_file(tmp_path, old, new)
    run_fails_fast([str(flight[0]), "--vehicle", str(veh)], tmp_path / "run", str(veh), expected)


@pytest.mark.parametrize("old, new, expected", [
    ("[aero]\n", "[estimation]\nsmoother_gain = 2.0\n\n[aero]\n",
     "[estimation.smoother_gain] unknown key 'smoother_gain' in [estimation]; valid: f_max_hz"),
    ("[reference]\n", "[reference]\nS_ft2 = 8.45\n", "[reference.S_ft2] unknown key 'S_ft2' in [reference]; valid: S_m2"),
])
def test_u7_vehicle_unknown_keys_are_refused_listing_the_valid_ones(flight, tmp_path, old, new, expected):
    veh = vehicle_file(tmp_path, old, new)
    run_fails_fast([str(flight[0]), "--vehicle", str(veh)], tmp_path / "run", str(veh), expected)


# --------------------------------------------------------------------------- U8-U12 model terms
def test_u8_deeply_nested_toml_vehicle_and_spec(flight, tmp_path):
    nested = "x = " + "[" * 3000 + "]" * 3000 + "\n"
    veh = tmp_path / "vehicle.toml"
    veh.write_text(nested)
    run_fails_fast([str(flight[0]), "--vehicle", str(veh)], tmp_path / "run", str(veh), "nested deeper")
    spec = tmp_path / "model.toml"
    spec.write_text(nested)
    run_fails_fast([str(flight[0]), "--model", str(spec)], tmp_path / "run", str(spec), "nested deeper")


@pytest.fixture
def run_dir(tmp_path, synthetic_fd):
    d = tmp_path / "run"
    d.mkdir()
    synthetic_fd.to_parquet(d / "flight_data.parquet", index=False)
    return d


@pytest.mark.parametrize("term, expected", [
    ("1" * 401 + " * alpha", "has 401 digits: numbers in a term must lie within"),
    ("9**9**9", "the constant '9 ** 9 ** 9' = inf"),
    ("alpha/0", "division by zero"),
    ("alpha * 1e999", "outside ±1e+12"),
    ("-" * 40 + "alpha", "nested deeper than 32 levels"),
])
def test_u9_u10_terms_that_overflowed_or_misled_are_refused_before_the_run(flight, tmp_path, run_dir, term,
                                                                         expected):
    spec = tmp_path / "model.toml"
    spec.write_text(f'[Cm]\nterms = ["Cm_0 = 1", "Cm_x = {term}"]\n')
    run_fails_fast([str(flight[0]), "--model", str(spec)], tmp_path / "out", str(spec), "[Cm] Cm_x", expected)
    clean_failure(cli("fit", str(run_dir), "--model", str(spec)), "[Cm] Cm_x", expected)


def test_u10_a_term_never_finite_names_the_term_and_the_reason(run_dir, tmp_path):
    spec = tmp_path / "model.toml"
    spec.write_text('[Cm]\nterms = ["Cm_0 = 1", "Cm_alpha = alpha", "Cm_nan = sqrt(-1 - abs(alpha))"]\n')
    clean_failure(cli("fit", str(run_dir), "--model", str(spec)),
                  "[Cm] term Cm_nan = sqrt(-1 - abs(alpha)): NaN at every one of the", "sqrt of a negative value",
                  "fix the term or remove it")


def test_u10_a_term_over_a_signal_without_a_finite_value_names_term_and_signal(synthetic_fd):
    from aerosid.modelling.models import ChannelModel, parse_term, vehicle_signals

    veh = load_vehicle("seed-rlv")
    signals = vehicle_signals(synthetic_fd, veh)
    signals["beta"] = np.full(len(synthetic_fd), np.nan)  # e.g. a channel all NaN in the flight data
    model = ChannelModel("Cn", (parse_term("Cn_0 = 1", "Cn"), parse_term("Cn_beta = beta", "Cn")))
    with pytest.raises(ModelSpecError, match="term Cn_beta = beta: its signal 'beta' has no finite value"):
        model.design(signals)
    signals["beta"] = np.where(np.arange(len(synthetic_fd)) < 100, np.nan, 0.01)
    _, notes = model.design(signals)
    assert notes == (f"term Cn_beta = beta: signal 'beta' is not finite at 100 of {len(synthetic_fd)} samples: "
                     "those samples are left out of the Cn fit",)


def test_u11_aerosid_fit_prints_the_samples_a_term_drops(run_dir, tmp_path):
    spec = tmp_path / "model.toml"
    spec.write_text('[Cm]\nterms = ["Cm_0 = 1", "Cm_alpha = alpha", "Cm_delta_p = delta_p/2", "Cm_log = log(alpha)"]\n')
    result = cli("fit", str(run_dir), "--model", str(spec), "--mach-half-width", "1")
    assert result.exit_code == 0, result.output
    assert "warning: term Cm_log = log(alpha) is NaN at" in result.output and "left out of the Cm fit" in result.output


def test_u11_a_term_that_drops_samples_says_so(synthetic_fd, tmp_path):
    veh = load_vehicle("seed-rlv")
    spec = tmp_path / "model.toml"
    spec.write_text('[Cm]\nterms = ["Cm_0 = 1", "Cm_alpha = alpha", "Cm_delta_p = delta_p/2", '
                    '"Cm_log = log(alpha)"]\n')
    models = load_models(spec)
    n_bad = int((synthetic_fd["alpha_rad"] <= 0).sum())
    assert n_bad > 0
    ident = identify(synthetic_fd, veh, models, mach_half_width=None)
    warning = next(w for w in ident.fits["Cm"].warnings if "Cm_log" in w)
    assert warning.startswith("term Cm_log = log(alpha) is NaN") and f" at {n_bad} of {len(synthetic_fd)} samples" in warning
    assert "log of a value <= 0" in warning and "left out of the Cm fit" in warning
    assert ident.fits["Cm"].n_dropped == n_bad
    assert "Cm_log = log(alpha) is NaN" in ident.summary()
    from aerosid.diagnosis import diagnose  # the diagnosis needs every sample: it refuses, naming the term

    with pytest.raises(ValueError, match=f"Cm: {n_bad} samples with non-finite values .*term Cm_log = log"):
        diagnose(synthetic_fd, veh, models, mach_half_width=None)


def test_u12_too_many_terms_are_refused(flight, tmp_path):
    spec = tmp_path / "model.toml"
    terms = ", ".join(f'"Cm_{i} = alpha**{i % 5 + 1} * {i + 1}"' for i in range(2000))
    spec.write_text(f"[Cm]\nterms = [{terms}]\n")
    run_fails_fast([str(flight[0]), "--model", str(spec)], tmp_path / "run", str(spec),
                   "[Cm] 2000 terms: at most 40 per channel")
    with pytest.raises(ModelSpecError, match="at most"):
        load_models(spec)


# --------------------------------------------------------------------------- U13 too short, constant
def test_u13_a_three_row_file_and_an_all_constant_file(flight, tmp_path):
    _, raw = flight
    short = write(raw.iloc[:3], tmp_path / "three_rows.parquet")
    run_fails_fast([str(short), "--vehicle", "seed-rlv"], tmp_path / "run", str(short), "column 't_s'", "the flight spans 0.02 s (3 rows)",
                   "min_segment_s = 5 s")
    const = raw.copy()
    for c in const.columns[1:]:
        const[c] = float(np.nanmedian(raw[c]))
    bad = write(const, tmp_path / "constant.parquet")
    run_fails_fast([str(bad), "--vehicle", "seed-rlv"], tmp_path / "run", str(bad), "column 'ax_m_s2'", "a constant inertial channel",
                   "dead or frozen sensor")


def test_u13_no_segment_names_the_reason(flight, tmp_path):
    """A 9 s flight with a 2 s telemetry gap passes the pre-flight check, but no piece
    between the gaps is 5 s long: planning fails saying why (it used to end in 'no
    segment could be processed (no segment)'); so do windows outside the flight."""
    from aerosid.io import write_parquet_atomic
    from aerosid.preprocess import preprocess
    from tasks.stages import plan_segments_task

    _, raw = flight
    t = raw["t_s"]
    short = raw[(t < 9.0) & ~((t > 3.5) & (t < 5.5))].reset_index(drop=True)
    res = preprocess(short, source="gap.parquet")
    path = tmp_path / "preprocessed.parquet"
    write_parquet_atomic(res.frame, path, metadata=res.metadata())
    plan = plan_segments_task.fn(str(path), None, 5.0)
    assert plan["segments"] == [] and plan["refusal"]
    msg = plan["refusal"]  # the limits that refused the data are named, with how to change them
    assert "min_segment_s" in msg and "5" in msg
    far = plan_segments_task.fn(str(path), [[100.0, 200.0]], 5.0)
    assert far["segments"] == [] and far["refusal"]


# --------------------------------------------------------------------------- U14 no traceback from any command
def test_u14_an_unexpected_error_in_any_command_is_one_line(run_dir, monkeypatch):
    import aerosid.modelling.versions

    def broken(*args, **kwargs):
        raise KeyError("something nobody expected")

    monkeypatch.setattr(aerosid.modelling.versions, "history", broken)
    text = clean_failure(cli("history", str(run_dir)), "Error: KeyError: 'something nobody expected'",
                         "AEROSID_TRACEBACK=1")
    assert len(text.strip().splitlines()) == 1
    monkeypatch.setenv("AEROSID_TRACEBACK", "1")
    assert isinstance(cli("history", str(run_dir)).exception, KeyError)


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _subprocess_env(home: Path, **extra) -> dict:
    """A hermetic environment; PREFECT_SERVER_API_PORT points at a free port so that a
    Prefect server someone runs on this machine is not reused."""
    env = {**os.environ, "PREFECT_HOME": str(home), "PREFECT_SERVER_ANALYTICS_ENABLED": "false",
           "PYTHONPATH": str(ROOT), "PREFECT_SERVER_API_PORT": str(_free_port()), **extra}
    env.pop("PREFECT_API_URL", None)
    env.pop("AEROSID_TRACEBACK", None)
    return env


@pytest.mark.prefect
def test_u14_a_failed_flight_ends_in_one_line_and_the_server_output_goes_to_its_log(flight, tmp_path):
    """The whole CLI in its own process, as a user runs it: a flight that fails inside the
    flow (time in milliseconds) ends with the one `Error:` line; the ephemeral server's
    own output (its shutdown tracebacks) goes to PREFECT_HOME/aerosid-server.log."""
    _, raw = flight
    bad = write(raw.assign(t_s=raw["t_s"] * 1000.0), tmp_path / "milliseconds.parquet")
    home = tmp_path / "prefect-home"
    proc = subprocess.run([sys.executable, "-m", "aerosid.cli", "run", str(bad), "--vehicle", "seed-rlv", "--out", str(tmp_path / "run")],
                          env=_subprocess_env(home), capture_output=True, text=True, timeout=900)
    text = proc.stdout + proc.stderr
    assert proc.returncode == 1, text
    assert "Traceback" not in text and "is t_s in seconds?" in text
    assert [line for line in text.splitlines() if line.startswith("Error:")] == [
        next(line for line in text.splitlines() if "is t_s in seconds?" in line and line.startswith("Error:"))]
    assert (home / "aerosid-server.log").is_file()


# --------------------------------------------------------------------------- U15-U16 Prefect start-up
def test_u15_a_prefect_server_that_does_not_start_is_a_one_line_error(flight, tmp_path):
    home = tmp_path / "prefect-home"
    proc = subprocess.run([sys.executable, "-m", "aerosid.cli", "run", str(flight[0]), "--out", str(tmp_path / "run")],
                          env=_subprocess_env(home, PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS="1"),
                          capture_output=True, text=True, timeout=900)
    text = proc.stdout + proc.stderr
    assert proc.returncode == 1, text
    assert "Traceback" not in text
    assert "Error: Prefect's local API server did not start within 1 s" in text
    assert "PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS" in text and str(home / "aerosid-server.log") in text


def test_u16_the_test_harness_waits_long_enough_for_its_server(monkeypatch):
    """prefect_test_harness() has its own server_startup_timeout (default 30 s, too short
    on a loaded 2-core machine): the suite's harness passes a long one."""
    import prefect.testing.utilities as utilities

    from tests.conftest import prefect_harness_context

    seen = {}

    class Stop(Exception):
        pass

    def start(self, timeout=None):
        seen["timeout"] = timeout
        raise Stop

    monkeypatch.setattr(utilities.SubprocessASGIServer, "start", start)
    monkeypatch.setattr(utilities.SubprocessASGIServer, "_instances", {})  # leave the session's servers alone
    with pytest.raises(Stop):
        with prefect_harness_context():
            pass
    assert seen["timeout"] >= 300


def test_u15b_a_running_prefect_server_is_reused_only_if_it_answers_with_this_version():
    """`aerosid run` reuses a server on Prefect's default address (no start-up cost) --
    only one that answers /health and reports this Prefect's version."""
    import http.server
    import json
    import threading

    import prefect

    from aerosid.cli.prefect_server import running_server

    version = {"v": prefect.__version__}

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self):
            body = {"/api/health": True, "/api/admin/version": version["v"]}.get(self.path)
            self.send_response(200 if body is not None else 404)
            self.end_headers()
            self.wfile.write(json.dumps(body).encode())

        def log_message(self, *args):
            pass

    httpd = http.server.HTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{httpd.server_port}/api"
    try:
        assert running_server(url) == url
        version["v"] = "2.0.0"
        assert running_server(url) is None
    finally:
        httpd.shutdown()
    assert running_server(url) is None  # nothing listens any more


def test_a_parquet_time_column_of_timestamps_points_to_the_importer(flight, tmp_path):
    """A data system's Parquet with datetime t_s: the dtype error says what the column holds and
    which command reads it (aerosid import csv FILE.parquet; test_importers.py)."""
    _, raw = flight
    stamps = pd.Timestamp("2026-11-20 14:00:00") + pd.to_timedelta(raw["t_s"], unit="s")
    bad = write(raw.assign(t_s=stamps), tmp_path / "stamped.parquet")
    run_fails_fast([str(bad), "--vehicle", "seed-rlv"], tmp_path / "run", str(bad), "column 't_s'",
                   "t_s holds timestamps (timestamp[", "aerosid import csv FILE.parquet")


def test_an_empty_control_column_the_vehicle_does_not_use_says_to_fill_it_with_zeros(flight, tmp_path):
    """A data system without a fourth surface leaves d3 empty; the raw contract needs every
    channel, and the refusal now says when the vehicle's mixing does not read it (fill it with 0)."""
    _, raw = flight
    text = open(load_vehicle("c172x").source).read()
    one_aileron = text.replace("mixing = [[0.0, 0.5, -0.5, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]",
                               "mixing = [[0.0, 1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]")
    assert one_aileron != text
    veh = tmp_path / "one_aileron.toml"
    veh.write_text(one_aileron)
    for column, hint in (("d3_rad", True), ("d2_rad", False)):
        bad = write(raw.assign(**{column: np.nan}), tmp_path / f"no_{column}.parquet")
        text = clean_failure(cli("run", str(bad), "--vehicle", str(veh), "--out", str(tmp_path / "run")),
                             f"column '{column}'", "no value in the whole channel")
        assert ("mixing does not read d3_rad (its column 3 is zero): fill it with 0" in text) == hint, text


def test_a_record_too_coarse_to_measure_its_noise_in_is_refused_before_the_flow(flight, tmp_path):
    """5 Hz: the Nyquist frequency (2.5 Hz) is not above f_max_hz (4 Hz), where each channel's
    noise is measured; the smoother refuses it (test_pipeline.py), and the pre-flight now says so
    before any flow starts, naming t_s (docs/bad-input.md row 42)."""
    _, raw = flight
    bad = write(raw.iloc[::20].reset_index(drop=True), tmp_path / "five_hz.parquet")
    run_fails_fast([str(bad), "--vehicle", "seed-rlv"], tmp_path / "run", str(bad), "column 't_s'",
                   "Nyquist frequency 2.5 Hz (5 Hz sampling) is not above [estimation] f_max_hz = 4 Hz")
