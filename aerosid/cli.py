"""The ``aerosid`` command line.

This module only parses arguments and prints; the work happens in the core
(``aerosid.*``) or, for ``run``, in the Prefect flows (imported lazily so the
core never loads Prefect).
"""
from __future__ import annotations

import sys
from pathlib import Path

import click

EPILOG_SIMULATE = """\b
Examples:
  aerosid simulate --list-effects
  aerosid simulate --case seed-rlv --seed 3 --out runs/flight3
  aerosid simulate --effect pitch_damping --effect mach_cm_alpha=0.5 --out runs/hidden
  aerosid simulate --duration 600 --rate 100 --out runs/long
"""


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(package_name="aerosid")
def main() -> None:
    """Estimate a flight vehicle's aerodynamic coefficients from its own noisy
    telemetry (Estimation Before Modeling), and find what the model is missing.

    \b
    Typical session:
      aerosid simulate --case seed-rlv --out runs/ref      # a flight with known truth
      aerosid run runs/ref/telemetry.parquet --out runs/ref/result

    Units: SI and radians everywhere; reports also print per degree, saying so.
    """


@main.command(epilog=EPILOG_SIMULATE)
@click.option("--case", "case_name", default="seed-rlv", show_default=True,
              help="Built-in simulation case (vehicle + trajectory + manoeuvres + faults).")
@click.option("--effect", "effects", multiple=True, metavar="NAME[=SCALE]",
              help="Hide a catalogue effect in the flight aerodynamics (repeatable); SCALE multiplies "
                   "its physical default size. See --list-effects.")
@click.option("--seed", default=0, show_default=True, type=int, help="Random seed for noise and faults.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              help="Output folder for telemetry.parquet, truth.parquet and truth.json.")
@click.option("--duration", type=float, default=None, help="Flight duration [s] (default: the case's).")
@click.option("--rate", type=float, default=None, help="Sample rate [Hz] (default: the case's).")
@click.option("--no-faults", is_flag=True, help="No dropouts, outliers or sync gap (noise only).")
@click.option("--list-effects", is_flag=True, help="Print the hidden-effect catalogue and exit.")
def simulate(case_name, effects, seed, out_dir, duration, rate, no_faults, list_effects):
    """Simulate a flight whose truth is known and write its telemetry.

    Writes DIR/telemetry.parquet (raw, as a flight delivers it: dropouts as
    missing rows or NaN rows, outlier spikes, one sync gap), DIR/truth.parquet
    (true states, alpha, beta, coefficients and fault masks per sample) and
    DIR/truth.json (the true flight coefficients, SI per radian, about the CG).
    """
    from aerosid.effects import catalogue_table, parse_effect_spec

    if list_effects:
        click.echo(catalogue_table())
        return
    if out_dir is None:
        raise click.UsageError("--out DIR is required (or use --list-effects)")
    from dataclasses import replace

    from aerosid.simulation import load_case, simulate as run_simulation

    try:
        parsed = tuple(parse_effect_spec(e) for e in effects)
        overrides = {}
        if duration is not None:
            overrides["duration_s"] = duration
        if rate is not None:
            overrides["sample_rate_hz"] = rate
        case = load_case(case_name, **overrides)
        if no_faults:
            case = replace(case, faults=case.faults.without_faults())
    except (KeyError, ValueError) as exc:
        raise click.BadParameter(str(exc.args[0] if exc.args else exc)) from exc
    flight = run_simulation(case, parsed, seed=seed)
    paths = flight.write(out_dir)
    click.echo(flight.summary())
    for kind, path in paths.items():
        click.echo(f"  wrote {path}")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
