"""The console's HTTP API under fuzzing: every route, wrong types, extreme and tiny numbers, bad
names and stalled bodies.

What must hold whatever arrives: no answer is 500; a change is applied only if the model's
check of it could be computed, and without ``"confirm": true`` only if the check passes; every
refusal names a field of the request it refuses; a connection whose body never arrives is
closed within the body timeout.  In-process (the sim backend on a fake clock, a real uvicorn
server for the stalled connections).
"""

from __future__ import annotations

import json
import math
import socket
import threading
import time

import pytest
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from frictionlab.config import build_config
from frictionlab.console import create_app
from frictionlab.console.models import COMPENSATOR_FIELDS, FEEDBACK_FIELDS, OBSERVER_FIELDS
from frictionlab.realtime import FakeClock, RealtimeController

#: Numbers that broke the check's numerics, and their kin.
EXTREME = [5e-324, -5e-324, 1e-300, 1e-12, 0.0, -0.0, -1.0, 1e300, 1.7976931348623157e308,
           -1e308, 10**30, 2**63]
WRONG = [None, True, "1", "nan", "", [], [1.0], {}, {"a": 1}, "name\n"]
VALUES = st.one_of(st.sampled_from(EXTREME + WRONG),
                   st.floats(allow_nan=False, allow_infinity=False, width=64),
                   st.integers(min_value=-10**6, max_value=10**6))
COMP_FIELDS = sorted({f for fs in COMPENSATOR_FIELDS.values() for f in fs})
EXPERIMENTS = ["stiction", "stribeck", "free-oscillation", "control-scaling", "velocity-scale",
               "angle-scales", "bogus"]
EXPERIMENT_OPTIONS = ["step", "hold", "coulomb_levels", "references", "gain", "duration",
                      "omega0", "levels", "wait", "scaling", "push", "bogus"]
NAMES = st.one_of(st.sampled_from(["ok1", "a\n", "x\n.dat", "../x", ".hidden", "a" * 300,
                                   "run.dat\n", "nul\x00", "ok.csv", "é"]), st.text(max_size=20))


#: One strategy of bodies per POST route (the page's fields and some it does not have).
BODIES = {
    "/api/design": st.dictionaries(
        st.sampled_from([*FEEDBACK_FIELDS, *OBSERVER_FIELDS, "preset", "confirm", "h"]),
        st.one_of(VALUES, st.sampled_from(["fast", "slow"])), min_size=1, max_size=3),
    "/api/compensation": st.fixed_dictionaries(
        {}, optional={"kind": st.one_of(st.sampled_from(["lugre", "adaptive", "coulomb",
                                                          "classical", "none"]), VALUES),
                      "enabled": st.one_of(st.booleans(), VALUES),
                      "confirm": st.one_of(st.booleans(), VALUES),
                      "error_signal": st.one_of(st.sampled_from(["arm_angle", "pendulum_angle",
                                                                 "velocity_innovation"]),
                                                VALUES),
                      "params": st.one_of(st.dictionaries(st.sampled_from(COMP_FIELDS), VALUES,
                                                          max_size=2), VALUES)}),
    "/api/push": st.fixed_dictionaries({}, optional={"kick": VALUES}),
    "/api/experiment": st.fixed_dictionaries(
        {"name": st.sampled_from(EXPERIMENTS)},
        optional={"options": st.dictionaries(st.sampled_from(EXPERIMENT_OPTIONS), VALUES,
                                             max_size=2),
                  "limits": st.dictionaries(st.sampled_from(["max_speed", "max_travel",
                                                             "max_u_da", "bogus"]), VALUES,
                                            max_size=2),
                  "confirm": st.one_of(st.just(True), VALUES)}),
    "/api/record/name": st.fixed_dictionaries({"name": st.one_of(NAMES, VALUES)}),
    "/api/start": st.just({}),
    "/api/swingup": st.just({}),
    "/api/stop": st.just({}),
    "/api/record/start": st.just({}),
    "/api/record/stop": st.just({}),
}


@pytest.fixture(scope="module")
def console(tmp_path_factory):
    cfg = build_config("fast", "classical")
    # runs end by themselves after a second of (fake) time: a fuzzed Start cannot run on
    ctl = RealtimeController(cfg, "sim", log_dir=tmp_path_factory.mktemp("fuzz"),
                             clock=FakeClock(), realtime=False, manage_gc=False, duration=1.0)
    app = create_app(ctl, None, frame_period=0.01, status_period=0.05)
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


