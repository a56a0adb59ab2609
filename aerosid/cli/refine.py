"""``aerosid refine RUN_DIR TELEMETRY``: output-error refinement of a run's model.

Parses and prints only; the work is in aerosid.identification.refine (the core, in memory:
the manoeuvre's estimation runs without Prefect, as ``aerosid validate``'s).  Registered in
aerosid/cli/app.py.
"""
from __future__ import annotations

from pathlib import Path

import click

EPILOG = """\b
Examples:
  aerosid run runs/m018/telemetry.parquet --out runs/m018/run
  aerosid refine runs/m018/run runs/m018/telemetry.parquet
  aerosid refine runs/m018/run runs/m018/telemetry.parquet --axes lon --free Cm_alpha --free Cm_q
"""


@click.command(epilog=EPILOG)
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
@click.argument("telemetry", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--vehicle", default=None, metavar="NAME_OR_FILE",
              help="Vehicle of the manoeuvre (default: the run's, from RUN_DIR/run.json).")
@click.option("--version", "version_id", default=None, metavar="vNNN",
              help="Start from this model version (default: the latest under RUN_DIR/models, else the run's "
                   "coefficients).")
@click.option("--axes", type=click.Choice(["auto", "lon", "lat", "both"]), default="auto", show_default=True,
              help="Axes to refine: lon (CN, Cm: alpha, q, a_z), lat (CY, Cl, Cn: beta, p, r, a_y); auto = lon, "
                   "plus lat when the lateral channels are all identified (with beta inverted from C_Y, --axes lat "
                   "simulates C_Y at the preflight database's values and does not refine it).")
@click.option("--free", multiple=True, metavar="COEFFICIENT",
              help="Refine only this coefficient (repeatable; default: every identified one of the axes).")
@click.option("--window", "windows", multiple=True, nargs=2, type=float, metavar="T0 T1",
              help="Only this time window [s] of the telemetry (repeatable).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Folder for coefficients.parquet and output_error.json (default: RUN_DIR/refine/<telemetry name>).")
def refine(run_dir, telemetry, vehicle, version_id, axes, free, windows, out_dir):
    """Refine the run's model by output error on a manoeuvre, from its equation-error estimates.

    \b
    The model is simulated with the measured controls, airspeed, dynamic pressure and
    attitude (telemetry columns phi_rad, theta_rad) and its coefficients adjusted until the
    simulated alpha, q, a_z (beta, p, r, a_y) match the measured ones.  The sensors' noise is
    then output noise, which biases nothing, where the equation-error regression reads it in
    its regressors.  Slow: one simulation per coefficient per iteration (minutes on a long
    flight).  Prints the equation-error and output-error estimates side by side with sigma
    (coloured residuals) and the Cramer-Rao bound; writes coefficients.parquet (the refined
    model, for aerosid validate --coefficients) and output_error.json.
    """
    from aerosid.cli.validate import _default_out, run_on_manoeuvre
    from aerosid.identification.refine import refine as run_refine, write_refinement

    paths = run_on_manoeuvre(run_dir, telemetry, "refine",
                             lambda progress: run_refine(run_dir, telemetry, vehicle=vehicle, version=version_id,
                                                         axes=axes, free=list(free) or None,
                                                         windows=[tuple(w) for w in windows] or None,
                                                         progress=progress),
                             write_refinement, out_dir or _default_out(run_dir, telemetry, "refine"))
    click.echo("which model predicts better? predict another manoeuvre with each: aerosid validate "
               f"{run_dir} OTHER_TELEMETRY [--coefficients {paths['coefficients']}]")
