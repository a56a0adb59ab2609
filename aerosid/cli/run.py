"""``aerosid run``: the whole pipeline on telemetry files (Prefect flows, imported lazily
so the core never loads Prefect), after cheap pre-flight checks of every input
(``_preflight``): a bad input is one clear error before any flow starts."""
from __future__ import annotations

from pathlib import Path

import click

#: How long `aerosid run` waits for Prefect's ephemeral API server to answer [s].  The
#: first run on a machine builds Prefect's SQLite database first: 20-40 s on an idle
#: 2-core machine, 37-125 s measured on a loaded one, past Prefect's default 20 s.
SERVER_STARTUP_TIMEOUT_S = 300


def _hermetic_defaults() -> None:
    """Prefect without a server: its ephemeral mode; no analytics call leaves the machine."""
    import os

    os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
    os.environ.setdefault("PREFECT_LOGGING_LEVEL", "INFO")
    os.environ.setdefault("PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS", str(SERVER_STARTUP_TIMEOUT_S))


class _NoTraceback:
    """A logging filter: Prefect logs a failed run with its traceback; the CLI turns the
    errors it expects into one clear message, so the log keeps only the message line
    (AEROSID_TRACEBACK=1 keeps the traceback, for debugging)."""

    @staticmethod
    def filter(record) -> bool:
        record.exc_info, record.exc_text = None, None
        return True


def _quiet_run_tracebacks() -> None:
    import logging
    import os

    if os.environ.get("AEROSID_TRACEBACK"):
        return
    for name in ("prefect.flow_runs", "prefect.task_runs"):
        logger = logging.getLogger(name)
        if not any(isinstance(f, _NoTraceback) for f in logger.filters):
            logger.addFilter(_NoTraceback())


@click.command()
@click.argument("telemetry", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--vehicle", default=None, metavar="NAME_OR_FILE",
              help="Built-in vehicle name or a vehicle TOML file (default: the vehicle the telemetry file "
                   "names in its metadata, e.g. a simulated flight's; there is no default vehicle).")
