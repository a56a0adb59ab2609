"""``aerosid design``: the manoeuvre that would reveal an effect (aerosid.design)."""
from __future__ import annotations

from pathlib import Path

import click


@click.command()
@click.argument("run_dir", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("--effect", required=True, metavar="NAME",
              help="Candidate effect (e.g. pitch_damping, alpha_nonlinearity, alpha_dot), a coefficient of the "
                   "run's model (Cm_q), or a model-spec term 'Cm: Cm_a3 = alpha**3'.")
@click.option("--size", type=float, default=None,
              help="Coefficient value to make detectable (default: the catalogue size, else the run's estimate).")
@click.option("--versus", default=None, metavar="NAME",
              help="A second term to separate from the first (e.g. --effect control_alpha --versus "
                   "alpha_nonlinearity): the design looks for the manoeuvre on which either, present at its size, "
                   "is found significant with the other in the model.")
@click.option("--versus-size", type=float, default=None,
              help="Size of the --versus term (default: the run's estimate when the run's model has the term, "
                   "else the catalogue size).")
@click.option("--out", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Writes DIR/input.parquet, DIR/input.csv and DIR/design.json.")
@click.option("--mach-half-width", type=float, default=0.5, show_default=True,
              help="Regression window |M - M_ref| <= this, as the fit uses.")
@click.option("--no-refine", is_flag=True,
              help="Predict with the run's residual only (skip the one noisy simulated flight of the design "
                   "through the pipeline that measures how the manoeuvre changes the estimation error).")
@click.option("--power", type=click.Choice(["trim", "idle"]), default="trim", show_default=True,
              help="JSBSim aircraft: fly at the simulator's trimmed power, or power-off ('idle': a glide trimmed at "
                   "idle throttle, the input gets throttle_cmd_norm = 0) so the propeller's moment stays out of "
                   "the pitch-damping fit.")
@click.option("--quiet", is_flag=True, help="No progress lines.")
def design(run_dir, effect, size, versus, versus_size, out_dir, mach_half_width, no_refine, power, quiet):
    """Propose a manoeuvre that makes an effect detectable (or separates two terms).

    Uses the run's identified model and residual and the vehicle file's limits
    (surface deflections and rates, alpha, load factor, duration): candidate
    3-2-1-1s, doublets and Schroeder multisines are flown noise-free at the largest
    amplitude the limits allow, and the sigma the pipeline would report is predicted
    (Morelli-Klein covariance with the run's residual).  Prints sigma and the
    detectable size before (the run's manoeuvre) and after (the design), or says
    that no manoeuvre within the limits can do it.  Fly the design with
    `aerosid simulate ... --input DIR/input.parquet`.
    """
    from aerosid.design.core import DesignError, design as run_design, write_design
    from aerosid.modelling.versions import VersionError
    from aerosid.vehicles.vehicle import VehicleError

    say = (lambda msg: None) if quiet else (lambda msg: click.echo(f"  .. {msg}", err=True))
    try:
        d = run_design(run_dir, effect, size, versus, versus_size=versus_size, mach_half_width=mach_half_width,
                       refine=not no_refine, progress=say, power=power)
    except (DesignError, VersionError, VehicleError) as exc:
        raise click.ClickException(str(exc)) from exc
    except ImportError as exc:
        raise click.ClickException(f"the design needs a simulator that is not installed: {exc}") from exc
    paths = write_design(d, out_dir)
    click.echo(d.summary())
    for path in paths.values():
        click.echo(f"  wrote {path}")
