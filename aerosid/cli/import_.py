"""``aerosid import``: real flight data into aerosid's raw telemetry and a vehicle file.

Only argument parsing and printing; the converters are aerosid/vehicles/.
"""
from __future__ import annotations

from pathlib import Path

import click

EPILOG_IMPORT = """\b
Examples:
  aerosid import sidpac lon_020213f1_018.mat --out runs/to18
  aerosid import csv flight.csv --map flight.map.toml --out runs/flight
  aerosid run runs/to18/telemetry.parquet --out runs/to18/run
See docs/real-flight.md.
"""


@click.group(name="import", epilog=EPILOG_IMPORT)
def import_group() -> None:
    """Import real flight data: writes DIR/telemetry.parquet (the raw contract, SI and
    radians) and DIR/vehicle.toml, which `aerosid run DIR/telemetry.parquet` finds."""


def _import(read, out_dir: Path) -> None:
    """read() -> the imported flight; written to out_dir, with a stage display (aerosid.cli.progress)."""
    from aerosid.cli.progress import stage_progress

    with stage_progress("import") as progress:
        progress("read, convert and check", 0.0)
        imported = read()
        progress("write", 0.0)
        paths = imported.write(out_dir)
    _echo_written(imported, paths, out_dir)


def _echo_written(imported, paths: dict, out_dir: Path) -> None:
    click.echo(imported.summary())
    for path in paths.values():
        click.echo(f"  wrote {path}")
    click.echo(f"next: aerosid run {paths['telemetry']} --out {Path(out_dir) / 'run'}")


def _errors():
    from aerosid.preprocess import TelemetryError
    from aerosid.vehicles.vehicle import VehicleError
    from aerosid.vehicles.importers import ImportDataError

    return ImportDataError, TelemetryError, VehicleError


@import_group.command(name="sidpac", epilog=EPILOG_IMPORT)
@click.argument("file", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--out", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Folder for telemetry.parquet and vehicle.toml (created; files in it are replaced).")
def sidpac(file, out_dir):
    """A SIDPAC flight-data .mat file (fdata in SIDPAC's 90-column layout).

    Telemetry: V, p, q, r, h, the surfaces as d1..d4 (elevator, left and right
    aileron, rudder), alpha and beta as vanes, and density, dynamic pressure and
    attitude when recorded. Vehicle file: mass, inertia, CG, S, chord, span from
    the file; the accelerometer position recovered from the measured and CG
    accelerations when the file allows it.
    """
    from aerosid.vehicles.sidpac import import_sidpac

    try:
        _import(lambda: import_sidpac(file), out_dir)
    except _errors() as exc:
        raise click.ClickException(str(exc)) from exc
    except OSError as exc:
        raise click.ClickException(f"cannot write {out_dir}: {exc.strerror or exc}") from exc


@import_group.command(name="csv", epilog=EPILOG_IMPORT)
@click.argument("file", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--map", "map_file", required=True, type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="TOML map: per raw column the CSV column and its unit; the vehicle (a file or a [vehicle] "
                   "table). Example: aerosid/data/examples/twin-otter-018.map.toml.")
@click.option("--out", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Folder for telemetry.parquet and vehicle.toml (created; files in it are replaced).")
def csv(file, map_file, out_dir):
    """A flight-test CSV, columns and units named in a map (deg, deg/s, g, ft, ft/s, kt,
    lbf/ft^2, slug/ft^3, ...; converted by pint, each conversion recorded in the
    Parquet metadata). A data system's Parquet table (FILE.parquet) is read with the same
    map; a timestamp time column becomes seconds since 1970 UTC."""
    from aerosid.vehicles.csv_import import import_csv

    try:
        _import(lambda: import_csv(file, map_file), out_dir)
    except _errors() as exc:
        raise click.ClickException(str(exc)) from exc
    except OSError as exc:
        raise click.ClickException(f"cannot write {out_dir}: {exc.strerror or exc}") from exc
