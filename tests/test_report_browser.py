"""The report in a real headless browser (Debian's chromium, driven over the Chrome
DevTools Protocol): it loads from file:// with no console error, no exception and
no failed request, every plot is rendered with a size, and the tables are there.

CI installs chromium in .ci/run; elsewhere the test is skipped when
/usr/bin/chromium is absent.  Nothing leaves the machine: the page is a local
file and background networking is off.
"""
from __future__ import annotations

import itertools
import json
import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest

from tests.test_report import report_run  # noqa: F401  (the shared run folder, built once per session)

CHROMIUM = Path("/usr/bin/chromium")

pytestmark = [pytest.mark.prefect,
              pytest.mark.skipif(not CHROMIUM.exists(), reason="Debian's chromium is not installed at /usr/bin/chromium "
                                 "(apt-get install chromium; .ci/run does it in CI)")]

FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--remote-debugging-port=0"]


class Browser:
    """Headless chromium with one page, driven over a flattened CDP session."""

    def __init__(self, profile: Path, timeout_s: float = 60.0):
        self.timeout_s = timeout_s
        self.profile = profile
        self.log = open(profile.parent / "chromium.log", "wb")
        self.proc = subprocess.Popen([str(CHROMIUM), *FLAGS, f"--user-data-dir={profile}", "about:blank"],
                                     stdout=self.log, stderr=subprocess.STDOUT, start_new_session=True)
        self.ws = None
        self.session = None
        self.events: list[dict] = []
        self._ids = itertools.count(1)

    def connect(self) -> None:
        from websockets.sync.client import connect

        port_file = self.profile / "DevToolsActivePort"
        deadline = time.monotonic() + self.timeout_s
        while True:
            lines = port_file.read_text().split() if port_file.is_file() else []
            if len(lines) >= 2:
                break
            if self.proc.poll() is not None:
                raise RuntimeError(f"chromium exited with {self.proc.returncode}: {self._log_tail()}")
            if time.monotonic() > deadline:
                raise TimeoutError(f"chromium wrote no DevToolsActivePort in {self.timeout_s:.0f} s: {self._log_tail()}")
            time.sleep(0.05)
        port, path = lines[0], lines[1]
        self.ws = connect(f"ws://127.0.0.1:{port}{path}", max_size=None, open_timeout=self.timeout_s)
        target = self.call("Target.createTarget", {"url": "about:blank"}, session=False)["targetId"]
        self.session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True},
                                 session=False)["sessionId"]

    def _log_tail(self) -> str:
        self.log.flush()
        text = (self.profile.parent / "chromium.log").read_bytes().decode(errors="replace")
        return text[-2000:]

    def _recv(self, deadline: float) -> dict:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise TimeoutError("no answer from chromium in time")
        msg = json.loads(self.ws.recv(timeout=remaining))
        if "method" in msg:
            self.events.append(msg)
        return msg

    def call(self, method: str, params: dict | None = None, session: bool = True) -> dict:
        mid = next(self._ids)
        msg = {"id": mid, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = self.session
        self.ws.send(json.dumps(msg))
        deadline = time.monotonic() + self.timeout_s
        while True:
            reply = self._recv(deadline)
            if reply.get("id") == mid:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})

    def wait_for(self, method: str) -> dict:
        deadline = time.monotonic() + self.timeout_s
        for ev in self.events:
            if ev["method"] == method:
                return ev
        while True:
            msg = self._recv(deadline)
            if msg.get("method") == method:
                return msg

    def drain(self, seconds: float) -> None:
        """Collect the events that arrive within `seconds` (late console messages)."""
        deadline = time.monotonic() + seconds
        while True:
            try:
                self._recv(deadline)
            except TimeoutError:
                return

    def evaluate(self, expression: str):
        res = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True})
        if "exceptionDetails" in res:
            raise RuntimeError(f"{expression}: {res['exceptionDetails']}")
        return res["result"].get("value")

    def close(self) -> None:
        try:
            if self.ws is not None:
                self.ws.close()
        finally:
            if self.proc.poll() is None:
                try:
                    os.killpg(self.proc.pid, signal.SIGTERM)  # chromium's own process group (start_new_session)
                    self.proc.wait(timeout=10)
                except (subprocess.TimeoutExpired, ProcessLookupError):
                    os.killpg(self.proc.pid, signal.SIGKILL)
                    self.proc.wait(timeout=10)
            self.log.close()


