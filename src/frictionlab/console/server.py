"""Serving the operator console with uvicorn (``frictionlab run``).

:func:`serve` checks the bind address against the token rule
(:mod:`.security`), binds the socket itself (so a busy port is a clear
error), prints the console's address once it answers (after the start-up's
one-time work), serves until Exit, Ctrl-C or SIGTERM,
and leaves the loop stopped (u = 0 written) whichever way the server ended.

Connections cannot lock the operator out: there is no limit on concurrent
requests that idle connections could fill (uvicorn's ``limit_concurrency``
answered every request, Stop included, 503 while 64 idle connections were
open).  Instead :class:`ConsoleHTTP` closes a connection that has not sent
a complete request head within :data:`HEAD_TIMEOUT` seconds, and when more
than :data:`MAX_PENDING` connections are waiting for their first request it
closes the oldest of them.  A refused request (no token, wrong origin)
closes its connection (:mod:`.security`), and an idle kept-alive
connection is closed after uvicorn's keep-alive timeout (5 s).  A WebSocket
handshake that announces a body is answered 400 and closed (it would wait for
ever: see :meth:`ConsoleHTTP.handle_websocket_upgrade`).
"""

from __future__ import annotations

import contextlib
import signal
import socket
import sys
import threading
from collections import OrderedDict

import uvicorn
import uvicorn.config
from uvicorn.protocols.http.h11_impl import H11Protocol

from ..realtime.osrt import STOP_SIGNALS, try_realtime_priority
from .app import create_app
from .security import MAX_BODY, check_bind, is_loopback, resolve_token

__all__ = ["HEAD_TIMEOUT", "MAX_PENDING", "ConsoleHTTP", "console_url", "serve"]


#: uvicorn's WebSocket implementation (the sans-I/O one where this uvicorn has it).
_WS_IMPL = ("websockets-sansio" if "websockets-sansio" in uvicorn.config.WS_PROTOCOLS
            else "websockets")


#: Seconds a new connection has to send a complete request head.
HEAD_TIMEOUT = 3.0
#: Connections waiting for their first request head, at most (the oldest is closed).
MAX_PENDING = 32


class ConsoleHTTP(H11Protocol):
    """uvicorn's HTTP/1.1 protocol with a deadline for the first request head.

    A connection is *pending* from its opening until its first request head
    is complete, and again from the first byte of each later request on a
    kept-alive connection until that head is complete.  Pending connections
    are closed after :data:`HEAD_TIMEOUT` seconds, and a new connection beyond
    :data:`MAX_PENDING` pending ones closes the oldest, so idle or trickling
    connections (with or without the token) can neither pile up nor hold a
    slot the operator needs.
    """

    def _pending(self) -> OrderedDict:
        state = self.server_state
        if not hasattr(state, "frictionlab_pending"):
            state.frictionlab_pending = OrderedDict()
        return state.frictionlab_pending

    def connection_made(self, transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        #: The request (scope) after which the connection waits for another (kept alive).
        self._answered = None
        #: The scope when the head deadline was set: a new one means the head arrived.
        self._armed_at = None
        self._arm()

    def _arm(self) -> None:
        """Pending from now: a complete request head within :data:`HEAD_TIMEOUT`."""
        pending = self._pending()
        pending[self] = self.loop.call_later(HEAD_TIMEOUT, self._head_timeout)
        while len(pending) > MAX_PENDING:
            oldest, timer = pending.popitem(last=False)
            timer.cancel()
            oldest.transport.close()

    def _head_timeout(self) -> None:
        self._pending().pop(self, None)
        self.transport.close()

    def _not_pending(self) -> None:
        timer = self._pending().pop(self, None)
        if timer is not None:
            timer.cancel()

    def data_received(self, data: bytes) -> None:
        if self._answered is not None and self._answered is self.scope:
            # the first bytes of the next request on a kept-alive connection: its head has
            # HEAD_TIMEOUT too (uvicorn's keep-alive timer restarts with every byte, so a
            # head trickled a byte at a time held the connection for ever)
            self._answered = None
            self._armed_at = self.scope
            self._arm()
        super().data_received(data)
        if self.scope is not self._armed_at:  # a request head arrived (an upgrade too)
            self._not_pending()

    def on_response_complete(self) -> None:
        before = self.scope
        super().on_response_complete()
        if not self.transport.is_closing() and self.scope is before:
            # no pipelined request started: wait for the next one's head; part of it
            # may have come with this request already
            self._answered = before
            if self.conn.trailing_data[0]:
                self._answered = None
                self._armed_at = before
                self._arm()

    def connection_lost(self, exc) -> None:
        self._not_pending()
        super().connection_lost(exc)

    def handle_websocket_upgrade(self, event) -> None:
        # a WebSocket handshake has no body; uvicorn hands the head alone to the
        # WebSocket protocol, which then waited for ever on one announced (a stalled
        # connection the body timeout never saw): refused, and the connection closed
        if any(name in (b"content-length", b"transfer-encoding") and value.strip() != b"0"
               for name, value in self.headers):
            self.send_400_response("a WebSocket handshake has no body")
            return
        super().handle_websocket_upgrade(event)


class _Server(uvicorn.Server):
    """uvicorn's server, ending on SIGINT/SIGTERM/SIGHUP/SIGQUIT without re-raising the
    signal, and stopping the loop at once (u = 0 at its next tick, as Exit does) rather
    than after the server's own shutdown."""

    controller = None
    #: Called once the server accepts connections (prints the address: it answers now).
    on_started = None

    async def startup(self, sockets=None) -> None:
        await super().startup(sockets=sockets)
        if self.started and self.on_started is not None:
            self.on_started()

    @contextlib.contextmanager
    def capture_signals(self):
        if threading.current_thread() is not threading.main_thread():
            yield
            return
        previous = {sig: signal.signal(sig, self._on_signal) for sig in STOP_SIGNALS}
        try:
            yield
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)

    def _on_signal(self, sig, frame) -> None:
        if self.controller is not None:
            self.controller.stop("signal", signal.Signals(sig).name)
        self.signalled = True
        if self.should_exit and sig == signal.SIGINT:
            self.force_exit = True
        self.should_exit = True


