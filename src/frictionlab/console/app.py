"""The operator console's web application (FastAPI): the thesis's user interface, Sec. 7.1.

HTTP API (JSON; every ``POST`` body is a JSON object, ``{}`` when empty):

=============================  ==========================================================
``GET /``                      the page (``static/index.html``)
``GET /api/status``            controller status + running limit-cycle figures
``GET /api/schema``            fields, units and allowed ranges of every panel
``POST /api/start``            Start (``409`` when running, ``502`` when the rig fails)
``POST /api/swingup``          Swing up: Start with the swing-up from hanging (``409``
                               when running); the status's ``swing_up.phase`` is
                               ``swinging``, ``caught``, ``balancing`` (or ``stopped``)
``POST /api/stop``             Stop (reason ``user``)
``POST /api/design``           State Feedback / Kalman Filter panels, Fast / Slow (+ confirm)
``POST /api/compensation``     Compensation on/off, Friction Type, Friction Model (+ confirm)
``POST /api/push``             disturb the pendulum (emulated rigs only)
``POST /api/experiment``       Experiments panel: run an identification experiment (+ confirm)
``POST /api/record/start``     Save Data: start recording
``POST /api/record/stop``      Save Data: stop recording (the page then asks the name)
``POST /api/record/name``      the ``out>`` prompt: name the recording (``.dat`` added)
``GET /api/files/NAME.dat``    download a recording (``.dat`` or ``.csv``)
``POST /api/exit``             Exit: stop the loop safely and end the server
``WS /ws``                     plot frames (20 a second) and status (2 a second)
=============================  ==========================================================

Refused changes answer ``422`` with ``{"detail": message, "errors": [{"field",
"message"}]}`` and change nothing.  Access control is :mod:`.security`.

The routes are one ``APIRouter`` module per concept (:mod:`.routes`); the
plot stream's hub is :mod:`.hub`, the error answers :mod:`.errors`, the shared
state :mod:`.state`.  The server never blocks the control tick (:class:`Hub`).
Changes the model predicts unsafe answer ``422`` with ``confirm_required``
unless the request has ``"confirm": true`` (:func:`.errors.change_error`).  What a
server thread would load on first use, holding the GIL while the loop runs, is
loaded when the server starts, before the loop does (:func:`_warm_up`).
"""

from __future__ import annotations

import asyncio
import logging
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI, HTTPException, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.staticfiles import StaticFiles

from ..io.jsonsafe import json_safe
from . import routes
from .hub import MAX_PAGES, Hub, Page
from .models import field_errors, field_units
from .routes.page import STATIC_DIR
from .security import Guard
from .state import ConsoleState, Context
from .stream import SampleStream

__all__ = ["MAX_PAGES", "STATIC_DIR", "Hub", "Page", "create_app", "json_safe"]

log = logging.getLogger("frictionlab.console")