def problems(events: list[dict]) -> list[str]:
    """Console errors/warnings, uncaught exceptions, error log entries and failed loads."""
    out = []
    for ev in events:
        m, p = ev["method"], ev.get("params", {})
        if m == "Runtime.consoleAPICalled" and p.get("type") in ("error", "warning", "assert"):
            out.append(f"console.{p['type']}: {[a.get('value', a.get('description')) for a in p.get('args', [])]}")
        elif m == "Runtime.exceptionThrown":
            out.append(f"exception: {p.get('exceptionDetails', {}).get('text')}")
        elif m == "Log.entryAdded" and p.get("entry", {}).get("level") == "error":
            out.append(f"log error: {p['entry'].get('text')} ({p['entry'].get('url', '')})")
        elif m == "Network.loadingFailed":
            out.append(f"loading failed: {p.get('errorText')}")
        elif m == "Network.requestWillBeSent":
            url = p.get("request", {}).get("url", "")
            if not url.startswith(("file:", "data:", "about:")):
                out.append(f"network request: {url}")
    return out


def load_report(tmp_path: Path, report: Path) -> tuple[Browser, list[str]]:
    profile = tmp_path / "chromium-profile"
    profile.mkdir()
    browser = Browser(profile)
    browser.connect()
    for domain in ("Runtime", "Log", "Page", "Network"):
        browser.call(f"{domain}.enable")
    browser.call("Page.navigate", {"url": report.resolve().as_uri()})
    browser.wait_for("Page.loadEventFired")
    browser.drain(0.5)
    return browser, problems(browser.events)


def test_report_opens_in_a_headless_browser_without_errors(report_run, tmp_path):
    from aerosid.report import write_report

    run_dir, diag, truth = report_run
    work = tmp_path / "run"
    shutil.copytree(run_dir, work)
    report = write_report(work, diagnosis=diag, truth=truth)
    expected_svgs = report.read_text().count("<svg")
    assert expected_svgs >= 7  # >= 1 segment + 5 channels + versions

    browser = None
    try:
        browser, found = load_report(tmp_path, report)
        assert found == [], "\n".join(found)
        assert browser.evaluate("document.readyState") == "complete"
        assert browser.evaluate("document.querySelectorAll('svg').length") >= expected_svgs
        boxes = browser.evaluate("Array.from(document.querySelectorAll('svg')).map(s => {"
                                 "const r = s.getBoundingClientRect(); return [r.width, r.height]; })")
        assert len(boxes) == expected_svgs
        assert all(w > 50 and h > 50 for w, h in boxes), boxes
        # every plot has drawn paths (not an empty element)
        assert browser.evaluate("Array.from(document.querySelectorAll('svg')).every(s => "
                                "s.querySelectorAll('path').length > 5)")
        n_rows = browser.evaluate("document.querySelectorAll('table#coefficients tbody tr').length")
        assert n_rows >= 16 + 5  # 16 coefficients + one header row per channel
        assert browser.evaluate("document.querySelector('#coefficients').getBoundingClientRect().height") > 100
        assert "CN_alpha" in browser.evaluate("document.querySelector('#coefficients').innerText")
        assert browser.evaluate("!!document.querySelector('#effects-table')")
        assert browser.evaluate("!!document.querySelector('#versions-table')")
        assert browser.evaluate("document.scripts.length") == 0
        assert browser.evaluate("document.title").startswith("aerosid report")
        # no resource was fetched other than the file itself
        assert browser.evaluate("performance.getEntriesByType('resource').length") == 0
    finally:
        if browser is not None:
            browser.close()


