"""Progress display of the command line (rich.progress): stages, segments, ETA.

The core never imports this: its long functions take a plain callback
``progress(stage: str, fraction: float)`` (fraction of that stage done, 0..1) and
the CLI passes one made here.  Stages whose names share the part before ':' run
side by side (``smooth: segment s001``, ``smooth: segment s002``); a stage of
another group starting marks the earlier ones done.

On a terminal (stderr is a TTY) each stage is a bar with its elapsed time and ETA;
elsewhere (CI logs, pipes) one line per stage is written to stderr and nothing else.
``AEROSID_PROGRESS=0`` switches the display off.
"""
from __future__ import annotations

import os
import sys
import threading
import time
from contextlib import contextmanager
from typing import Callable, Iterator

ProgressCallback = Callable[[str, float], None]


def _group(stage: str) -> str:
    return stage.split(":", 1)[0].strip()


class StageProgress:
    """A progress(stage, fraction) callback that draws with rich on a terminal and writes one
    line per stage otherwise.  Thread-safe (Prefect runs tasks in threads)."""

    def __init__(self, title: str, stream=None, live: bool | None = None):
        self.title = title
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = os.environ.get("AEROSID_PROGRESS", "1") not in ("0", "false", "no")
        self.live = (bool(getattr(self.stream, "isatty", lambda: False)()) if live is None else live) and self.enabled
        self._lock = threading.Lock()
        self._tasks: dict[str, object] = {}  # stage -> rich task id (live) or None (lines)
        self._done: set[str] = set()
        self._started = time.monotonic()
        self._rich = None

    # -- context
    def __enter__(self) -> "StageProgress":
        if self.live and self._rich is None:
            from rich.console import Console
            from rich.progress import (BarColumn, Progress, SpinnerColumn, TaskProgressColumn, TextColumn,
                                       TimeElapsedColumn, TimeRemainingColumn)

            self._rich = Progress(SpinnerColumn(), TextColumn(f"[bold]{self.title}[/bold] {{task.description}}"),
                                  BarColumn(), TaskProgressColumn(), TimeElapsedColumn(),
                                  TextColumn("ETA"), TimeRemainingColumn(),
                                  console=Console(file=self.stream), transient=False)
            self._rich.start()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        with self._lock:
            if self._rich is not None:
                if exc_type is None:
                    for stage, task in self._tasks.items():
                        self._rich.update(task, completed=100)
                self._rich.stop()
                self._rich = None

    def close(self) -> None:
        """End the display (as leaving the with block does)."""
        self.__exit__(None, None, None)

    # -- the callback
    def __call__(self, stage: str, fraction: float) -> None:
        if not self.enabled:
            return
        fraction = min(max(float(fraction), 0.0), 1.0)
        with self._lock:
            if stage not in self._tasks:
                for other in list(self._tasks):  # a new group: the earlier groups are done
                    if _group(other) != _group(stage):
                        self._finish(other)
                if self._rich is not None:
                    self._tasks[stage] = self._rich.add_task(stage, total=100)
                else:
                    self._tasks[stage] = None
                    elapsed = time.monotonic() - self._started
                    # written, not print()ed: a Prefect flow with log_prints would turn a print into a log record
                    self.stream.write(f"[{self.title} {elapsed:6.1f} s] {stage}\n")
                    self.stream.flush()
            if self._rich is not None and stage not in self._done:
                self._rich.update(self._tasks[stage], completed=100 * fraction)
            if fraction >= 1.0:
                self._finish(stage)

    def _finish(self, stage: str) -> None:
        if stage in self._done:
            return
        self._done.add(stage)
        if self._rich is not None:
            self._rich.update(self._tasks[stage], completed=100)


@contextmanager
def stage_progress(title: str, stream=None, live: bool | None = None) -> Iterator[StageProgress]:
    """``with stage_progress("simulate") as progress: core_function(..., progress=progress)``."""
    with StageProgress(title, stream, live) as p:
        yield p


class RunProgress(StageProgress):
    """StageProgress for `aerosid run` (events from tasks.progress): also an overall bar over
    every stage execution expected, whose total grows as each flight's segments are planned
    ("plan: <flight>, N segment(s)"), so that its ETA covers the whole run."""

    #: stage executions of a flight besides its segments: preprocess, flight data, regression, report
    FIXED_STAGES = 4

    def __init__(self, title: str = "run", stream=None, live: bool | None = None):
        super().__init__(title, stream, live)
        self._total = self.FIXED_STAGES
        self._finished: set[str] = set()
        self._overall = None

    def __enter__(self) -> "RunProgress":
        super().__enter__()
        if self._rich is not None:
            self._overall = self._rich.add_task("all stages", total=self._total)
        return self

    def __call__(self, stage: str, fraction: float) -> None:
        import re

        if not self.enabled:
            return
        if stage.startswith("plan:") and stage not in self._tasks:  # each flight's plan counted once
            m = re.search(r"(\d+) segment", stage)
            with self._lock:
                self._total += int(m.group(1)) if m else 0
                if self._overall is not None:
                    self._rich.update(self._overall, total=self._total)
        super().__call__(stage, fraction)
        if fraction >= 1.0 and not stage.startswith("plan:") and ":" in stage:
            with self._lock:
                self._finished.add(stage)
                if self._overall is not None:
                    self._rich.update(self._overall, completed=len(self._finished),
                                      description=f"all stages ({len(self._finished)} of {self._total})")

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None and self._overall is not None:
            with self._lock:
                self._rich.update(self._overall, completed=self._total)
        super().__exit__(exc_type, exc, tb)


def quiet_console_logs() -> None:
    """Prefect's console log handlers to WARNING while the progress display reports the stages
    (INFO records still reach Prefect's API; the ledger records every stage).
    AEROSID_PROGRESS=0 keeps Prefect's INFO lines instead of the display."""
    import logging

    if os.environ.get("AEROSID_PROGRESS", "1") in ("0", "false", "no"):
        return
    loggers = [logging.getLogger()] + [v for v in logging.root.manager.loggerDict.values()
                                      if isinstance(v, logging.Logger)]
    for logger in loggers:
        for handler in logger.handlers:
            if type(handler).__name__ == "PrefectConsoleHandler":
                handler.setLevel(max(handler.level, logging.WARNING))