def console_url(host: str, port: int, token: str | None = None) -> str:
    """The address to open (with ``?token=`` when a token is needed)."""
    shown = host
    if host in ("0.0.0.0", "::", ""):
        shown = "127.0.0.1" if host != "::" else "::1"
    if ":" in shown:
        shown = f"[{shown}]"
    url = f"http://{shown}:{port}/"
    return f"{url}?token={token}" if token else url


def _bind(host: str, port: int) -> socket.socket:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise OSError(f"cannot serve the console on {host}:{port}: {exc.strerror or exc}") from None
    sock.listen(128)
    sock.set_inheritable(True)
    return sock


#: SCHED_FIFO priority of the server's event-loop thread: below the loop (50) and the log
#: writer (10), above every normal process.
SERVER_PRIORITY = 5


def _server_thread_priority() -> None:
    """Run the event loop (plot stream, WebSocket) at a low real-time priority.

    The server shares the GIL with the loop thread.  At normal priority a busy
    host (the browser itself) can preempt the server while it holds the GIL,
    and the loop then waits for the GIL for a whole time slice.  At
    SCHED_FIFO 5 nothing but real-time threads preempts it, and the loop
    (SCHED_FIFO 50) still preempts it.  Where it is not permitted nothing
    changes (the loop has already said so).
    """
    try_realtime_priority(SERVER_PRIORITY)


def serve(controller, host: str = "127.0.0.1", port: int = 8000, token: str | None = None, *,
          log_dir=None, autostart: bool | None = None, out=None,
          log_level: str = "warning") -> None:
    """Serve the operator console for ``controller`` until Exit or a signal.

    Parameters
    ----------
    controller
        A :class:`frictionlab.realtime.RealtimeController`.
    host, port
        Address to bind (default 127.0.0.1:8000; port 0 picks a free port).
    token : str, optional
        Access token; default ``$FRICTIONLAB_TOKEN``.  Required for an
        address that is not loopback.
    log_dir : path, optional
        Where recordings are written (default ``controller.log_dir``).
    autostart : bool, optional
        Start the loop as soon as the server is up.  Default: only for the
        in-process simulated rig (``sim``), whose pendulum starts upright;
        a real rig waits for Start (the pendulum must be balanced first).
    out : file, optional
        Where the address is printed (default stdout).

    Raises
    ------
    frictionlab.model.params.ParamError
        (field ``token``) A non-loopback address without a token, or a token
        that is too short.
    OSError
        The address cannot be bound.
    """
    token = resolve_token(token)
    check_bind(host, token)
    if autostart is None:
        autostart = getattr(controller, "backend_name", None) == "sim"
    sock = _bind(host, port)
    actual_port = sock.getsockname()[1]
    server: _Server | None = None

    def on_exit() -> None:
        if server is not None:
            server.should_exit = True

    app = create_app(controller, token, log_dir=log_dir, loopback_only=is_loopback(host),
                     autostart=autostart, on_exit=on_exit)
    config = uvicorn.Config(app, log_level=log_level, access_log=False, lifespan="on",
                            http=ConsoleHTTP, ws=_WS_IMPL, ws_max_size=MAX_BODY,
                            timeout_graceful_shutdown=3, server_header=False)
    server = _Server(config)
    server.signalled = False
    server.controller = controller
    out = sys.stdout if out is None else out
    if getattr(controller, "realtime", False):
        _server_thread_priority()
    # the address is printed when it answers: after the start-up's one-time work (the
    # warm-up, the loop's start), once the server accepts connections
    server.on_started = lambda: print(
        f"frictionlab console: {console_url(host, actual_port, token)}  "
        f"(Exit button or Ctrl-C to stop)", file=out, flush=True)
    try:
        server.run(sockets=[sock])
    finally:
        sock.close()
        if controller.running:
            controller.stop("signal" if server.signalled else "exit")
            controller.wait(10.0)
    print(f"frictionlab console: stopped{_summary(controller)}", file=out, flush=True)


def _summary(controller) -> str:
    """`` (reason; ticks, missed; log PATH)`` of the last run, for the closing line."""
    try:
        st = controller.status()
    except Exception:  # the closing line must never fail
        return ""
    if not st.get("ticks"):
        return " (the loop did not run)"
    text = f" ({st.get('stop_reason')}; {st['ticks']} ticks, {st.get('missed', 0)} missed"
    if st.get("log"):
        text += f"; log {st['log']}"
    return text + ")"