def _check_answer(client, ctl, path: str, body, before: dict) -> None:
    data = json.dumps(body)
    r = client.post(path, content=data, headers={"Content-Type": "application/json"})
    assert r.status_code < 500, (path, body, r.status_code, r.text)
    out = r.json()
    if r.status_code >= 400:
        assert out["detail"], (path, body, out)
    if r.status_code == 422 and not out.get("confirm_required") and path in (
            "/api/design", "/api/compensation", "/api/experiment", "/api/record/name",
            "/api/push"):
        fields = [e["field"] for e in out["errors"]]
        assert fields, (path, body, out)
        sent = set(body) if isinstance(body, dict) else set()
        for f in fields:
            if f is None:  # about the body as a whole: an empty change, say
                assert not sent - {"confirm"}, (path, body, out)
                continue
            # a refusal names a field the request has (not `kind` for an omega0 refusal)
            assert f.split(".")[0] in sent | {"name"}, (path, body, out)
    after = _settings(client)  # the status always answers, the check always computed
    chk = after["loop_check"]
    assert chk["spectral_radius"] is not None and math.isfinite(chk["spectral_radius"])
    changed = (after["design"] != before["design"]
               or after["compensation"] != before["compensation"])
    if changed:
        assert path in ("/api/design", "/api/compensation") and r.status_code == 200
        if not (isinstance(body, dict) and body.get("confirm") is True):
            assert chk["verdict"] == "ok", (body, chk)  # nothing unsafe without confirm
    if ctl.running and path not in ("/api/start", "/api/swingup"):
        client.post("/api/stop", json={})


@settings(max_examples=40, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(data=st.data())
@pytest.mark.slow
def test_fuzzed_requests_never_answer_500_nor_apply_what_is_not_checked(console, data):
    client, ctl = console
    path = data.draw(st.sampled_from(sorted(BODIES)))
    body = data.draw(BODIES[path])
    if data.draw(st.booleans()) and path in ("/api/design", "/api/compensation"):
        body = {**body, "confirm": True}
    before = _settings(client)
    _check_answer(client, ctl, path, body, before)


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


def _stalled(port: int, path: str) -> socket.socket:
    s = socket.create_connection(("127.0.0.1", port), timeout=10)
    s.sendall(f"POST {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
              f"Content-Length: 20\r\n\r\n{{\"ki".encode())
    return s


def _answer_and_close(sock: socket.socket, timeout: float) -> tuple[bytes, bool]:
    """What the server sends until it closes ``sock`` (or ``timeout`` s pass)."""
    sock.settimeout(timeout)
    got = b""
    try:
        while chunk := sock.recv(4096):
            got += chunk
    except (ConnectionResetError, BrokenPipeError):
        return got, True
    except TimeoutError:
        return got, False
    return got, True


@pytest.mark.slow
def test_a_body_that_never_arrives_is_answered_and_its_connection_closed(tmp_path):
    """A request head, then nothing: 408 and the connection closed once the body timeout
    has passed, on every POST route at once; the operator's requests still answer."""
    cfg = build_config("fast", "classical")
    ctl = RealtimeController(cfg, "sim", log_dir=tmp_path, clock=FakeClock(), realtime=False,
                             manage_gc=False)
    timeout = 0.5
    app = create_app(ctl, None, body_timeout=timeout)
    try:
        with _Uvicorn(app) as srv:
            t0 = time.monotonic()
            socks = [_stalled(srv.port, p) for p in sorted(BODIES)]
            # the slack is for a busy host; a stalled body held forever would never end
            results = [_answer_and_close(s, timeout + 20) for s in socks]
            elapsed = time.monotonic() - t0
            for s in socks:
                s.close()
            assert all(closed for _, closed in results), results
            assert all(got.startswith(b"HTTP/1.1 408") for got, _ in results), results
            assert elapsed >= timeout  # they waited for the timeout, not less
            ok = socket.create_connection(("127.0.0.1", srv.port), timeout=10)
            ok.sendall(b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close"
                       b"\r\n\r\n")
            got, closed = _answer_and_close(ok, 20)
            ok.close()
            assert got.startswith(b"HTTP/1.1 200") and closed
    finally:
        ctl.close()
