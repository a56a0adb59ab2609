"""The modelling-loop commands: ``aerosid diagnose``, ``aerosid fit``, ``aerosid history``.

They read a run folder written by ``aerosid run`` (RUN_DIR/flight_data.parquet,
RUN_DIR/run.json) and keep the model versions under RUN_DIR/models/.  Register
them with ``main.add_command(...)`` in aerosid/cli.py.  This module only parses
and prints; the work is in aerosid.diagnosis and aerosid.versions.
"""
from __future__ import annotations

from pathlib import Path

import click

_RUN_DIR = click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
_MACH = click.option("--mach-half-width", type=float, default=0.5, show_default=True,
                     help="Use the samples with |M - M_ref| <= this (M_ref from the vehicle file), as the fit does.")

EPILOG_LOOP = """\b
The modelling loop:
  aerosid diagnose runs/ref/result           # where does the model fail, what is missing?
  cat > cm.toml <<EOF
  [Cm]
  terms = ["Cm_0 = 1", "Cm_alpha = alpha", "Cm_delta_p = delta_p/2", "control_alpha"]
  EOF
  aerosid fit runs/ref/result --model cm.toml --note "add control-alpha"
  aerosid diagnose runs/ref/result           # diagnoses the latest version
  aerosid history runs/ref/result            # the error falls version by version
"""


def _errors():
    from aerosid.models import ModelSpecError
    from aerosid.vehicle import VehicleError
    from aerosid.versions import VersionError

    return (ModelSpecError, VersionError, VehicleError)


def _check_run_dir(run_dir: Path) -> None:
    if not run_dir.is_dir():
        raise click.ClickException(f"{run_dir}: no such run folder (make one with `aerosid run TELEMETRY --out "
                                   f"{run_dir}`)")


