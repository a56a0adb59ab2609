"""``aerosid audit``: trace a file back to its raw telemetry through the ledger."""
from __future__ import annotations

from pathlib import Path

import click


@click.command()
@click.argument("file", type=click.Path(exists=True, dir_okay=False, path_type=Path))
def audit(file):
    """Trace FILE back to its raw telemetry and parameters through the ledger, and check it.

    Looks for ledger.jsonl in FILE's folder and its parents, finds the stage
    execution that wrote FILE's exact content (SHA-256), then follows its inputs.
    Every file in that lineage is hashed again and compared with what the ledger
    recorded, and the ledger's hash chain is checked: the audit fails naming the
    first file that changed, or the ledger line that was edited.
    """
    from tasks.audit import audit as run_audit

    try:
        result = run_audit(file)
    except OSError as exc:
        raise click.ClickException(f"cannot read {exc.filename or file}: {exc.strerror or exc}") from exc
    click.echo(result.summary())
    if not result.ok:
        raise click.ClickException(f"{file}: audit failed:\n  " + "\n  ".join(result.problems))