def create_app(controller, token: str | None = None, log_dir=None, *,
               loopback_only: bool = True, autostart: bool = False, on_exit=None,
               frame_period: float = 0.05, status_period: float = 0.5,
               lc_window: float = 5.0, max_body: int | None = None,
               body_timeout: float | None = None) -> Guard:
    """The console application for ``controller`` (an ASGI app).

    Parameters
    ----------
    controller
        A :class:`frictionlab.realtime.RealtimeController` (or an object with
        the same methods).
    token : str, optional
        Token every request must carry (see :mod:`.security`).
    log_dir : path, optional
        Where recordings are (default: ``controller.log_dir``).
    loopback_only : bool
        Accept only loopback ``Host`` headers (the server binds to loopback).
    autostart : bool
        Start the controller when the server starts.
    on_exit : callable, optional
        Called after the Exit button stopped the loop (ends the server).
    frame_period, status_period, lc_window : float
        See :class:`Hub`.
    max_body : int, optional
        Request size limit (default :data:`.security.MAX_BODY`).
    body_timeout : float, optional
        Seconds a request body has to arrive (default :data:`.security.BODY_TIMEOUT`).

    Returns
    -------
    Guard
        The FastAPI app wrapped in the access-control middleware; the
        FastAPI app itself is ``.app`` (its ``state`` holds ``hub`` and
        ``console``).
    """
    log_dir = Path(log_dir) if log_dir is not None else getattr(controller, "log_dir", None)
    h = float(controller.status().get("h") or 0.005)
    stream = SampleStream(controller, h=h, history=40.0)
    ctx = Context(controller, ConsoleState(controller, log_dir), token=token, on_exit=on_exit)
    hub = ctx.hub = Hub(stream, ctx.full_status, frame_period=frame_period,
                        status_period=status_period, lc_window=lc_window)

    @asynccontextmanager
    async def lifespan(app):
        await _warm_up(app, stream)  # before the loop starts (autostart below)
        hub.start()
        if autostart and not controller.running:
            try:
                await asyncio.to_thread(controller.start)
            except Exception as exc:
                log.error("frictionlab console: could not start the controller: %s", exc)
        try:
            yield
        finally:
            await hub.stop()

    app = FastAPI(title="frictionlab operator console", lifespan=lifespan, docs_url=None,
                  redoc_url=None, openapi_url=None)
    app.state.hub = hub
    app.state.console = ctx.state
    app.state.stream = stream
    app.state.context = ctx

    units = field_units(controller.cfg) if hasattr(controller, "cfg") else {}

    @app.exception_handler(RequestValidationError)
    async def _validation(request: Request, exc: RequestValidationError):
        errors = field_errors(exc, units)
        return JSONResponse({"detail": "; ".join(e["message"] for e in errors),
                             "errors": errors}, status_code=422)

    @app.exception_handler(HTTPException)
    async def _http(request: Request, exc: HTTPException):
        body = exc.detail if isinstance(exc.detail, dict) else {"detail": exc.detail,
                                                                 "errors": []}
        return JSONResponse(body, status_code=exc.status_code, headers=exc.headers)

    for module in routes.MODULES:
        app.include_router(module.router(ctx))
    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")

    limits = {k: v for k, v in (("max_body", max_body), ("body_timeout", body_timeout))
              if v is not None}
    return Guard(app, token, loopback_only=loopback_only, **limits)


#: Requests served once, to nobody, before the loop starts (see :func:`_warm_up`).
_WARM_UP_PATHS = ("/", "/static/app.js", "/api/schema")


async def _warm_up(app: FastAPI, stream: SampleStream) -> None:
    """Do the console's one-time work now, before the loop starts.

    On first use each of these loaded code or tables on a server thread,
    holding the GIL while the loop ran (a stall of the loop): the
    limit-cycle feature kernels (:meth:`SampleStream.warm`, 0.3 s), and
    what the first requests load (anyio's thread pool for plain ``def``
    routes and its file I/O for files, 10 ms; the MIME type tables).  The
    latter are loaded by serving a few requests through ``app`` itself,
    the responses discarded.
    """
    stream.warm()
    for path in _WARM_UP_PATHS:
        await _serve_once(app, path)


async def _serve_once(app: FastAPI, path: str) -> None:
    """One ``GET path`` through the ASGI ``app`` from loopback; the response is dropped."""
    scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1",
             "method": "GET", "scheme": "http", "path": path, "raw_path": path.encode(),
             "root_path": "", "query_string": b"", "headers": [(b"host", b"127.0.0.1")],
             "client": ("127.0.0.1", 0), "server": ("127.0.0.1", 0)}

    requested = False
    answered = asyncio.Event()

    async def receive():
        nonlocal requested
        if not requested:
            requested = True
            return {"type": "http.request", "body": b"", "more_body": False}
        await answered.wait()  # the client "leaves" once the response is complete
        return {"type": "http.disconnect"}

    async def send(message):
        if message["type"] == "http.response.body" and not message.get("more_body"):
            answered.set()

    await app(scope, receive, send)