@click.option("--out", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Run folder: every stage's Parquet, coefficients.parquet, run.json, ledger.jsonl.")
@click.option("--flight", default=None, help="Flight identifier (default: from the file name); with several "
                                             "files, the pooled identification's (default: the run folder's name).")
@click.option("--window", "windows", multiple=True, nargs=2, type=float, metavar="T0 T1",
              help="Only this time window [s] (repeatable: each window is a phase/segment).")
@click.option("--model", "model_spec", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Model specification TOML (default: the seed's linear models).")
@click.option("--mach-half-width", type=float, default=0.5, show_default=True,
              help="Regress on samples with |M - M_ref| <= this (M_ref from the vehicle file).")
@click.option("--preprocess", "preprocess_settings", multiple=True, metavar="KEY=VALUE",
              help="A preprocessing threshold for this run (repeatable), on top of the vehicle file's "
                   "[preprocess] table: a global key (false_alarm=1e-4, max_interp_gap_s=1.0) or one "
                   "sensor's (V_m_s.update_interval_s=0.2, d1_rad.frozen_max_still_s=30). "
                   "Keys: docs/preprocessing.md.")
@click.option("--min-segment-s", type=float, default=None,
              help="Shortest piece of the flight that is smoothed [s] (default: the vehicle file's "
                   "[preprocess] min_segment_s, else 5).")
@click.option("--per-degree", is_flag=True,
              help="Print coefficients per degree (angle slopes per deg, rate derivatives per deg/s, fin slopes "
                   "per degree pair) instead of SI per radian.")
def run(telemetry, vehicle, out_dir, flight, windows, model_spec, mach_half_width, preprocess_settings,
        min_segment_s, per_degree):
    """Run the whole pipeline on one telemetry file (Prefect flow process_flight), or
    identify one model from several manoeuvres of one aircraft (process_manoeuvres).

    \b
    Stages: preprocess -> split into segments at long gaps -> EKF + MBF smoother
    per segment -> air data, coefficients, alpha/beta inversion -> regression.
    Several files: each is preprocessed and smoothed on its own (RUN_DIR/flights/<id>/),
    their flight data are pooled into one regression. Measured air data columns
    (rho_kg_m3, qbar_pa, p_static_pa, T_total_K) replace the US-1976 atmosphere;
    run.json's air_data says where each quantity came from.
    Needs no Prefect server (ephemeral mode). Re-running with the same inputs and
    code reuses every stage's output; the ledger (RUN_DIR/ledger.jsonl) records all.
    """
    _hermetic_defaults()
    from aerosid.preprocess import TelemetryError
    from aerosid.vehicles.vehicle import VehicleError

    params, min_segment_s = _preprocess_options(preprocess_settings, min_segment_s)
    pooled = len(telemetry) > 1
    try:
        if pooled and windows:
            raise click.UsageError("--window applies to one telemetry file; cut each manoeuvre's file to its "
                                   "window before pooling them")
        if windows:
            windows = _windows_in_run_time(telemetry[0], windows)
        # bad input fails here, before Prefect starts
        named = [_preflight(t, vehicle, model_spec, params, windows, min_segment_s) for t in telemetry]
        if flight is not None:
            from flows.steps import check_flight_id

            check_flight_id(flight)
        from aerosid.cli.prefect_server import PrefectServer
        from aerosid.cli.progress import RunProgress, quiet_console_logs
        from tasks.progress import listening

        with RunProgress("run") as progress:  # stages, segments, ETA (one line per stage when not a TTY)
            progress("start Prefect (local API server)", 0.0)
            server = PrefectServer()  # starts up while the flows are imported
            from flows.pipeline import pooled_vehicle, process_flight, process_manoeuvres

            vehicle = pooled_vehicle([str(t) for t in telemetry], vehicle) if pooled else named[0]
            _quiet_run_tracebacks()
            server.wait()
            quiet_console_logs()
            with server.settings(), listening(progress):
                if pooled:
                    summary = process_manoeuvres([str(t) for t in telemetry], str(out_dir), vehicle=vehicle,
                                                 name=flight, model_spec=str(model_spec) if model_spec else None,
                                                 mach_half_width=mach_half_width, preprocess_params=params,
                                                 min_segment_s=min_segment_s)
                else:
                    summary = process_flight(str(telemetry[0]), str(out_dir), vehicle=vehicle, flight=flight,
                                             windows=[list(w) for w in windows] or None,
                                             model_spec=str(model_spec) if model_spec else None,
                                             mach_half_width=mach_half_width, preprocess_params=params,
                                             min_segment_s=min_segment_s)
    except (TelemetryError, VehicleError, ValueError, RuntimeError) as exc:  # RuntimeError: tasks' StageFailed
        raise click.ClickException(str(exc)) from exc
    except OSError as exc:  # read-only or full output folder, a vanished file
        where = f" ({exc.filename})" if exc.filename else ""
        raise click.ClickException(f"cannot write the run folder {out_dir}: {exc.strerror or exc}{where}; "
                                   "earlier outputs are left as they were") from exc
    for fs in summary.get("flights", [summary]):
        _echo_usable_share(fs.get("usable_share"), (fs.get("preprocess") or {}).get("time_origin_s"))
        if fs.get("error", {}).get("stage") == "plan-segments":
            raise click.ClickException(f"{fs.get('telemetry', telemetry[0])}: {fs['error']['message']}")
        if fs.get("segments_note"):
            click.echo(f"note: {fs['segments_note']}")
        click.echo(f"flight {fs['flight']}: {fs['status']}; segments ok "
                   f"{[d['segment'] for d in fs['segments_ok']]}, failed {fs['segments_failed']}")
    for fid, src in (summary.get("air_data") or {}).items():
        click.echo(f"air data of {fid}: " + "; ".join(f"{k} from {v}" for k, v in src.items()))
    # one flight: its own; pooled manoeuvres: each one's (preprocessing, segments), then the pool's
    # (its flight data)
    findings = [(f"{fs['flight']}: ", f) for fs in summary.get("flights", []) for f in fs.get("findings", [])] + [
        ("", f) for f in summary.get("findings", [])]
    if findings:
        from aerosid.estimation.findings import Finding

        click.echo(f"{len(findings)} finding(s) -- the spans marked 'cut' were left out of the regression:")
        for manoeuvre, f in findings:
            click.echo(f"  {manoeuvre}{Finding(**f).summary()}")
    if "coefficients" in summary:
        import pandas as pd

        from aerosid.identification.identify import format_table

        if pooled:
            click.echo(f"pooled {len(summary['flights'])} manoeuvres into one identification: {summary['status']}")
        click.echo(format_table(pd.read_parquet(summary["coefficients"]["path"]), per_degree=per_degree))
        click.echo(f"wrote {out_dir}/coefficients.parquet, report.html, diagnosis.json, run.json, ledger.jsonl")
        from aerosid.cli.run_summary import run_outcome_lines

        for line in run_outcome_lines(Path(out_dir), mach_half_width):
            click.echo(line)
    if summary["status"] == "failed":
        reasons = "; ".join(f"{f['segment']}: {f['error']}" for fs in summary.get("flights", [summary])
                            for f in fs["segments_failed"])
        what = ", ".join(str(t) for t in telemetry)
        raise click.ClickException(f"{what}: no segment could be processed ({reasons or 'no segment'}); "
                                   f"see {out_dir}/ledger.jsonl")


def _preprocess_options(items, min_segment_s):
    """--preprocess KEY=VALUE items -> (PreprocessParams keyword arguments, min_segment_s);
    a bad key or value is a usage error naming it."""
    from aerosid.preprocess import SettingsError, parse_assignments, parse_settings

    try:
        params, from_items = parse_settings(parse_assignments(items))
    except (SettingsError, ValueError) as exc:
        raise click.BadParameter(str(exc), param_hint="--preprocess") from exc
    if min_segment_s is not None and not min_segment_s > 0:
        raise click.BadParameter(f"must be > 0, got {min_segment_s}", param_hint="--min-segment-s")
    return params, min_segment_s if min_segment_s is not None else from_items


def _windows_in_run_time(telemetry, windows) -> tuple:
    """--window pairs in the run's time: a record stamped in absolute time (Unix time) is processed
    in seconds since its first whole second (aerosid.preprocess.core.time_origin_s), so a window
    given in the record's own clock (both ends at or past that origin) is moved by it, with a note."""
    import pyarrow.parquet as pq

    from aerosid.preprocess.core import time_origin_s

    try:
        t_s = pq.read_table(telemetry, columns=["t_s"]).column("t_s")
        origin = time_origin_s(float(t_s[0].as_py())) if len(t_s) else 0.0
    except Exception:  # an unreadable file or no t_s: the preflight names it
        return tuple(windows)
    if not origin:
        return tuple(windows)
    out = tuple((a - origin, b - origin) if min(a, b) >= origin else (a, b) for a, b in windows)
    if out != tuple(windows):
        click.echo(f"note: --window in the record's clock, counted from t_s = {origin:.0f}: "
                   + ", ".join(f"{a:g}..{b:g} s" for a, b in out))
    return out


def _echo_usable_share(share: dict | None, time_origin_s: float | None = None) -> None:
    """One line: rows used of rows recorded, and the channels below 100 %; and the origin the
    run's times count from when the record is stamped in absolute time."""
    if not share:
        return
    low = {c: v["share"] for c, v in share["by_channel"].items() if v["used"] < share["recorded"]}
    click.echo(f"preprocess: rows used {share['used']} of {share['recorded']} recorded "
               f"({100.0 * share['share']:.1f} %)"
               + (("; channels below 100 %: " + ", ".join(f"{c} {100.0 * v:.1f} %" for c, v in low.items()))
                  if low else ""))
    if time_origin_s:
        click.echo(f"times (findings, windows, plots) are in s since t_s = {time_origin_s:.0f}, the record's first "
                   "whole second (absolute timestamps: aerosid.preprocess.time_origin_s)")


#: The inertial channels: a constant one is a dead sensor.
IMU_COLUMNS = ("ax_m_s2", "ay_m_s2", "az_m_s2", "p_rad_s", "q_rad_s", "r_rad_s")
#: Largest telemetry file `aerosid run` reads [bytes] (a 10-hour flight at 100 Hz is ~0.5 GB).
MAX_TELEMETRY_BYTES = 4_000_000_000


def _regular_file(path: Path, max_bytes: int) -> None:
    """A regular telemetry file (not a device, FIFO or folder: /dev/zero would never end), of bounded size."""
    import os
    import stat

    from aerosid.preprocess import TelemetryError

    st = os.stat(path)
    if not stat.S_ISREG(st.st_mode):
        raise TelemetryError("not a regular file (a device, pipe or folder cannot be telemetry)", file=str(path))
    if st.st_size > max_bytes:
        raise TelemetryError(f"{st.st_size} bytes: more than the {max_bytes} a telemetry file may have", file=str(path))


def _unused_control(vehicle: str | None, column: str) -> str:
    """For a control column d1..d4 that the vehicle's [controls] mixing does not read: the hint
    to fill it with zeros ("" otherwise, or when the vehicle does not load)."""
    import re

    m = re.fullmatch(r"d([1-4])_rad", column)
    if vehicle is None or m is None:
        return ""
    from aerosid.vehicles.vehicle import VehicleError, load_vehicle

    try:
        veh = load_vehicle(vehicle)
    except (VehicleError, OSError, ValueError):
        return ""
    k = int(m.group(1)) - 1
    if any(row[k] for row in veh.mixing):
        return ""
    return (f"; vehicle {veh.name}'s [controls] mixing does not read {column} (its column {k + 1} is zero): "
            "fill it with 0")


def _check_noise_band(t, veh, pre_params, source: str) -> None:
    """The smoother's refusal of a record too coarse to measure its noise in (Nyquist frequency
    not above f_max_hz), before any flow starts, as a TelemetryError naming t_s.  A rate outside
    the preprocessing's rate_bounds_hz is left to its own error ("is t_s in seconds?")."""
    import numpy as np

    from aerosid.estimation.pipeline import check_noise_band
    from aerosid.estimation.smoothing import smoothing_options
    from aerosid.preprocess import TelemetryError

    d = np.diff(np.asarray(t, float))
    d = d[np.isfinite(d) & (d > 0)]
    if not d.size:
        return
    rate = pre_params.nominal_rate_hz or 1.0 / float(np.median(d))
    lo, hi = pre_params.rate_bounds_hz
    if not lo <= rate <= hi:
        return
    try:
        check_noise_band(1.0 / rate, smoothing_options(veh).f_max_hz)
    except ValueError as exc:
        raise TelemetryError(str(exc), file=source, column="t_s") from None


def _preflight(telemetry: Path, vehicle: str | None, model_spec: str | None, preprocess_params: dict | None = None,
               windows=(), min_segment_s: float | None = None) -> str:
    """Cheap checks of the inputs before any flow starts: the telemetry file is a
    regular file of readable Parquet that follows RawTelemetry, has rows, spans at least
    the minimum segment length, has no channel without a single value and no constant
    inertial channel; the vehicle (given, else the one the file names: there is no
    default), its preprocessing settings with the run's on top, and the model
    specification load; the telemetry's units fit the vehicle's envelope
    (aerosid.plausibility.units); the time windows leave a segment of at least the
    minimum segment length.  Returns the vehicle."""
    import numpy as np
    import pyarrow.parquet as pq

    from aerosid.io import telemetry_vehicle
    from aerosid.modelling.models import default_models, load_models
    from aerosid.plausibility.units import check_units, range_unit_hint
    from aerosid.preprocess import TelemetryError
    from aerosid.preprocess.core import time_origin_s
    from aerosid.vehicles.vehicle import load_vehicle
    from schemas.telemetry import CHANNELS, MEASURED_AIR_DATA_CHANNELS, RAW_COLUMNS, RawTelemetry, sentinel_mask
    from tasks.runner import read_validated

    _regular_file(telemetry, MAX_TELEMETRY_BYTES)
    try:
        frame = read_validated(telemetry, RawTelemetry)
    except TelemetryError as exc:
        if exc.column in RAW_COLUMNS and "column_in_dataframe" in exc.reason:
            extra = [c for c in pq.read_schema(telemetry).names if c not in RAW_COLUMNS]
            if extra:
                raise TelemetryError(f"{exc.reason}; columns outside the contract {extra}: misnamed? "
                                     f"(the raw contract is {list(RAW_COLUMNS)})", file=exc.file,
                                     column=exc.column, rows=exc.rows) from None
        if exc.column == "t_s" and "dtype" in exc.reason:
            import pyarrow as pa

            kind = pq.read_schema(telemetry).field("t_s").type
            if pa.types.is_timestamp(kind) or pa.types.is_date(kind):
                raise TelemetryError(f"{exc.reason}; t_s holds timestamps ({kind}), the raw contract seconds as "
                                     "float64: `aerosid import csv FILE.parquet --map MAP --out DIR` reads a data "
                                     "system's Parquet (its names, units and timestamps; docs/real-flight.md)",
                                     file=exc.file, column=exc.column, rows=exc.rows) from None
        if exc.column in RAW_COLUMNS + MEASURED_AIR_DATA_CHANNELS and "mostly_in_physical_range" in exc.reason:
            hint = range_unit_hint(exc.column, pq.read_table(telemetry, columns=[exc.column]).column(0).to_numpy())
            if hint:
                raise TelemetryError(exc.reason + hint, file=exc.file, column=exc.column, rows=exc.rows) from None
        raise
    if len(frame) == 0:
        raise TelemetryError("no rows: nothing to process", file=str(telemetry))
    for c in CHANNELS:
        x = frame[c].to_numpy()
        if not (np.isfinite(x) & ~sentinel_mask(x)).any():
            raise TelemetryError(f"no value in the whole channel (all {len(frame)} rows NaN, infinite or a "
                                 f"no-data sentinel): the pipeline needs every channel{_unused_control(vehicle, c)}",
                                 file=str(telemetry), column=c, rows=range(len(frame)))
    for c in (m for m in MEASURED_AIR_DATA_CHANNELS if m in frame.columns):
        x = frame[c].to_numpy()
        if not (np.isfinite(x) & ~sentinel_mask(x)).any():
            raise TelemetryError(f"no value in the whole measured air-data column (all {len(frame)} rows NaN, "
                                 "infinite or a no-data sentinel): fill it, or drop the column to use the US-1976 "
                                 "atmosphere", file=str(telemetry), column=c, rows=range(len(frame)))
    for c in IMU_COLUMNS:
        x = frame[c].to_numpy(float)
        x = x[np.isfinite(x) & ~sentinel_mask(x)]
        if x.size > 1 and np.ptp(x) == 0.0:
            raise TelemetryError(f"all {x.size} values are {float(x[0]):g}: a constant inertial channel is a dead or "
                                 "frozen sensor, and the filter needs its measurements", file=str(telemetry),
                                 column=c, rows=range(len(frame)))
    if vehicle is None:
        vehicle = telemetry_vehicle(telemetry)  # the file was read: names its vehicle or raises
    veh = load_vehicle(vehicle)
    from aerosid.preprocess import DEFAULT_MIN_SEGMENT_S, PreprocessParams, merge_settings

    pre_params = PreprocessParams.from_dict(merge_settings(veh.preprocess, preprocess_params or {}))
    shortest = next(v for v in (min_segment_s, veh.min_segment_s, DEFAULT_MIN_SEGMENT_S) if v is not None)
    t = frame["t_s"].to_numpy(float)
    if t[-1] - t[0] < shortest:
        raise TelemetryError(f"the flight spans {t[-1] - t[0]:.3g} s ({len(frame)} rows): shorter than the minimum "
                             f"segment length min_segment_s = {shortest:g} s (set it with --min-segment-s or the "
                             "vehicle file's [preprocess] min_segment_s)", file=str(telemetry), column="t_s",
                             rows=range(len(frame)))
    from aerosid.vehicles.airspeed import as_true_airspeed

    check_units(as_true_airspeed(frame, veh.airspeed_kind)[0], veh, str(telemetry))  # as the preprocessing reads it
    _check_noise_band(t, veh, pre_params, str(telemetry))
    if veh.air_data_source == "vanes":
        for c in (veh.alpha_column, veh.beta_column):
            if c not in frame.columns:
                raise TelemetryError(f"vehicle {veh.name} reads alpha and beta from air-data vanes "
                                     f"({veh.source} [air_data]) but the telemetry has no such column",
                                     file=str(telemetry), column=c)
    if model_spec:
        load_models(model_spec, base=default_models(veh), mach_reference=veh.mach_reference)
    if windows:  # windows too short to smooth are refused now, naming the limit (gaps are seen later)
        from aerosid.preprocess.segments import plan_segments

        # in the pipeline's time (preprocess.time_origin_s)
        plan = plan_segments(t - time_origin_s(float(t[0])), [], [tuple(w) for w in windows], float(shortest))
        if not plan.segments:
            raise ValueError(f"{telemetry}: {plan.refusal()}")
    return vehicle
