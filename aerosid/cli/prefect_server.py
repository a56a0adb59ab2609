"""Prefect for `aerosid run`: its ephemeral API server, started once per command and
early, or a running server reused.  Imported lazily (the core never loads Prefect)."""
from __future__ import annotations

import sys
from pathlib import Path

import click


class PrefectServer:
    """Prefect's ephemeral API server, started once per command and early: the server
    process starts up while this process imports the flows, and the flow then finds it
    running (SubprocessASGIServer is a per-process singleton).  Nothing is started when
    PREFECT_API_URL names a server, or when a server of the same Prefect version answers
    on Prefect's default address (PREFECT_SERVER_API_HOST:PORT, where `prefect server
    start` listens): it is reused, the cheapest start-up of all.

    The server process writes its own output to PREFECT_HOME/aerosid-server.log rather
    than the terminal: its shutdown used to print ~150 lines of tracebacks after a run's
    clear error.  A server that does not start is a one-line error naming the wait and
    the log (``wait``)."""

    def __init__(self) -> None:
        import threading

        import prefect.settings as ps

        self.thread, self.error, self.reused = None, None, None
        if ps.PREFECT_API_URL.value():
            return
        self.reused = running_server(f"http://{ps.PREFECT_SERVER_API_HOST.value()}:"
                                      f"{ps.PREFECT_SERVER_API_PORT.value()}/api")
        if self.reused:
            return
        from prefect.server.api.server import SubprocessASGIServer

        self.server = SubprocessASGIServer()
        if self.server.running:
            return
        home = Path(ps.PREFECT_HOME.value()).expanduser()
        home.mkdir(parents=True, exist_ok=True)
        self.log = home / "aerosid-server.log"
        self.timeout = int(ps.PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS.value())
        self.launched = threading.Event()
        popen = self.server._run_uvicorn_command

        def launch():  # Popen with descriptors 1 and 2 pointing at the log (the child inherits them)
            import os

            sys.stdout.flush(), sys.stderr.flush()
            saved = [os.dup(1), os.dup(2)]
            try:
                with open(self.log, "ab") as fh:
                    os.dup2(fh.fileno(), 1)
                    os.dup2(fh.fileno(), 2)
                    return popen()
            finally:
                os.dup2(saved[0], 1), os.dup2(saved[1], 2)
                os.close(saved[0]), os.close(saved[1])
                self.launched.set()

        self.server._run_uvicorn_command = launch
        self.thread = threading.Thread(target=self._start, name="aerosid-prefect-server", daemon=True)
        self.thread.start()
        self.launched.wait(timeout=60)  # nothing else writes to 1 and 2 while they point at the log

    def _start(self) -> None:
        try:
            self.server.start(timeout=self.timeout)
        except Exception as exc:  # reported by wait()
            self.error = exc
        finally:
            self.launched.set()

    def settings(self):
        """A context in which flows use the reused server (a no-op otherwise)."""
        from contextlib import nullcontext

        if not self.reused:
            return nullcontext()
        import prefect.settings as ps

        return ps.temporary_settings(updates={ps.PREFECT_API_URL: self.reused})

    def wait(self) -> None:
        if self.thread is None:
            return
        self.thread.join()
        if self.error is not None:
            first = str(self.error).split(" stdout:")[0]
            raise click.ClickException(
                f"Prefect's local API server did not start within {self.timeout} s ({first}); its log: {self.log}. "
                "The machine may be overloaded: try again, raise PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS, "
                "or start one server for many runs (`prefect server start`, then set PREFECT_API_URL)")


def running_server(api_url: str) -> str | None:
    """api_url if a Prefect server of this Prefect's version answers there (e.g. one
    `prefect server start` on its default address), else None.  A refused connection
    costs a millisecond."""
    import httpx
    import prefect

    try:
        with httpx.Client(timeout=10.0) as client:  # a loaded server may take seconds; a refused connection does not
            if client.get(f"{api_url}/health").status_code != 200:
                return None
            version = client.get(f"{api_url}/admin/version").json()
    except (httpx.HTTPError, ValueError):
        return None
    return api_url if str(version) == prefect.__version__ else None
