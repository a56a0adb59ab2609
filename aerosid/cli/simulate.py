"""``aerosid simulate``: a flight whose truth is known (the built-in simulator or JSBSim)."""
from __future__ import annotations

import re
from contextlib import contextmanager
from pathlib import Path

import click

EPILOG_SIMULATE = """\b
Examples:
  aerosid simulate --list-effects
  aerosid simulate --case seed-rlv --seed 3 --out runs/flight3
  aerosid simulate --effect pitch_damping --effect mach_cm_alpha=0.5 --out runs/hidden
  aerosid simulate --hidden pitch_control_lag --out runs/lag   # not a catalogue effect (localisation)
  aerosid simulate --duration 600 --rate 100 --out runs/long
"""


@click.command(epilog=EPILOG_SIMULATE)
@click.option("--case", "case_name", default="seed-rlv", show_default=True,
              help="Built-in simulation case (vehicle + trajectory + manoeuvres + faults).")
@click.option("--effect", "effects", multiple=True, metavar="NAME[=SCALE]",
              help="Hide a catalogue effect in the flight aerodynamics (repeatable); SCALE multiplies "
                   "its physical default size. See --list-effects.")
@click.option("--hidden", "hidden", multiple=True, metavar="NAME[=SCALE]",
              help="Hide an effect that is NOT in the diagnosis catalogue (repeatable; for testing the "
                   "diagnosis' localisation): see the second section of --list-effects.")
