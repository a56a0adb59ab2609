"""The modelling-loop commands: ``aerosid diagnose``, ``aerosid fit``, ``aerosid history``.

They read a run folder written by ``aerosid run`` (RUN_DIR/flight_data.parquet,
RUN_DIR/run.json) and keep the model versions under RUN_DIR/models/.  Register
them with ``main.add_command(...)`` in aerosid/cli.py.  This module only parses
and prints; the work is in aerosid.diagnosis and aerosid.modelling.versions.
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
  add = ["control_alpha"]      # the lines the diagnosis prints; the other terms stay
  EOF
  aerosid fit runs/ref/result --model cm.toml --note "add control-alpha"
  aerosid diagnose runs/ref/result           # diagnoses the latest version
  aerosid history runs/ref/result            # the error falls version by version
"""


def _errors():
    from aerosid.modelling.models import ModelSpecError
    from aerosid.vehicles.vehicle import VehicleError
    from aerosid.modelling.versions import VersionError

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
    channel's residual is shown against its floor (what a complete model would
    leave: the flight-derived coefficient's own error and the recovered angles'
    error through the model) and the excess over it.

    Writes RUN_DIR/diagnosis.json (effects best first, recommended, lookalikes,
    floor, regimes, time windows, whiteness, message).  Act on the
    recommendation only: add it, `aerosid fit`, and diagnose again.
    """
    _check_run_dir(run_dir)
    from aerosid.cli.progress import StageProgress
    from aerosid.diagnosis import diagnose as run_diagnosis
    from aerosid.io import write_json_atomic
    from aerosid.vehicles.vehicle import load_vehicle
    from aerosid.modelling.versions import history, latest_models, read_flight_data, run_vehicle, spec_for_run

    spec_warnings: list[str] = []
    progress = StageProgress("diagnose").__enter__()
    try:
        progress("read the flight data", 0.0)
        fd = read_flight_data(run_dir)
        vehicle = load_vehicle(run_vehicle(run_dir))
        if model_spec is not None:
            spec = spec_for_run(model_spec, run_dir, version_id)
            models, spec_warnings = spec.models, spec.warnings()
            source = str(model_spec)
        elif version_id is not None:
            models = dict(history(run_dir).get(version_id).models)
            source = version_id
        else:
            h = history(run_dir)
            models = latest_models(run_dir)
            source = h.latest.id if h.latest else "default models"
        diag = run_diagnosis(fd, vehicle, models, mach_half_width=mach_half_width, n_windows=n_windows,
                             progress=progress)
    except _errors() as exc:
        progress.close()
        raise click.ClickException(str(exc)) from exc
    except ValueError as exc:
        progress.close()
        raise click.ClickException(f"{run_dir / 'flight_data.parquet'}: {exc}") from exc
    except BaseException:
        progress.close()
        raise
    doc = diag.to_json()
    doc["model"] = source
    out = write_json_atomic(doc, run_dir / "diagnosis.json")
    from aerosid.modelling.loop import run_truth
    from aerosid.report import write_report

    with progress:
        progress("write report.html", 0.0)
        report = write_report(run_dir, diagnosis=out, version=version_id, truth=run_truth(run_dir))  # chosen, else latest
    for line in spec_warnings:  # e.g. the parent's terms a terms = [...] list dropped
        click.echo(line)
    if not quiet:
        click.echo(f"model: {source}")
        click.echo(diag.summary())
    click.echo(f"wrote {out} and {report}")


_PER_DEGREE = click.option("--per-degree", is_flag=True,
                           help="Print coefficients per degree (angle and control slopes per deg, fin slopes per "
                                "degree pair, rate derivatives per deg/s) instead of SI per radian.")


@click.command(epilog=EPILOG_LOOP)
@_RUN_DIR
@click.option("--model", "model_spec", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Model spec TOML, one table per channel: add = [...] / remove = [...] change the parent's "
                   "terms; terms = [...] replaces them (and says which it drops). A term is \"NAME = EXPRESSION\" "
                   "or a candidate's name (e.g. control_alpha, mach_cm0, roll_damping). Channels it does not "
                   "mention keep the parent's terms. Default: the default models.")
@click.option("--parent", default=None, metavar="vNNN", help="Parent version (default: the latest).")
@click.option("--note", default="", help="A short note stored with the version (why this change).")
@_MACH
@_PER_DEGREE
def fit(run_dir, model_spec, parent, note, mach_half_width, per_degree):
    """Fit a model spec to the run's flight data and keep it as a new version.

    Prints every term's estimate, sigma (corrected for coloured residuals), t and
    p per channel, and warns on terms that are not significant (p >= 0.001).
    Each version RUN_DIR/models/vNNN/ holds spec.toml, metrics.json (per
    channel: residual RMS, R^2, PSE, F, coefficients and their coloured-residual
    sigma), coefficients.parquet and its parent's id.  The first fit of a run
    also stores v001 = the default linear models, so there is always a baseline
    to compare with.  Versions are never overwritten.

    \b
    A spec relative to the parent version (the latest, or --parent):
      [Cm]
      add = ["control_alpha", "Cm_a3 = alpha**3"]
      remove = ["Cm_0"]

    \b
    Term syntax (SI, radians): "Cm_q = q_hat", "Cm_aa = alpha*abs(alpha)",
    "Cm_step = (sign(mach - 12.2) - sign(mach - 12.35))/2", or a candidate
    name such as "pitch_damping".  Signals: alpha beta alpha_r phi_r mach V qbar
    delta_p delta_y delta_r p q r p_hat q_hat r_hat alpha_dot_hat beta_dot_hat t;
    functions sin cos tan arctan tanh exp log sqrt abs sign.
    """
    _check_run_dir(run_dir)
    from aerosid.cli.progress import stage_progress
    from aerosid.modelling.versions import fit_version, history, spec_for_run

    try:
        with stage_progress("fit") as progress:
            progress("read the model spec", 0.0)
            spec = spec_for_run(model_spec, run_dir, parent) if model_spec is not None else None
            before = history(run_dir)
            progress("fit the model", 0.0)
            v = fit_version(run_dir, spec.models if spec else None, parent=parent, note=note,
                            mach_half_width=mach_half_width)
            h = history(run_dir)
    except _errors() as exc:
        raise click.ClickException(str(exc)) from exc
    except ValueError as exc:
        raise click.ClickException(f"{run_dir / 'flight_data.parquet'}: {exc}") from exc
    created = [x.id for x in h.versions if x.id not in {y.id for y in before.versions}]
    click.echo(f"created {', '.join(created)}")
    click.echo(v.summary())
    p = h.get(v.parent) if v.parent else None
    _echo_terms(v, p, per_degree)
    for line in _loud_warnings(v.path / "coefficients.parquet"):
        click.echo(line)
    if p is not None:
        click.echo(f"changes vs {p.id}: {h.changes(v)}")
        for ch in v.metrics["channels"]:
            a, b = p.channel_metric(ch, "rms_residual"), v.channel_metric(ch, "rms_residual")
            if a > 0:
                click.echo(f"  {ch:<4} residual RMS {a:.4g} -> {b:.4g} ({100 * (b / a - 1):+.1f} %)")
    for line in spec.warnings() if spec else ():  # e.g. the parent's terms a terms = [...] list dropped
        click.echo(line)
    with stage_progress("report") as progress:
        progress("diagnose and write report.html", 0.0)
        _diagnose_and_report(run_dir, v.id, mach_half_width)


def _diagnose_and_report(run_dir: Path, version: str, mach_half_width) -> None:
    """After a fit: diagnose the new version and write diagnosis.json and report.html for it."""
    from aerosid.modelling.loop import diagnose_and_report
    from aerosid.report import write_report

    try:
        paths = diagnose_and_report(run_dir, version, mach_half_width=mach_half_width)
    except _errors() + (ValueError,) as exc:  # e.g. too few samples to diagnose: the fit itself stands
        click.echo(f"could not diagnose {version}: {exc}")
        click.echo(f"wrote {write_report(run_dir, version=version)} (its diagnosis section is of an older model)")
        return
    click.echo(f"wrote {paths['diagnosis']} (diagnosis of {version}: `aerosid diagnose {run_dir}` prints it) and "
               f"{paths['report']}")


def _echo_terms(v, parent, per_degree: bool) -> None:
    """Every term's estimate, sigma, t, p and significance, then a warning per term that is not significant."""
    import pandas as pd

    from aerosid.identification.term_report import significance_warnings, term_table

    path = v.path / "coefficients.parquet"
    if not path.is_file():
        return
    table = pd.read_parquet(path)
    new = frozenset()
    if parent is not None:
        old = {(ch, t.coefficient, t.expression) for ch, m in parent.models.items() for t in m.terms}
        new = frozenset(t.coefficient for ch, m in v.models.items() for t in m.terms
                        if (ch, t.coefficient, t.expression) not in old)
    click.echo(term_table(table, per_degree=per_degree, new_terms=new))
    for line in significance_warnings(table):
        click.echo(f"warning: {line}")


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
@click.option("--against", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
              metavar="TELEMETRY",
              help="Also simulate this manoeuvre (another flight of the vehicle, or the run's own telemetry; with "
                   "phi_rad, theta_rad) with every version, as aerosid validate does (lon axis), and list the "
                   "simulated alpha, q, a_z errors: look-alike terms that the equation error cannot tell apart "
                   "often predict differently.")
