"""Access control of ``frictionlab run``'s console, against the real server (and a browser)."""

from __future__ import annotations

import json
import secrets
import urllib.request

import pytest
from playwright.sync_api import expect
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from .conftest import ConsoleProcess, wait_until

# a browser and a console server: slow; the tests share the console and go on from
# each other's state, so under pytest-xdist they run in one worker, in order
pytestmark = [pytest.mark.timeout(120), pytest.mark.slow, pytest.mark.xdist_group("browser")]


def test_non_loopback_bind_without_token_is_refused(tmp_path):
    proc = ConsoleProcess(tmp_path, "--host", "0.0.0.0")
    try:
        assert proc.proc.wait(60) == 2
    finally:
        proc.stop()
    err = "".join(proc.stderr)
    assert "needs a token" in err and "--token" in err
    assert not any("frictionlab console:" in line for line in proc.stdout)


def test_token_from_the_environment_is_checked(tmp_path):
    proc = ConsoleProcess(tmp_path, "--host", "0.0.0.0", env={"FRICTIONLAB_TOKEN": "short"})
    try:
        assert proc.proc.wait(60) == 2
    finally:
        proc.stop()
    assert "at least 8 characters" in "".join(proc.stderr)


TOKEN = secrets.token_urlsafe(16)


@pytest.fixture(scope="module")
def guarded(tmp_path_factory):
    # --token=VALUE: a urlsafe token starts with "-" one time in 64, which argparse
    # would take for an option after a separate "--token"
    proc = ConsoleProcess(tmp_path_factory.mktemp("guarded"), "--host", "0.0.0.0",
                          f"--token={TOKEN}")
    try:
        proc.wait_url()
        proc.wait_running(TOKEN)
        yield proc
    finally:
        proc.stop()


def _raw(proc, path, method="GET", headers=None, body=None) -> int:
    req = urllib.request.Request(proc.base + path, data=body, method=method,
                                 headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=10) as resp:
            return resp.status
    except urllib.error.HTTPError as exc:
        return exc.code


def test_every_request_needs_the_token(guarded):
    assert guarded.url == f"http://127.0.0.1:{guarded.port}/?token={TOKEN}"
    for path in ("/", "/api/status", "/api/schema", "/static/app.js"):
        assert _raw(guarded, path) == 401, path
        assert _raw(guarded, path, headers={"Authorization": "Bearer wrong-token"}) == 401
        assert _raw(guarded, path, headers={"Authorization": f"Bearer {TOKEN}"}) == 200
    assert _raw(guarded, f"/?token={TOKEN}") == 200
    # commands without the token change nothing
    code, body = guarded.post("/api/exit", {})
    assert code == 401 and body["detail"] == "missing or wrong token"
    code, body = guarded.post("/api/stop", {}, token="x" * 22)
    assert code == 401
    assert guarded.get("/api/status", TOKEN)[1]["running"]


def test_websocket_needs_the_token(guarded):
    ws_url = f"ws://127.0.0.1:{guarded.port}/ws"
    with pytest.raises(InvalidStatus) as exc:
        connect(ws_url, open_timeout=10).close()
    assert exc.value.response.status_code == 401
    with connect(f"{ws_url}?token={TOKEN}", open_timeout=10) as ws:
        first = json.loads(ws.recv(timeout=10))
    assert first["type"] == "samples"


def test_no_cross_origin_requests_and_size_limits(guarded):
    auth = {"Authorization": f"Bearer {TOKEN}"}
    assert guarded.get("/api/status", TOKEN)[0] == 200
    evil = {**auth, "Origin": "http://evil.example"}
    assert _raw(guarded, "/api/status", headers=evil) == 403
    ws_url = f"ws://127.0.0.1:{guarded.port}/ws?token={TOKEN}"
    with pytest.raises(InvalidStatus) as exc:
        connect(ws_url, origin="http://evil.example", open_timeout=10).close()
    assert exc.value.response.status_code == 403
    big = json.dumps({"params": {"sigma0": 1.0}, "pad": "x" * 100_000}).encode()
    assert _raw(guarded, "/api/compensation", "POST",
                {**auth, "Content-Type": "application/json"}, big) == 413
    assert _raw(guarded, "/api/push", "POST", {**auth, "Content-Type": "text/plain"},
                b"kick=1") == 415


def test_browser_with_the_printed_address_works_then_exit(browser, guarded):
    ctx = browser.new_context()
    page = ctx.new_page()
    try:
        page.goto(guarded.url)
        expect(page.locator("#conn")).to_have_text("live", timeout=30_000)
        wait_until(lambda: page.evaluate("() => window.__console.frames") >= 3,
                   what="plot frames through the token-protected WebSocket")
        exit_button = page.locator("#exit")
        exit_button.click()
        exit_button.click()
        expect(page.locator("#ended")).to_be_visible()
    finally:
        ctx.close()
    assert guarded.proc.wait(30) == 0