@click.option("--seed", default=0, show_default=True, type=int, help="Random seed for noise and faults.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              help="Output folder for telemetry.parquet, truth.parquet and truth.json.")
@click.option("--duration", type=float, default=None, help="Flight duration [s] (default: the case's).")
@click.option("--rate", type=float, default=None, help="Sample rate [Hz] (default: the case's).")
@click.option("--no-faults", is_flag=True, help="No dropouts, outliers or sync gap (noise only).")
@click.option("--list-effects", is_flag=True, help="Print the hidden-effect catalogue and exit.")
@click.option("--jsbsim", "jsbsim_aircraft", default=None, metavar="AIRCRAFT",
              help="Fly AIRCRAFT in JSBSim instead of the built-in simulator: c172x (hand-written flight) or "
                   "any aircraft of the jsbsim package that trims (e.g. pa28, OV10, T37, F4N; flight "
                   "design and DIR/vehicle.toml generated). Needs the extra: pip install 'aerosid[jsbsim]'.")
@click.option("--turbulence", type=click.Choice(["none", "light", "moderate"]), default="none", show_default=True,
              help="With --jsbsim: fly in JSBSim's MIL-F-8785C (Tustin) turbulence, rotational gusts included "
                   "(light: vertical gust ~0.55 m/s rms; moderate ~1.4 m/s). Analyse such a flight with "
                   "[estimation] turbulent_air = true in its vehicle file.")
@click.option("--manoeuvre", default="3211", show_default=True,
              help="JSBSim input sequence: 3211 = elevator 3-2-1-1, then aileron and rudder doublets.")
@click.option("--input", "input_file", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
              help="Fly a designed input (DIR/input.parquet or .csv of `aerosid design`): t_s plus control "
                   "columns in radians; it replaces the manoeuvres of its axes.")
def simulate(case_name, effects, hidden, seed, out_dir, duration, rate, no_faults, list_effects, jsbsim_aircraft,
             turbulence, manoeuvre, input_file):
    """Simulate a flight whose truth is known and write its telemetry.

    Writes DIR/telemetry.parquet (raw, as a flight delivers it: dropouts as
    missing rows or NaN rows, outlier spikes, one sync gap), DIR/truth.parquet
    (true states, alpha, beta, coefficients and fault masks per sample) and
    DIR/truth.json (the true flight coefficients, SI per radian, about the CG).
    """
    from aerosid.modelling.effects import catalogue_table, parse_effect_spec

    from aerosid.simulation.hidden import hidden_table, parse_hidden_spec

    if list_effects:
        click.echo(catalogue_table())
        click.echo(hidden_table())
        return
    if out_dir is None:
        raise click.UsageError("--out DIR is required (or use --list-effects)")
    from dataclasses import replace

    if jsbsim_aircraft is not None:
        if effects or hidden or duration is not None or rate is not None:
            raise click.UsageError("--effect, --hidden, --duration and --rate apply to the built-in simulator, "
                                   "not --jsbsim")
        from aerosid.simulation.jsbsim_flight import JSBSimUnavailable, simulate_jsbsim

        from aerosid.cli.progress import stage_progress

        table = _input_table(input_file, jsbsim=True)
        try:
            with stage_progress("simulate") as progress, _reopened_output_notices_dropped():
                flight = simulate_jsbsim(jsbsim_aircraft, manoeuvre, seed=seed, faults=not no_faults,
                                         progress=progress, input_table=table, turbulence=turbulence)
                progress("write", 0.0)
                paths = flight.write(out_dir)
        except JSBSimUnavailable as exc:
            raise click.ClickException(str(exc)) from exc
        except ValueError as exc:
            raise click.BadParameter(str(exc)) from exc
        click.echo(flight.summary())
        for kind, path in paths.items():
            click.echo(f"  wrote {path}")
        return

    if turbulence != "none":
        raise click.UsageError("--turbulence applies to --jsbsim flights (the built-in simulator flies in calm air)")
    from aerosid.simulation import load_case, simulate as run_simulation

    try:
        parsed = tuple(parse_effect_spec(e) for e in effects)
        parsed_hidden = tuple(parse_hidden_spec(h) for h in hidden)
        overrides = {}
        if duration is not None:
            overrides["duration_s"] = duration
        if rate is not None:
            overrides["sample_rate_hz"] = rate
        table = _input_table(input_file, jsbsim=False)
        if table is not None:
            from aerosid.design.io import as_case_inputs

            overrides["inputs"] = as_case_inputs(table)
            overrides.setdefault("duration_s", float(table["t_s"].iloc[-1]))
        case = load_case(case_name, **overrides)
        if no_faults:
            case = replace(case, faults=case.faults.without_faults())
    except (KeyError, ValueError) as exc:
        raise click.BadParameter(str(exc.args[0] if exc.args else exc)) from exc
    from aerosid.cli.progress import stage_progress

    with stage_progress("simulate") as progress:
        flight = run_simulation(case, parsed, seed=seed, progress=progress, hidden=parsed_hidden)
        progress("sensors, faults and write", 0.0)
        paths = flight.write(out_dir)
    click.echo(flight.summary())
    for kind, path in paths.items():
        click.echo(f"  wrote {path}")


#: JSBSim's notice, on stdout, when it re-opens an aircraft's <output> file that it holds open
#: already (at every initial-condition run after the first), and the line that follows it.
_REOPEN_NOTICE = re.compile(r"ERROR: unable to open the file (?P<path>\S+)\n\s*=> Output to this file is disabled\.\n")


@contextmanager
def _reopened_output_notices_dropped():
    """JSBSim's stdout during the flight, less its re-open notices for files in aerosid's scratch
    folder.  An aircraft whose XML asks for an output file (pogo: pogo.csv) has it opened at the
    first initial-condition run and re-opened at every later one; the stream being open, JSBSim
    prints "ERROR: unable to open the file ..." (265 times for pogo's trim and design): harmless,
    aerosid disables those outputs, but it read as a failure.  stdout (fd 1, JSBSim's C++ stream)
    goes to a temporary file meanwhile and the rest of it is written back after the flight; the
    progress display is on stderr."""
    import os
    import sys
    import tempfile

    scratch = tempfile.gettempdir()
    sys.stdout.flush()
    saved = os.dup(1)
    with tempfile.TemporaryFile() as cap:
        os.dup2(cap.fileno(), 1)
        try:
            yield
        finally:
            sys.stdout.flush()
            os.dup2(saved, 1)
            os.close(saved)
            cap.seek(0)
            text = cap.read().decode(errors="replace")
            kept = _REOPEN_NOTICE.sub(lambda m: "" if m["path"].startswith(scratch) else m[0], text)
            sys.stdout.write(re.sub(r"\n{3,}", "\n\n", kept))
            sys.stdout.flush()


def _input_table(path, jsbsim: bool):
    """The designed input of `simulate --input` (None without one); a bad file -> a clear error."""
    if path is None:
        return None
    from aerosid.design.io import JSBSIM_COLUMNS, RLV_COLUMNS, InputFileError, read_input

    try:
        return read_input(path, JSBSIM_COLUMNS if jsbsim else RLV_COLUMNS)
    except InputFileError as exc:
        raise click.ClickException(str(exc)) from exc