def history(run_dir, csv_path, against):
    """Show the model versions of a run: what changed and how the error fell.

    One row per version under RUN_DIR/models, best first by held-out
    prediction error: each channel's data are cut into 8 time blocks, the
    model is fitted without a block and predicts it (leave-one-window-out
    RMS; the in-sample residual RMS in brackets).  A look-alike of the true
    term lowers the in-sample RMS almost as much; it predicts unseen blocks
    worse.  Also: the parent and the terms added or removed relative to it
    (R^2, PSE, held-out RMS and the rank in --csv).  With --against TELEMETRY,
    every version is also simulated on that manoeuvre (as aerosid validate
    does, longitudinal axis): a missing term shows far more in the simulated
    alpha than in the residual.  Read-only.
    """
    _check_run_dir(run_dir)
    from aerosid.modelling.versions import history as read_history

    try:
        h = read_history(run_dir)
    except _errors() as exc:
        raise click.ClickException(str(exc)) from exc
    click.echo(h.summary())
    if csv_path is not None:
        h.table().to_csv(csv_path, index=False)
        click.echo(f"wrote {csv_path}")
    if against is not None and h.versions:
        from aerosid.identification.identified import ModelSourceError
        from aerosid.identification.validate import compare_versions, version_comparison_text

        from aerosid.cli.progress import stage_progress

        try:
            with stage_progress("history") as progress:
                frame = compare_versions(run_dir, against, [v.id for v in h.versions], progress=progress)
        except (ValueError, ModelSourceError, *_errors()) as exc:
            raise click.ClickException(str(exc)) from exc
        click.echo(version_comparison_text(frame, against, {v.id: h.changes(v) for v in h.versions}))
