"""The ``aerosid`` command group (``main``, the console script ``aerosid.cli:main``) and
its commands, one module each in aerosid/cli/.

The CLI only parses arguments and prints; the work happens in the core
(``aerosid.*``) or, for ``run``, in the Prefect flows (imported lazily so the
core never loads Prefect).
"""
from __future__ import annotations

import sys

import click


class _NoTracebackGroup(click.Group):
    """The command group: an error no command turned into a message still reaches the
    user as one `Error: ...` line, never as a traceback (AEROSID_TRACEBACK=1 re-raises
    it, for debugging)."""

    def invoke(self, ctx):
        import os

        try:
            return super().invoke(ctx)
        except (click.exceptions.ClickException, click.exceptions.Exit, click.exceptions.Abort):
            raise
        except RecursionError as exc:
            if os.environ.get("AEROSID_TRACEBACK"):
                raise
            raise click.ClickException("an input is nested too deeply to be read (RecursionError); check the "
                                       "TOML and Parquet files given") from exc
        except Exception as exc:
            if os.environ.get("AEROSID_TRACEBACK"):
                raise
            raise click.ClickException(f"{type(exc).__name__}: {exc} (unexpected; AEROSID_TRACEBACK=1 shows "
                                       "where it came from)") from exc


@click.group(cls=_NoTracebackGroup,
             context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
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


from aerosid.cli.audit import audit  # noqa: E402  (the commands, one module each)
from aerosid.cli.design import design  # noqa: E402
from aerosid.cli.import_ import import_group  # noqa: E402  (aerosid import sidpac|csv)
from aerosid.cli.modelling import diagnose, fit, history  # noqa: E402  (the modelling loop)
from aerosid.cli.refine import refine  # noqa: E402  (output-error refinement)
from aerosid.cli.run import run  # noqa: E402
from aerosid.cli.simulate import simulate  # noqa: E402
from aerosid.cli.validate import validate  # noqa: E402  (predict another manoeuvre)

for _command in (simulate, run, audit, diagnose, fit, history, import_group, validate, refine, design):
    main.add_command(_command)

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
