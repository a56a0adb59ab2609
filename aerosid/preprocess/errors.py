"""TelemetryError: bad raw telemetry, named by file, column and rows.

Kept in a leaf module without dependencies so that ``schemas.telemetry`` can
raise it without an import cycle.  (It may move to ``aerosid/errors.py`` later;
``aerosid.preprocess.TelemetryError`` will stay importable.)
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence

#: How many row indices an error message lists before it abbreviates.
MAX_ROWS_IN_MESSAGE = 10


def _format_rows(rows: Sequence[int]) -> str:
    shown = ", ".join(str(r) for r in rows[:MAX_ROWS_IN_MESSAGE])
    more = len(rows) - MAX_ROWS_IN_MESSAGE
    return f"[{shown}{f', ... (+{more} more)' if more > 0 else ''}]"


class TelemetryError(ValueError):
    """Raw telemetry that cannot be preprocessed (or a frame that violates a schema).

    Attributes
    ----------
    file:
        The source the frame came from (a path, or ``"<memory>"``).
    column:
        The offending column, or ``None`` when the problem is not one column's
        (e.g. an empty frame).
    rows:
        0-based positional row indices of the offending rows in the frame as it was
        given (list; may be empty).  The message lists at most the first
        :data:`MAX_ROWS_IN_MESSAGE`.
    reason:
        The bare explanation without the file/column/rows prefix.
    """

    def __init__(
        self,
        reason: str,
        *,
        file: str = "<memory>",
        column: str | None = None,
        rows: Iterable[int] = (),
    ) -> None:
        self.reason = reason
        self.file = str(file)
        self.column = column
        self.rows = [int(r) for r in rows]
        where = [f"file {self.file!r}"]
        if column is not None:
            where.append(f"column {column!r}")
        if self.rows:
            where.append(f"rows {_format_rows(self.rows)}")
        super().__init__(f"{', '.join(where)}: {reason}")

    def __reduce__(self):  # keyword-only arguments: make pickling (Prefect, multiprocessing) work
        return (_rebuild_telemetry_error, (self.reason, self.file, self.column, self.rows))


def _rebuild_telemetry_error(reason: str, file: str, column: str | None, rows: list[int]) -> TelemetryError:
    return TelemetryError(reason, file=file, column=column, rows=rows)
