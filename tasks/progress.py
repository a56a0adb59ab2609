"""Stage progress events of this process, for a display (the CLI's rich bars).

A plain callback registry: ``listening(callback)`` registers ``callback(stage,
fraction)`` while a flow runs in this process; the stage executions call ``emit``
when they start (fraction 0) and end (fraction 1).  Labels: ``"<stage>: <flight>"``
or ``"<stage>: <flight> segment <id>"`` (stages of one kind share the part before
':'), and ``"plan: <flight>, N segment(s)"`` once a flight's segments are known.
Nothing here prints; a listener that raises is ignored (progress never fails a run).
Flows run on Dask workers (campaigns) emit in the workers, where nobody listens.
"""
from __future__ import annotations

import threading
from contextlib import contextmanager
from typing import Callable, Iterator

_LISTENERS: list[Callable[[str, float], None]] = []
_LOCK = threading.Lock()


@contextmanager
def listening(callback: Callable[[str, float], None] | None) -> Iterator[None]:
    if callback is None:
        yield
        return
    with _LOCK:
        _LISTENERS.append(callback)
    try:
        yield
    finally:
        with _LOCK:
            _LISTENERS.remove(callback)


def emit(stage: str, fraction: float) -> None:
    with _LOCK:
        listeners = list(_LISTENERS)
    for callback in listeners:
        try:
            callback(stage, fraction)
        except Exception:  # a display must never fail a stage
            pass


def label(stage: str, flight: str, segment: str = "") -> str:
    return f"{stage}: {flight}" + (f" segment {segment}" if segment else "")
