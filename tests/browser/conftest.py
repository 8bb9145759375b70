"""Browser tests of the operator console: ``frictionlab run`` in a subprocess, Debian's chromium
driven by Playwright (``scripts/install-system-deps`` installs chromium when it is missing).

The page runs under its own strict Content-Security-Policy (no ``bypass_csp``); waits poll the
page's state (``window.__console``) or use Playwright's auto-waiting assertions, never fixed
sleeps.

A loop that stopped is a failure, with one documented exception (docs/development.md, "A busy
machine"): a trial that the loop's own host-stall stop ended (:data:`HOST_STALL_STOPS`) is
run again, at most :data:`MAX_STALL_RETRIES` times, with a warning in pytest's summary
(:func:`retry_host_stalls`).  Any other stop - the safety stop a test checks included - fails
at once, and a test that finds the loop stopped fails (:func:`assert_running`) rather than
starting it again.
"""

from __future__ import annotations

import json
import os
import queue
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
import urllib.request
import warnings
from pathlib import Path
from urllib.parse import urlsplit

import pytest

CHROMIUM = os.environ.get("FRICTIONLAB_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]
STARTUP_TIMEOUT = 60.0
_URL = re.compile(r"frictionlab console: (http://\S+)")
#: The stops of a stalled host (the loop's safety stop when it was not running for longer than
#: its slack): the only ones after which a browser test runs its trial again.
HOST_STALL_STOPS = ("paused", "rig_silent")
#: How many times a trial is run again after a host-stall stop.
MAX_STALL_RETRIES = 2


class LoopStopped(AssertionError):
    """The loop stopped while a test needed it running; ``reason`` is its stop reason."""

    def __init__(self, reason: str | None, detail: str | None = ""):
        super().__init__(f"the loop stopped: {reason} {detail or ''}".rstrip())
        self.reason = reason
        self.detail = detail


class HostStallWarning(UserWarning):
    """A browser test's trial ran again after a host-stall stop (how often, in the summary)."""


def check_running(st: dict) -> dict:
    """``st`` (a status), or :class:`LoopStopped` with its stop reason if the loop stopped."""
    if not st.get("running"):
        raise LoopStopped(st.get("stop_reason"), st.get("stop_detail"))
    return st


def retry_host_stalls(trial, restart, what: str):
    """``trial()``'s result; after a :class:`LoopStopped` with a host-stall reason
    (:data:`HOST_STALL_STOPS`), warn, ``restart()`` and run it again, at most
    :data:`MAX_STALL_RETRIES` times; any other stop (or one retry too many) is raised."""
    for attempt in range(MAX_STALL_RETRIES + 1):
        try:
            return trial()
        except LoopStopped as stop:
            if stop.reason not in HOST_STALL_STOPS or attempt == MAX_STALL_RETRIES:
                raise
            # shown in pytest's warnings summary: how often a host stalls this long
            warnings.warn(HostStallWarning(f"{what}: a stalled host stopped the loop "
                                           f"({stop.reason}: {stop.detail}); run again"),
                          stacklevel=2)
            restart()
    raise AssertionError("unreachable")


class ConsoleProcess:
    """``frictionlab run`` serving the console, its printed address and its output.

    The server binds port 0 (the kernel picks a free one, no race with other
    processes) and the port is read from the address it prints.
    """

    def __init__(self, log_dir: Path, *args: str, env: dict | None = None):
        self.log_dir = log_dir
        cmd = [sys.executable, "-m", "frictionlab", "run", "--port", "0",
               "--log-dir", str(log_dir), *args]
        full_env = {k: v for k, v in os.environ.items() if k != "FRICTIONLAB_TOKEN"}
        full_env.update({"PYTHONUNBUFFERED": "1", **(env or {})})
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, env=full_env)
        self.lines: queue.Queue[str] = queue.Queue()
        self.stdout: list[str] = []
        self.stderr: list[str] = []
        threading.Thread(target=self._pump, args=(self.proc.stdout, self.stdout, True),
                         daemon=True).start()
        threading.Thread(target=self._pump, args=(self.proc.stderr, self.stderr, False),
                         daemon=True).start()
        self.url: str | None = None

    def _pump(self, stream, sink: list, announce: bool) -> None:
        for line in stream:
            sink.append(line)
            if announce:
                self.lines.put(line)

    def wait_url(self, timeout: float = STARTUP_TIMEOUT) -> str:
        """The address ``frictionlab run`` printed on start."""
        deadline = time.monotonic() + timeout
        while self.url is None:
            left = deadline - time.monotonic()
            if left <= 0 or self.proc.poll() is not None:
                raise AssertionError(f"no console address printed; stderr: {''.join(self.stderr)}")
            try:
                line = self.lines.get(timeout=min(left, 0.5))
            except queue.Empty:
                continue
            m = _URL.search(line)
            if m:
                self.url = m.group(1)
        return self.url

    @property
    def port(self) -> int:
        """The port the server bound (from the printed address)."""
        port = urlsplit(self.wait_url()).port
        assert port, self.url
        return port

    @property
    def base(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def get(self, path: str, token: str | None = None) -> tuple[int, dict]:
        req = urllib.request.Request(self.base + path)
        if token:
            req.add_header("Authorization", f"Bearer {token}")
        try:
            with urllib.request.urlopen(req, timeout=10) as resp:
                return resp.status, json.loads(resp.read())
        except urllib.error.HTTPError as exc:
            return exc.code, json.loads(exc.read() or b"{}")

    def post(self, path: str, body: dict, token: str | None = None) -> tuple[int, dict]:
        req = urllib.request.Request(self.base + path, data=json.dumps(body).encode(),
                                     method="POST",
                                     headers={"Content-Type": "application/json"})
        if token:
            req.add_header("Authorization", f"Bearer {token}")
        try:
            with urllib.request.urlopen(req, timeout=10) as resp:
                return resp.status, json.loads(resp.read())
        except urllib.error.HTTPError as exc:
            return exc.code, json.loads(exc.read() or b"{}")

    def wait_running(self, token: str | None = None, timeout: float = STARTUP_TIMEOUT) -> dict:
        """Poll the status until the loop runs and has ticked."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                break
            try:
                code, st = self.get("/api/status", token)
            except OSError:
                code, st = 0, {}
            if code == 200 and st.get("running") and st.get("ticks", 0) > 0:
                return st
            time.sleep(0.1)  # polling interval, not a timing assumption
        raise AssertionError(f"the loop did not start; stderr: {''.join(self.stderr)}")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)


def wait_until(predicate, timeout: float = 30.0, interval: float = 0.1, what: str = ""):
    """Poll ``predicate()`` until it returns a truthy value; return it."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what or predicate}")
        time.sleep(interval)


@pytest.fixture(scope="module")
def browser():
    """Chromium for one test module (Playwright's sync API runs an event loop of its own:
    it is stopped before the rest of the suite runs)."""
    if not Path(CHROMIUM).exists() and shutil.which("chromium") is None:
        raise AssertionError("chromium is missing: run scripts/install-system-deps as root "
                             "(apt-get install -y chromium)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM if Path(CHROMIUM).exists()
                               else shutil.which("chromium"), args=CHROMIUM_ARGS)
        try:
            yield b
        finally:
            b.close()
