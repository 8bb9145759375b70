"""The console's HTTP API under fuzzing: every route, wrong types, extreme and tiny numbers, bad
names and stalled bodies.

What must hold whatever arrives: no answer is 500; a change is applied only if the model's
check of it could be computed, and without ``"confirm": true`` only if the check passes; every
refusal names a field of the request it refuses; no file outside the log directory or the
page's own is served; a connection whose body never arrives, or arrives a byte at a time, is
closed within the body timeout.  The routes are read from the app itself
(:func:`app_routes`), so a route added later without a strategy here fails
:func:`test_every_route_of_the_app_is_fuzzed`.  The thesis plant's console and a motor
plant's (``--plant qube2``, its compensator fields in volts).  In-process (the sim backend on
a fake clock, a real uvicorn server for the stalled connections).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import socket
import threading
import time
from urllib.parse import quote

import pytest
from fastapi.routing import APIWebSocketRoute
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from starlette.routing import Mount, WebSocketRoute
from starlette.websockets import WebSocketDisconnect

from frictionlab.config import build_config
from frictionlab.console import create_app
from frictionlab.console.models import COMPENSATOR_FIELDS, FEEDBACK_FIELDS, OBSERVER_FIELDS
from frictionlab.console.security import BODY_TIMEOUT
from frictionlab.realtime import FakeClock, RealtimeController

#: Numbers that broke the check's numerics, and their kin; the motor plant's volts (its
#: 10 V limit) among them.
EXTREME = [5e-324, -5e-324, 1e-300, 1e-12, 0.0, -0.0, -1.0, 1e300, 1.7976931348623157e308,
           -1e308, 10**30, 2**63, 10**400, 0.155, 9.99, 10.0, 10.5, 12.0]
#: Non-finite numbers: JSON's ``NaN``/``Infinity`` tokens (which Python's parser accepts).
NONFINITE = [math.nan, math.inf, -math.inf]
#: Numbers as text, and other wrong types.
AS_TEXT = ["nan", "NaN", "inf", "-inf", "Infinity", "1e-300", "5e-324", "1e999", "0x10", " 1"]
WRONG = [None, True, False, "", [], [1.0], {}, {"a": 1}, "name\n", "é", "\u202e", "x" * 1000]
VALUES = st.one_of(st.sampled_from(EXTREME + NONFINITE + AS_TEXT + WRONG),
                   st.floats(width=64),
                   st.integers(min_value=-10**6, max_value=10**6))
COMP_FIELDS = sorted({f for fs in COMPENSATOR_FIELDS.values() for f in fs})
EXPERIMENTS = ["stiction", "stribeck", "free-oscillation", "control-scaling", "velocity-scale",
               "angle-scales", "bogus"]
EXPERIMENT_OPTIONS = ["step", "hold", "coulomb_levels", "references", "gain", "duration",
                      "omega0", "levels", "wait", "scaling", "push", "bogus"]
#: Bad names: trailing newlines, path separators, unicode, control characters, too long.
BAD_NAMES = ["ok1", "a\n", "x\n.dat", "../x", "..\\x", "/etc/passwd", "x/y", ".hidden",
             "a" * 300, "run.dat\n", "nul\x00", "ok.csv", "é", "名前", "a b", "CON", "",
             "-x", "\u202etxt.dat"]
NAMES = st.one_of(st.sampled_from(BAD_NAMES), st.text(max_size=20))
#: Bodies that are not a JSON object of the route's fields.
GARBAGE = [b"", b"[1, 2", b"null", b"[]", b'"x"', b"1e999", b"NaN", "é".encode(), b"{" * 200,
           b'{"a":' * 100 + b"1" + b"}" * 100, b"\xff\xfe\x00", b'{"confirm": true',
           b'{"kick": 0.3, "kick": 99}']
#: Query strings for the GET routes.
QUERIES = ["", "token=x", "token=" + "a" * 5000, "token=%00", "a=%ff", "x=1&x=2", "%", "&&=="]
#: What is near the log directory and the page's files: a request that reaches it is a traversal.
SECRET = b"frictionlab-fuzz-secret-3f9a"
#: Paths under the page's static files, plain and with encoded traversals.
STATIC = ["app.js", "index.html", "vendor/", "", "../app.py", "%2e%2e/app.py",
          "..%2fapp.py", "%2e%2e%2f%2e%2e%2fconfig.py", "vendor/..%2f..%2fapp.py",
          "index.html%00", "app.js%0a", "%c0%ae%c0%ae/app.py", "..%5capp.py", "é"]


@dataclasses.dataclass(frozen=True)
class Req:
    """One request of the fuzz: ``method`` (``WS`` for a WebSocket), the path and query, the
    raw body (or the WebSocket's messages)."""

    method: str
    path: str
    content: bytes | None = None
    messages: tuple = ()

    def body(self):
        """The body as the server parses it (None: not JSON)."""
        try:
            return json.loads(self.content) if self.content else None
        except (ValueError, RecursionError):
            return None


def _dumps(obj) -> bytes:
    return json.dumps(obj).encode()  # NaN and Infinity as JSON's tokens


def post(path: str, objects) -> st.SearchStrategy:
    """POST ``path`` with a JSON object from ``objects`` (two in three) or a garbage body."""
    bodies = st.one_of(objects.map(_dumps), objects.map(_dumps), st.sampled_from(GARBAGE))
    return bodies.map(lambda b: Req("POST", path, b))


def get(path: str) -> st.SearchStrategy:
    return st.sampled_from(QUERIES).map(lambda q: Req("GET", path + ("?" + q if q else "")))


def _file_name(name: str, ext: str, encode: bool) -> str:
    """``name.ext`` in a URL path: percent-encoded, or as it is where a client can send it
    so (printable ASCII; the client itself refuses control characters)."""
    raw = f"{name}.{ext}"
    return raw if not encode and raw.isascii() and raw.isprintable() else quote(raw, safe="")


EMPTY = st.one_of(st.just({}), st.dictionaries(st.sampled_from(["confirm", "x", "kick"]),
                                                VALUES, max_size=2))

#: One strategy of requests per route of the app, keyed as :func:`app_routes` lists them.
REQUESTS = {
    ("GET", "/"): get("/"),
    ("GET", "/api/status"): get("/api/status"),
    ("GET", "/api/schema"): get("/api/schema"),
    ("GET", "/api/files/{filename}"): st.builds(
        lambda name, ext, enc: Req("GET", "/api/files/" + _file_name(name, ext, enc)),
        st.one_of(NAMES, st.sampled_from(["..%2fsecret", "%2e%2e%2fsecret", "..%5csecret",
                                          "rec", "secret"])),
        st.sampled_from(["dat", "csv", "json", "dat\n", "py"]), st.booleans()),
    ("MOUNT", "/static"): st.sampled_from(STATIC).map(lambda p: Req("GET", "/static/" + p)),
    ("WS", "/ws"): st.lists(st.one_of(st.text(max_size=50), st.binary(max_size=50),
                                      st.sampled_from(GARBAGE), st.just(b"x" * 70_000)),
                            max_size=3).map(lambda m: Req("WS", "/ws", messages=tuple(m))),
    ("POST", "/api/design"): post("/api/design", st.dictionaries(
        st.sampled_from([*FEEDBACK_FIELDS, *OBSERVER_FIELDS, "preset", "confirm", "h"]),
        st.one_of(VALUES, st.sampled_from(["fast", "slow"])), min_size=1, max_size=3)),
    ("POST", "/api/compensation"): post("/api/compensation", st.fixed_dictionaries(
        {}, optional={"kind": st.one_of(st.sampled_from(["lugre", "adaptive", "coulomb",
                                                          "classical", "none"]), VALUES),
                      "enabled": st.one_of(st.booleans(), VALUES),
                      "confirm": st.one_of(st.booleans(), VALUES),
                      "error_signal": st.one_of(st.sampled_from(["arm_angle", "pendulum_angle",
                                                                 "velocity_innovation"]),
                                                VALUES),
                      "params": st.one_of(st.dictionaries(st.sampled_from(COMP_FIELDS), VALUES,
                                                          max_size=2), VALUES)})),
    ("POST", "/api/push"): post("/api/push", st.fixed_dictionaries({}, optional={
        "kick": VALUES})),
    ("POST", "/api/experiment"): post("/api/experiment", st.fixed_dictionaries(
        {"name": st.one_of(st.sampled_from(EXPERIMENTS), VALUES)},
        optional={"options": st.one_of(st.dictionaries(st.sampled_from(EXPERIMENT_OPTIONS),
                                                       VALUES, max_size=2), VALUES),
                  "limits": st.dictionaries(st.sampled_from(["max_speed", "max_travel",
                                                             "max_u_da", "bogus"]), VALUES,
                                            max_size=2),
                  "confirm": st.one_of(st.just(True), VALUES)})),
    ("POST", "/api/record/name"): post("/api/record/name", st.fixed_dictionaries(
        {"name": st.one_of(NAMES, VALUES)})),
    ("POST", "/api/start"): post("/api/start", EMPTY),
    ("POST", "/api/swingup"): post("/api/swingup", EMPTY),
    ("POST", "/api/stop"): post("/api/stop", EMPTY),
    ("POST", "/api/record/start"): post("/api/record/start", EMPTY),
    ("POST", "/api/record/stop"): post("/api/record/stop", EMPTY),
}
#: Routes fuzzed by a test of their own: Exit ends the console.
OWN_TEST = {("POST", "/api/exit"): "test_exit_answers_any_body_and_ends_the_console_once"}
#: The routes that change the controller's settings.
CHANGES = ("/api/design", "/api/compensation")


def app_routes(guard) -> set[tuple[str, str]]:
    """Every route of the console app (``guard.app``, routers included) as ``(method, path)``;
    ``WS`` for a WebSocket, ``MOUNT`` for a mounted directory."""
    def walk(routes, prefix=""):
        for r in routes:
            sub = getattr(r, "original_router", None)  # an included router (FastAPI >= 0.16x)
            if sub is not None:
                ctx = getattr(r, "include_context", None)
                yield from walk(sub.routes, prefix + (getattr(ctx, "prefix", "") or ""))
            elif isinstance(r, APIWebSocketRoute | WebSocketRoute):
                yield "WS", prefix + r.path
            elif isinstance(r, Mount):
                yield "MOUNT", prefix + r.path
            else:
                for m in r.methods:
                    yield m, prefix + r.path

    return set(walk(guard.app.routes))


def _console(tmp_path_factory, plant: str, **app_options):
    cfg = build_config("fast", "classical", plant=plant)
    log_dir = tmp_path_factory.mktemp(f"fuzz-{plant}") / "runs"
    log_dir.mkdir()
    # beside the log directory: a request that reads it has escaped the log directory
    (log_dir.parent / "secret.dat").write_bytes(SECRET)
    (log_dir / "rec.dat").write_bytes(b"0 0 0 0 0 0 0 0 0 0\n")
    # runs end by themselves after a second of (fake) time: a fuzzed Start cannot run on
    ctl = RealtimeController(cfg, "sim", log_dir=log_dir, clock=FakeClock(), realtime=False,
                             manage_gc=False, duration=1.0)
    app = create_app(ctl, None, frame_period=0.01, status_period=0.05, **app_options)
    return ctl, app


@pytest.fixture(scope="module")
def console(tmp_path_factory):
    ctl, app = _console(tmp_path_factory, "thesis")
    with TestClient(app, base_url="http://127.0.0.1:8000",
                    raise_server_exceptions=False) as client:
        yield client, ctl
    ctl.close()


@pytest.fixture(scope="module")
def fuzz_console(tmp_path_factory):
    """The thesis plant's console for the fuzz alone (it applies confirmed changes: the
    other tests start from the defaults)."""
    ctl, app = _console(tmp_path_factory, "thesis")
    with TestClient(app, base_url="http://127.0.0.1:8000",
                    raise_server_exceptions=False) as client:
        yield client, ctl
    ctl.close()


@pytest.fixture(scope="module")
def motor_console(tmp_path_factory):
    """``frictionlab run --plant qube2``'s console: u and the compensator's levels in V."""
    ctl, app = _console(tmp_path_factory, "qube2")
    with TestClient(app, base_url="http://127.0.0.1:8000",
                    raise_server_exceptions=False) as client:
        yield client, ctl
    ctl.close()


def _settings(client) -> dict:
    st_ = client.get("/api/status")
    assert st_.status_code == 200, st_.text
    s = st_.json()
    return {"design": s["design"], "compensation": s["compensation"],
            "loop_check": s["loop_check"]}


def _send(client, req: Req):
    """Send ``req``; the HTTP response (None for a WebSocket)."""
    if req.method == "WS":
        try:
            with client.websocket_connect("ws://127.0.0.1:8000" + req.path) as ws:
                assert json.loads(ws.receive_text())["type"]  # the backlog's first message
                for m in req.messages:
                    (ws.send_bytes if isinstance(m, bytes) else ws.send_text)(m)
        except WebSocketDisconnect as exc:  # a close after the messages, not a server error
            assert exc.code != 1011, exc
        return None
    headers = {"Content-Type": "application/json"} if req.method == "POST" else {}
    return client.request(req.method, req.path, content=req.content, headers=headers)


def _check_answer(client, ctl, req: Req, before: dict) -> None:
    r = _send(client, req)
    path, body = req.path, req.body()
    if r is not None:
        assert r.status_code < 500, (req, r.status_code, r.text)
        assert SECRET not in r.content, req  # nothing outside the log directory served
        assert b"__future__" not in r.content, req  # nor the package's sources
        if r.status_code >= 400:
            assert r.json()["detail"], (req, r.text)
        out = r.json() if r.status_code == 422 else {}
        if out and not out.get("confirm_required") and path in (
                *CHANGES, "/api/experiment", "/api/record/name", "/api/push"):
            fields = [e["field"] for e in out["errors"]]
            assert fields, (req, out)
            sent = set(body) if isinstance(body, dict) else set()
            for f in fields:
                if f is None:  # about the body as a whole: not an object, or an empty change
                    assert not sent - {"confirm"}, (req, out)
                    continue
                # a refusal names a field the request has (not `kind` for an omega0 refusal)
                assert f.split(".")[0] in sent | {"name"}, (req, out)
    after = _settings(client)  # the status always answers, the check always computed
    chk = after["loop_check"]
    assert chk["spectral_radius"] is not None and math.isfinite(chk["spectral_radius"])
    changed = (after["design"] != before["design"]
               or after["compensation"] != before["compensation"])
    if changed:
        assert path in CHANGES and r.status_code == 200, (req, r.status_code)
        if not (isinstance(body, dict) and body.get("confirm") is True):
            assert chk["verdict"] == "ok", (req, chk)  # nothing unsafe without confirm
    if ctl.running and path not in ("/api/start", "/api/swingup"):
        client.post("/api/stop", json={})


def test_every_route_of_the_app_is_fuzzed(console):
    """The routes as the app has them: each has a strategy here (or a test of its own)."""
    client, _ctl = console
    routes = app_routes(client.app)
    assert ("POST", "/api/design") in routes and ("WS", "/ws") in routes  # the walk works
    assert routes == set(REQUESTS) | set(OWN_TEST), (routes ^ (set(REQUESTS) | set(OWN_TEST)))


#: ``FRICTIONLAB_FUZZ_EXAMPLES=N``: a longer hunt, N random examples per plant (CI runs the
#: same derandomised few every time).
HUNT = int(os.environ.get("FRICTIONLAB_FUZZ_EXAMPLES", "0"))
FUZZ = dict(deadline=None, derandomize=not HUNT,
            suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def _fuzz(console, data):
    client, ctl = console
    key = data.draw(st.sampled_from(sorted(REQUESTS)))
    req = data.draw(REQUESTS[key])
    if req.method == "POST" and req.path in CHANGES and data.draw(st.booleans()):
        body = req.body()
        if isinstance(body, dict):
            req = dataclasses.replace(req, content=_dumps({**body, "confirm": True}))
    _check_answer(client, ctl, req, _settings(client))


@settings(max_examples=HUNT or 60, **FUZZ)
@given(data=st.data())
@pytest.mark.slow
def test_fuzzed_requests_never_answer_500_nor_apply_what_is_not_checked(fuzz_console, data):
    _fuzz(fuzz_console, data)


@settings(max_examples=HUNT or 25, **FUZZ)
@given(data=st.data())
@pytest.mark.slow
def test_the_motor_plant_s_console_under_the_same_fuzz(motor_console, data):
    """``--plant qube2``: the same requests (levels in volts among the numbers); over its 10 V
    limit a compensator saturates and is applied only with confirm."""
    _fuzz(motor_console, data)


def test_exit_answers_any_body_and_ends_the_console_once(tmp_path_factory):
    """Exit with bodies of every wrong kind: no 500; the first ends the loop and the console
    (nothing starts or changes afterwards), the status still answers."""
    exits = []
    ctl, app = _console(tmp_path_factory, "thesis", on_exit=lambda: exits.append(1))
    try:
        with TestClient(app, base_url="http://127.0.0.1:8000",
                        raise_server_exceptions=False) as client:
            assert client.post("/api/start", json={}).status_code == 200
            for content in [*GARBAGE, b'{"confirm": "yes", "x": 1e999}', b"{}"]:
                r = client.post("/api/exit", content=content,
                                headers={"Content-Type": "application/json"})
                assert r.status_code < 500, (content, r.text)
            assert exits and not ctl.running
            before = _settings(client)
            assert client.post("/api/start", json={}).status_code == 409
            assert client.post("/api/design", json={"preset": "slow"}).status_code == 409
            assert _settings(client) == before
    finally:
        ctl.close()


@pytest.mark.parametrize("field", ["omega1", "omega2", "observer_omega1", "observer_omega2",
                                   "omega0"])
@pytest.mark.parametrize("value", [5e-324, 1e-300])
@pytest.mark.parametrize("confirm", [False, True])
def test_tiny_design_values_are_refused_at_their_field_confirm_or_not(console, field, value,
                                                                      confirm):
    """Pole frequencies below 0.01 rad/s are out of range; an omega_0 the design cannot be
    computed with is refused as such: confirm applies neither."""
    client, _ctl = console
    before = _settings(client)
    r = client.post("/api/design", json={field: value, "confirm": confirm})
    assert r.status_code == 422, r.text
    assert not r.json().get("confirm_required")
    assert [e["field"] for e in r.json()["errors"]] == [field]
    assert _settings(client) == before


@pytest.mark.parametrize("path, body, field", [
    ("/api/design", {"preset": "fast", "omega0": 5e-324}, "omega0"),
    ("/api/design", {"omega0": None}, "omega0"),
    ("/api/design", {"preset": None}, "preset"),
    ("/api/compensation", {"kind": None}, "kind"),
    ("/api/compensation", {"enabled": None, "confirm": True}, "enabled"),
    ("/api/compensation", {"params": None}, "params"),
])
def test_what_the_long_fuzz_found_is_refused_at_its_field(console, path, body, field):
    """A preset with field values, a field sent as null: refused at that field, not at the
    body as a whole."""
    client, _ctl = console
    before = _settings(client)
    r = client.post(path, json=body)
    assert r.status_code == 422 and [e["field"] for e in r.json()["errors"]] == [field], r.text
    assert _settings(client) == before


@pytest.mark.parametrize("field", ["zeta1", "observer_zeta2"])
def test_a_tiny_damping_is_refused_unless_confirmed(console, field):
    """zeta = 1e-300 is an undamped pole pair: the check computes it and refuses it as
    unstable or without margin (confirm would apply it, as any unsafe change)."""
    client, _ctl = console
    before = _settings(client)
    r = client.post("/api/design", json={field: 1e-300})
    assert r.status_code == 422 and r.json()["confirm_required"], r.text
    assert [e["field"] for e in r.json()["errors"]] == [field]
    assert _settings(client) == before


@pytest.mark.parametrize("kind", ["lugre", "adaptive"])
@pytest.mark.parametrize("value", [5e-324, 1e-300])
@pytest.mark.parametrize("confirm", [False, True])
def test_tiny_sigma0_is_refused_confirm_or_not(console, kind, value, confirm):
    client, _ctl = console
    before = _settings(client)
    r = client.post("/api/compensation",
                    json={"kind": kind, "params": {"sigma0": value}, "confirm": confirm})
    assert r.status_code == 422, r.text
    assert "params.sigma0" in [e["field"] for e in r.json()["errors"]]
    assert _settings(client) == before


def test_a_change_whose_check_cannot_be_computed_is_refused_even_confirmed(console,
                                                                        monkeypatch):
    """The check failing (numpy's LinAlgError, say) refuses the change; confirm does not
    apply it, and the status still answers."""
    import numpy as np

    from frictionlab.realtime import params as rp

    client, _ctl = console
    before = _settings(client)

    def broken(*args, **kwargs):
        raise np.linalg.LinAlgError("Array must not contain infs or NaNs")

    monkeypatch.setattr(rp, "check_loop", broken)
    for confirm in (False, True):
        r = client.post("/api/design", json={"zeta2": 0.8, "confirm": confirm})
        assert r.status_code == 422, r.text
        out = r.json()
        assert not out.get("confirm_required")
        assert [e["field"] for e in out["errors"]] == ["zeta2"]
        assert "cannot" in out["detail"] or "fails" in out["detail"]
    monkeypatch.undo()
    assert _settings(client) == before


def test_a_stable_design_needs_a_margin(console):
    """Poles so slow that the loop hardly recovers (a modulus just below 1) are refused
    unless confirmed; the refusal says why."""
    client, _ctl = console
    before = _settings(client)
    r = client.post("/api/design", json={"omega1": 0.01})
    assert r.status_code == 422 and r.json()["confirm_required"], r.text
    assert r.json()["check"]["spectral_radius"] < 1
    assert "margin" in r.json()["detail"]
    assert _settings(client) == before


def test_a_design_the_simulated_pendulum_falls_with_is_refused_unless_confirmed(console):
    """omega0 = 7.5 against the plant's 6.8 passes the linear check, but with friction
    the limit cycle grows and the pendulum falls: the simulation refuses it (confirm
    applies it, as any unsafe change)."""
    client, _ctl = console
    before = _settings(client)
    r = client.post("/api/design", json={"omega0": 7.5})
    assert r.status_code == 422 and r.json()["confirm_required"], r.text
    out = r.json()
    assert out["check"]["verdict"] == "falls" and out["check"]["spectral_radius"] < 1
    assert [e["field"] for e in out["errors"]] == ["omega0"]
    assert "falls" in out["detail"] and 6.8 <= out["safe"]["omega0"] < 7.5
    assert _settings(client) == before
    r = client.post("/api/design", json={"omega0": out["safe"]["omega0"]})
    assert r.status_code == 200 and r.json()["status"]["loop_check"]["verdict"] == "ok"
    assert client.post("/api/design", json={"preset": "fast"}).status_code == 200


def test_the_documented_refusal_is_the_program_s(console):
    """docs/console.md's example of a refusal (``{"omega0": 100}``) is what the server
    answers, word for word and number for number."""
    from pathlib import Path

    doc = (Path(__file__).parents[1] / "docs" / "console.md").read_text()
    block = doc.split('For example\n`{"omega0": 100}`:\n\n', 1)[1].split("\n\n", 1)[0]
    shown = " ".join(line.strip() for line in block.splitlines())
    client, _ctl = console
    r = client.post("/api/design", json={"omega0": 100.0})
    assert r.status_code == 422 and r.json()["detail"] == shown, (r.json()["detail"], shown)


@pytest.mark.parametrize("options, field", [
    ({"scaling": 1.0}, "options.scaling"),
    ({"step": 1e-300}, "options.step"),
    ({"step": 5e-324}, "options.step"),
    ({"coulomb_levels": 0.5}, "options.coulomb_levels"),
    ({"hold": [1.0]}, "options.hold"),
    ({"hold": -1.0}, "options.hold"),
])
@pytest.mark.parametrize("confirm", [False, True])
def test_experiment_options_are_checked_and_one_that_cannot_finish_is_refused(
        console, options, field, confirm):
    client, ctl = console
    r = client.post("/api/experiment",
                    json={"name": "stiction", "options": options, "confirm": confirm})
    assert r.status_code == 422, r.text
    assert [e["field"] for e in r.json()["errors"]] == [field]
    assert not ctl.running


# --- stalled connections on a real server ----------------------------------------------------


class _Uvicorn:
    """The console app served by uvicorn (the console's own protocol class) in a thread."""

    def __init__(self, app):
        import uvicorn

        from frictionlab.console.server import ConsoleHTTP

        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(64)
        self.port = self.sock.getsockname()[1]
        config = uvicorn.Config(app, log_level="error", access_log=False, lifespan="on",
                                http=ConsoleHTTP)
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run,
                                       kwargs={"sockets": [self.sock]}, daemon=True)

    def __enter__(self):
        self.thread.start()
        deadline = time.monotonic() + 60
        while not self.server.started:
            assert time.monotonic() < deadline and self.thread.is_alive(), "no server"
            time.sleep(0.01)
        return self

    def __exit__(self, *exc):
        self.server.should_exit = True
        self.thread.join(30)
        self.sock.close()


def _concrete(method: str, path: str) -> tuple[str, str]:
    """A request line's method and path for a route of :func:`app_routes`."""
    if method == "MOUNT":
        return "GET", path + "/app.js"
    if method == "WS":
        return "GET", path
    return method, path.replace("{filename}", "rec.dat")


def _stalled(port: int, method: str, path: str, length: int = 20,
             sent: bytes = b'{"ki') -> socket.socket:
    """A request head announcing ``length`` bytes of body, then only ``sent`` of them."""
    s = socket.create_connection(("127.0.0.1", port), timeout=10)
    s.sendall(f"{method} {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json"
              f"\r\nContent-Length: {length}\r\n\r\n".encode() + sent)
    return s


def _answer_and_close(sock: socket.socket, timeout: float,
                      trickle: bool = False) -> tuple[bytes, bool, float]:
    """What the server sends until it closes ``sock`` (or ``timeout`` s pass), whether it
    closed it, and when (monotonic); ``trickle``: send a byte of body every 0.1 s meanwhile."""
    sock.settimeout(0.1 if trickle else timeout)
    got, end = b"", time.monotonic() + timeout
    try:
        while time.monotonic() < end:
            try:
                chunk = sock.recv(4096)
            except TimeoutError:
                if trickle:
                    sock.sendall(b" ")
                    continue
                break
            if not chunk:
                return got, True, time.monotonic()
            got += chunk
    except (ConnectionResetError, BrokenPipeError):
        return got, True, time.monotonic()
    return got, False, time.monotonic()


def test_the_documented_body_timeout_is_the_servers():
    """docs/console.md: a body arrives in full within 3 s of the head, or 408."""
    assert BODY_TIMEOUT == 3.0


@pytest.mark.slow
def test_a_body_that_never_arrives_is_answered_and_its_connection_closed(tmp_path):
    """A request head, then part of its body and nothing more, on every route of the app at
    once (GETs with a body too), and on two a body trickled a byte at a time: 408 and the
    connection closed once the body timeout has passed; a WebSocket handshake with a body:
    400 and closed; the operator's requests still answer."""
    cfg = build_config("fast", "classical")
    (tmp_path / "rec.dat").write_bytes(b"0\n")
    ctl = RealtimeController(cfg, "sim", log_dir=tmp_path, clock=FakeClock(), realtime=False,
                             manage_gc=False)
    timeout = 0.5
    app = create_app(ctl, None, body_timeout=timeout)
    lines = sorted(_concrete(m, p) for m, p in app_routes(app) | {("PUT", "/api/design")})
    try:
        with _Uvicorn(app) as srv:
            t0 = time.monotonic()
            socks = [_stalled(srv.port, m, p) for m, p in lines]
            trickled = [_stalled(srv.port, m, p, length=1000, sent=b"")
                        for m, p in (("POST", "/api/design"), ("GET", "/api/status"))]
            # the slack is for a busy host; a stalled body held for ever would never end
            results = [_answer_and_close(s, timeout + 20) for s in socks]
            results += [_answer_and_close(s, timeout + 20, trickle=True) for s in trickled]
            for s in socks + trickled:
                s.close()
            assert all(closed for _, closed, _ in results), results
            assert all(got.startswith(b"HTTP/1.1 408") for got, _, _ in results), results
            closed_after = [t - t0 for _, _, t in results]
            # they waited for the timeout, not less; closed within it (plus a busy host's
            # slack, far below the 5 s a kept-alive idle connection is held)
            assert min(closed_after) >= timeout and max(closed_after) < timeout + 4.0, \
                closed_after
            # a WebSocket handshake announcing a body: refused and closed at once (uvicorn
            # would hand the head alone to the WebSocket protocol, which waited for ever)
            ws = socket.create_connection(("127.0.0.1", srv.port), timeout=10)
            ws.sendall(b"GET /ws HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n"
                       b"Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                       b"Sec-WebSocket-Version: 13\r\nContent-Length: 20\r\n\r\n{\"ki")
            got, closed, _ = _answer_and_close(ws, timeout + 20)
            ws.close()
            assert got.startswith(b"HTTP/1.1 400") and closed, got[:100]
            ok = socket.create_connection(("127.0.0.1", srv.port), timeout=10)
            ok.sendall(b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close"
                       b"\r\n\r\n")
            got, closed, _ = _answer_and_close(ok, 20)
            ok.close()
            assert got.startswith(b"HTTP/1.1 200") and closed
            # raw traversals (a client that does not normalise the path): nothing served
            for path in ("/static/../routes/page.py", "/api/files/../secret.dat",
                         "/static/../../config.py"):
                raw = socket.create_connection(("127.0.0.1", srv.port), timeout=10)
                raw.sendall(f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close"
                            "\r\n\r\n".encode())
                got, _, _ = _answer_and_close(raw, 20)
                raw.close()
                assert got.startswith(b"HTTP/1.1 404"), (path, got[:100])
    finally:
        ctl.close()


@pytest.mark.slow
def test_a_kept_alive_connection_must_send_each_head_in_time(tmp_path, monkeypatch):
    """After an answer, the next request's head on the same connection has the head timeout
    too, from its first byte: trickled a byte at a time (which restarts uvicorn's keep-alive
    timer) or left half sent, the connection is closed; a healthy kept-alive client is
    served."""
    from frictionlab.console import server

    head_timeout = 0.5
    monkeypatch.setattr(server, "HEAD_TIMEOUT", head_timeout)
    cfg = build_config("fast", "classical")
    ctl = RealtimeController(cfg, "sim", log_dir=tmp_path, clock=FakeClock(), realtime=False,
                             manage_gc=False)
    req = b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"
    try:
        with _Uvicorn(create_app(ctl, None)) as srv:
            trials = []
            for first, trickle in ((req + b"GET /api/status HTTP/1.1\r\nX-Pad: ", True),
                                   (req, True), (req + b"GET /api/sta", False)):
                s = socket.create_connection(("127.0.0.1", srv.port), timeout=10)
                s.sendall(first)
                trials.append((s, trickle))
            t0 = time.monotonic()
            results = [_answer_and_close(s, head_timeout + 20, trickle=t) for s, t in trials]
            for s, _ in trials:
                s.close()
            for got, closed, t in results:
                assert closed and got.count(b"HTTP/1.1 200") == 1, got[:200]
                assert t - t0 < head_timeout + 4.0  # far below the 20 s a held one reaches
            healthy = socket.create_connection(("127.0.0.1", srv.port), timeout=10)
            for _ in range(2):  # each sent at once: answered, the connection kept open
                healthy.sendall(req)
                got = b""
                while b"\r\n\r\n" not in got:
                    got += healthy.recv(1 << 16)
                head, body = got.split(b"\r\n\r\n", 1)
                length = int(head.lower().split(b"content-length: ")[1].split(b"\r\n")[0])
                while len(body) < length:
                    body += healthy.recv(1 << 16)
                assert head.startswith(b"HTTP/1.1 200") and len(body) == length, head
            healthy.close()
    finally:
        ctl.close()