@click.command(epilog=EPILOG_LOOP)
@_RUN_DIR
@click.option("--model", "model_spec", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Diagnose this model spec (TOML) instead of the latest version.")
@click.option("--version", "version_id", default=None, metavar="vNNN",
              help="Diagnose this stored version instead of the latest.")
@click.option("--windows", "n_windows", type=int, default=8, show_default=True,
              help="Number of time windows for the residual breakdown and the held-out consistency check.")
@_MACH
@click.option("--quiet", is_flag=True, help="Write diagnosis.json without printing the report.")
def diagnose(run_dir, model_spec, version_id, n_windows, mach_half_width, quiet):
    """Compare the model with the measurements and find what it is missing.

    Fits the current model (the latest version under RUN_DIR/models, or the
    default linear models when there is none) to RUN_DIR/flight_data.parquet and
    reports:

    \b
    * model vs measurement per channel: residual RMS, R^2, whiteness
      (autocorrelation, Ljung-Box) and the frequency band holding the residual;
    * where it fails: residual RMS per time window and per regime bin (alpha,
      beta, Mach, qbar, fin deflections, roll angle), worst first;
    * which effect is missing: every candidate physical effect (the simulator's
      catalogue, same names as `aerosid simulate --list-effects`, plus rate
      damping, alpha-dot, Mach and non-linear terms) is added in turn and
      judged by evidence that holds with coloured residuals: the corrected
      partial F and its p-value, the share of residual variance it explains,
      the PSE drop, a leave-one-window-out check, and a check that errors in
      the recovered angles cannot explain it.  It says plainly when nothing
      significant is missing.

    When the candidates that explain the residual are look-alikes (e.g.
    control_alpha and alpha_nonlinearity in Cm), each is fitted and they are
    compared on held-out prediction, the shift each forces on the other
    coefficients and partial residuals; one is recommended only when the
    evidence separates them, else none, with the manoeuvre that would.  Each
    channel's residual is shown against its floor (the flight-derived
    coefficient's own sigma) and the excess over it.

    Writes RUN_DIR/diagnosis.json (effects best first, recommended, lookalikes,
    floor, regimes, time windows, whiteness, message).  Act on the
    recommendation only: add it, `aerosid fit`, and diagnose again.
    """
    _check_run_dir(run_dir)
    from aerosid.diagnosis import diagnose as run_diagnosis
    from aerosid.io import write_json_atomic
    from aerosid.vehicle import load_vehicle
    from aerosid.versions import history, latest_models, models_from_spec, read_flight_data, run_vehicle

    try:
        fd = read_flight_data(run_dir)
        vehicle = load_vehicle(run_vehicle(run_dir))
        if model_spec is not None:
            models = models_from_spec(model_spec, run_dir, version_id)
            source = str(model_spec)
        elif version_id is not None:
            models = dict(history(run_dir).get(version_id).models)
            source = version_id
        else:
            h = history(run_dir)
            models = latest_models(run_dir)
            source = h.latest.id if h.latest else "default models"
        diag = run_diagnosis(fd, vehicle, models, mach_half_width=mach_half_width, n_windows=n_windows)
    except _errors() as exc:
        raise click.ClickException(str(exc)) from exc
    except ValueError as exc:
        raise click.ClickException(f"{run_dir / 'flight_data.parquet'}: {exc}") from exc
    doc = diag.to_json()
    doc["model"] = source
    out = write_json_atomic(doc, run_dir / "diagnosis.json")
    from aerosid.report import write_report

    report = write_report(run_dir, diagnosis=diag)
    if not quiet:
        click.echo(f"model: {source}")
        click.echo(diag.summary())
    click.echo(f"wrote {out} and {report}")


@click.command(epilog=EPILOG_LOOP)
@_RUN_DIR
@click.option("--model", "model_spec", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Model spec TOML: one table per channel, terms = [\"NAME = EXPRESSION\" or a catalogue effect "
                   "name]. Channels it does not mention keep the parent's terms. Default: the default models.")
@click.option("--parent", default=None, metavar="vNNN", help="Parent version (default: the latest).")
@click.option("--note", default="", help="A short note stored with the version (why this change).")
@_MACH
def fit(run_dir, model_spec, parent, note, mach_half_width):
    """Fit a model spec to the run's flight data and keep it as a new version.

    Each version RUN_DIR/models/vNNN/ holds spec.toml, metrics.json (per
    channel: residual RMS, R^2, PSE, F, coefficients and their coloured-residual
    sigma), coefficients.parquet and its parent's id.  The first fit of a run
    also stores v001 = the default linear models, so there is always a baseline
    to compare with.  Versions are never overwritten.

    \b
    Term syntax (SI, radians): "Cm_q = q_hat", "Cm_aa = alpha*abs(alpha)",
    "Cm_step = (sign(mach - 12.2) - sign(mach - 12.35))/2", or a catalogue name
    such as "pitch_damping".  Signals: alpha beta alpha_r phi_r mach V qbar
    delta_p delta_y delta_r p q r p_hat q_hat r_hat t; functions sin cos tan
    arctan tanh exp log sqrt abs sign.
    """
    _check_run_dir(run_dir)
    from aerosid.versions import fit_version, history, models_from_spec

    try:
        models = models_from_spec(model_spec, run_dir, parent) if model_spec is not None else None
        before = history(run_dir)
        v = fit_version(run_dir, models, parent=parent, note=note, mach_half_width=mach_half_width)
        h = history(run_dir)
    except _errors() as exc:
        raise click.ClickException(str(exc)) from exc
    except ValueError as exc:
        raise click.ClickException(f"{run_dir / 'flight_data.parquet'}: {exc}") from exc
    created = [x.id for x in h.versions if x.id not in {y.id for y in before.versions}]
    click.echo(f"created {', '.join(created)}")
    click.echo(v.summary())
    for line in _loud_warnings(v.path / "coefficients.parquet"):
        click.echo(line)
    if v.parent:
        p = h.get(v.parent)
        click.echo(f"changes vs {p.id}: {h.changes(v)}")
        for ch in v.metrics["channels"]:
            a, b = p.channel_metric(ch, "rms_residual"), v.channel_metric(ch, "rms_residual")
            if a > 0:
                click.echo(f"  {ch:<4} residual RMS {a:.4g} -> {b:.4g} ({100 * (b / a - 1):+.1f} %)")
    from aerosid.report import write_report

    click.echo(f"wrote {write_report(run_dir)} (run `aerosid diagnose` to re-diagnose this version)")


def _loud_warnings(coefficients: Path) -> list[str]:
    """Terms that dropped samples and estimates far from their preflight values, from a
    version's coefficients table (the table `aerosid run` prints shows them too)."""
    import pandas as pd

    if not coefficients.is_file():
        return []
    table = pd.read_parquet(coefficients)
    lines = []
    for text in table.drop_duplicates("channel")["warnings"]:
        lines += [f"  warning: {w}" for w in str(text).split(" | ") if "left out of the" in w]
    if "preflight_warning" in table.columns:
        for _, row in table[table["preflight_warning"].fillna("").astype(bool)].iterrows():
            lines.append(f"!! WARNING {row['coefficient']}: {row['preflight_warning']}")
    return lines


@click.command()
@_RUN_DIR
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also write the table (version, parent, changes, note, rank_heldout, rms/heldout/r2/pse per "
                   "channel) as CSV.")
def history(run_dir, csv_path):
    """Show the model versions of a run: what changed and how the error fell.

    One row per version under RUN_DIR/models, best first by held-out
    prediction error: each channel's data are cut into 8 time blocks, the
    model is fitted without a block and predicts it (leave-one-window-out
    RMS; the in-sample residual RMS in brackets).  A look-alike of the true
    term lowers the in-sample RMS almost as much; it predicts unseen blocks
    worse.  Also: the parent and the terms added or removed relative to it
    (R^2, PSE, held-out RMS and the rank in --csv).  Read-only.
    """
    _check_run_dir(run_dir)
    from aerosid.versions import history as read_history

    try:
        h = read_history(run_dir)
    except _errors() as exc:
        raise click.ClickException(str(exc)) from exc
    click.echo(h.summary())
    if csv_path is not None:
        h.table().to_csv(csv_path, index=False)
        click.echo(f"wrote {csv_path}")