def test_minimal_report_opens_without_errors(report_run, tmp_path):
    """A run folder with no diagnosis, no versions, and a hostile flight id."""
    from aerosid.report import write_report

    run_dir, _, _ = report_run
    work = tmp_path / "run"
    shutil.copytree(run_dir, work, ignore=shutil.ignore_patterns("diagnosis.json", "models"))
    doc = json.loads((work / "run.json").read_text())
    doc["flight"] = "<script>console.error('injected')</script>"
    (work / "run.json").write_text(json.dumps(doc))
    report = write_report(work)
    browser = None
    try:
        browser, found = load_report(tmp_path, report)
        assert found == [], "\n".join(found)
        assert browser.evaluate("document.scripts.length") == 0
        assert "<script>" in browser.evaluate("document.title")  # shown as text, not run
        assert browser.evaluate("document.querySelectorAll('svg').length") >= 6
    finally:
        if browser is not None:
            browser.close()


def test_report_after_two_fits_shows_the_latest_version(report_run, tmp_path):
    """run -> fit (v002) -> fit (v003) with the CLI: the report the second fit writes shows
    v003's coefficients, its measured-vs-model and residual plots, and its diagnosis."""
    import math

    import pandas as pd
    from click.testing import CliRunner

    from aerosid.cli import main

    run_dir, _, _ = report_run
    work = tmp_path / "run"  # as `aerosid run` left it: v001 (the default models) and its diagnosis
    shutil.copytree(run_dir, work, ignore=shutil.ignore_patterns("v002", "report.html"))
    base = '"Cm_0 = 1", "Cm_alpha = alpha", "Cm_delta_p = delta_p/2", "pitch_damping"'
    specs = {"v002": f"[Cm]\nterms = [{base}]\n", "v003": f'[Cm]\nterms = [{base}, "Cm_a3 = alpha**3"]\n'}
    for version, text in specs.items():
        spec = tmp_path / f"{version}.toml"
        spec.write_text(text)
        result = CliRunner().invoke(main, ["fit", str(work), "--model", str(spec), "--note", version])
        assert result.exit_code == 0, result.output
        assert f"created {version}" in result.output and f"diagnosis of {version}" in result.output
    assert json.loads((work / "diagnosis.json").read_text())["model"] == "v003"
    table = pd.read_parquet(work / "models" / "v003" / "coefficients.parquet").set_index("coefficient")
    cm_alpha = format(table.loc["Cm_alpha", "estimate"] * math.pi / 180, ".5g")
    old_alpha = pd.read_parquet(work / "models" / "v001" / "coefficients.parquet").set_index("coefficient")
    assert format(old_alpha.loc["Cm_alpha", "estimate"] * math.pi / 180, ".5g") != cm_alpha
    report = work / "report.html"
    browser = None
    try:
        browser, found = load_report(tmp_path, report)
        assert found == [], "\n".join(found)
        text = browser.evaluate("document.body.innerText")
        assert "Model shown: model version v003 (the latest)" in text
        assert browser.evaluate("document.querySelector('#diagnosed-model').innerText") == "v003"
        assert not browser.evaluate("!!document.querySelector('#diagnosis-stale')")
        coef = browser.evaluate("document.querySelector('#coefficients').innerText")
        assert "Cm_a3" in coef and "Cm_q" in coef and cm_alpha in coef
        labels = browser.evaluate("Array.from(document.querySelectorAll('svg')).map(s => s.getAttribute('aria-label'))")
        for ch in ("Cm", "Cn", "Cl"):
            assert f"{ch}: measured vs model v003 (top) and residual (bottom) against time" in labels
            assert any(lab.startswith(f"{ch}, model v003: partial residuals") for lab in labels)
        assert not any("v001" in lab or "v002" in lab for lab in labels if "model v" in lab)
        boxes = browser.evaluate("Array.from(document.querySelectorAll('svg')).map(s => {"
                                 "const r = s.getBoundingClientRect(); return [r.width, r.height]; })")
        assert all(w > 50 and h > 50 for w, h in boxes), boxes
        rows = browser.evaluate("Array.from(document.querySelectorAll('#versions-table tbody tr'))"
                                ".map(r => r.cells[0].innerText)")
        assert [r.replace("└─", "").replace("◀ shown", "").strip() for r in rows] == ["v001", "v002", "v003"]
        assert "shown" in rows[-1]
    finally:
        if browser is not None:
            browser.close()
