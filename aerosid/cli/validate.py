"""``aerosid validate RUN_DIR OTHER_TELEMETRY``: predict another manoeuvre with a run's model.

Parses and prints only; the work is in aerosid.identification.validate (the core,
in memory: the other manoeuvre's estimation runs without Prefect, see
aerosid.ebm.estimate_flight_data).  Registered in aerosid/cli.py.
"""
from __future__ import annotations

import re
from pathlib import Path

import click

EPILOG = """\b
Examples:
  aerosid run runs/m018/telemetry.parquet --out runs/m018/run
  aerosid validate runs/m018/run runs/m017/telemetry.parquet
  aerosid validate runs/m018/run runs/m017/telemetry.parquet --bias intercepts --out runs/m018/pred017
  aerosid validate runs/m018/run runs/m017/telemetry.parquet --coefficients runs/m018/run/refine/m018/coefficients.parquet
"""


def _default_out(run_dir: Path, telemetry: Path, folder: str = "validation") -> Path:
    """RUN_DIR/<folder>/<the telemetry's name> (its folder's name for a telemetry.parquet)."""
    stem = telemetry.parent.name if telemetry.stem == "telemetry" and telemetry.parent.name else telemetry.stem
    return run_dir / folder / (re.sub(r"[^A-Za-z0-9_.-]+", "_", stem).strip("._-") or "other")


@click.command(epilog=EPILOG)
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
@click.argument("other_telemetry", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--vehicle", default=None, metavar="NAME_OR_FILE",
              help="Vehicle of the other manoeuvre (default: the run's, from RUN_DIR/run.json).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Folder for validation.json, validation.html, validation.parquet "
                   "(default: RUN_DIR/validation/<telemetry name>).")
@click.option("--version", "version_id", default=None, metavar="vNNN",
              help="Use this model version (default: the latest under RUN_DIR/models, else the run's coefficients).")
@click.option("--coefficients", "coefficients", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              default=None, metavar="FILE",
              help="Use this coefficients table instead of a model version (e.g. aerosid refine's "
                   "RUN_DIR/refine/<name>/coefficients.parquet).")
@click.option("--bias", type=click.Choice(["none", "offsets", "intercepts"]), default="offsets", show_default=True,
              help="none: the model as identified; offsets: remove the mean of measured - predicted per output "
                   "(SIDPAC's prediction); intercepts: also re-estimate CN_0, Cm_0, ... on this manoeuvre.")
@click.option("--axes", type=click.Choice(["auto", "lon", "lat", "both"]), default="auto", show_default=True,
              help="Which axes to simulate: lon (alpha, q, a_z), lat (beta, p, r, a_y); auto = lon, plus lat when "
                   "the lateral channels are all identified (with beta inverted from C_Y, --axes lat simulates C_Y "
                   "at the preflight database's values).")
@click.option("--window", "windows", multiple=True, nargs=2, type=float, metavar="T0 T1",
              help="Only this time window [s] of the other telemetry (repeatable).")
def validate(run_dir, other_telemetry, vehicle, out_dir, version_id, coefficients, bias, axes, windows):
    """Predict another manoeuvre of the same vehicle with the run's identified model.

    \b
    Coefficient prediction: OTHER_TELEMETRY goes through the same estimation as the
    run (preprocessing, EKF + MBF smoother, flight data); each channel's coefficient
    is predicted from its regressors.
    Output prediction: the model is simulated driven by the measured controls,
    airspeed, dynamic pressure and attitude (telemetry columns phi_rad, theta_rad),
    from the measured initial state; alpha, q, a_z (beta, p, r, a_y) are compared
    with the measurements.

    Prints Theil's inequality coefficient (TIC) and the RMS error per output and
    channel; writes validation.json, validation.html (measured vs predicted plots,
    self-contained) and validation.parquet (the time histories).
    """
    from aerosid.identification.validate import validate as run_validation, write_validation

    run_on_manoeuvre(run_dir, other_telemetry, "validate",
                     lambda progress: run_validation(run_dir, other_telemetry, vehicle=vehicle, version=version_id,
                                                     bias=bias, axes=axes, windows=[tuple(w) for w in windows] or None,
                                                     progress=progress, coefficients=coefficients),
                     write_validation, out_dir or _default_out(run_dir, other_telemetry))


def run_on_manoeuvre(run_dir: Path, telemetry: Path, stage: str, compute, write, out: Path) -> dict:
    """What ``validate`` and ``refine`` share: RUN_DIR checked, compute(progress) under the
    progress display with the core's errors as one clear line, its summary printed, then
    write(result, out) and what it wrote.  Returns the written paths."""
    from aerosid.cli.progress import stage_progress
    from aerosid.identification.identified import ModelSourceError
    from aerosid.preprocess import TelemetryError
    from aerosid.vehicles.vehicle import VehicleError

    if not run_dir.is_dir():
        raise click.ClickException(f"{run_dir}: no such run folder (make one with `aerosid run TELEMETRY --out "
                                   f"{run_dir}`)")
    try:
        with stage_progress(stage) as progress:
            result = compute(progress)
    except (ModelSourceError, VehicleError, TelemetryError) as exc:
        raise click.ClickException(str(exc)) from exc
    except ValueError as exc:
        raise click.ClickException(f"{telemetry}: {exc}" if str(telemetry) not in str(exc) else str(exc)) from exc
    click.echo(result.summary())
    try:
        paths = write(result, out)
    except OSError as exc:
        raise click.ClickException(f"cannot write {out}: {exc.strerror or exc}") from exc
    except ValueError as exc:
        raise click.ClickException(f"nothing written to {out}: {exc}") from exc
    click.echo("wrote " + ", ".join(str(p) for p in paths.values()))
    return paths
