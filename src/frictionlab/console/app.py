"""The operator console's web application (FastAPI): the thesis's user interface, Sec. 7.1.

HTTP API (JSON; every ``POST`` body is a JSON object, ``{}`` when empty):

=============================  ==========================================================
``GET /``                      the page (``static/index.html``)
``GET /api/status``            controller status + running limit-cycle figures
``GET /api/schema``            fields, units and allowed ranges of every panel
``POST /api/start``            Start (``409`` when running, ``502`` when the rig fails)
``POST /api/stop``             Stop (reason ``user``)
``POST /api/design``           State Feedback / Kalman Filter panels, Fast / Slow
``POST /api/compensation``     Compensation on/off, Friction Type, Friction Model
``POST /api/push``             disturb the pendulum (emulated rigs only)
``POST /api/record/start``     Save Data: start recording
``POST /api/record/stop``      Save Data: stop recording (the page then asks the name)
``POST /api/record/name``      the ``out>`` prompt: name the recording (``.dat`` added)
``GET /api/files/NAME.dat``    download a recording (``.dat`` or ``.csv``)
``POST /api/exit``             Exit: stop the loop safely and end the server
``WS /ws``                     plot frames (20 a second) and status (2 a second)
=============================  ==========================================================

Refused changes answer ``422`` with ``{"detail": message, "errors": [{"field",
"message"}]}`` and change nothing.  Access control is :mod:`.security`.

The server never blocks the control tick: the loop puts each tick's sample
into a bounded subscription and moves on; :class:`Hub` drains it on the
server's event loop every ``frame_period`` seconds and fans the frames out
to the connected pages, each through its own small queue from which the
oldest frames are dropped when that page cannot keep up.  What a server
thread would load on first use, holding the GIL while the loop runs, is
loaded when the server starts, before the loop does (:func:`_warm_up`).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import re
import threading
import time
from concurrent.futures import TimeoutError as FutureTimeout
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI, HTTPException, Request, WebSocket, WebSocketDisconnect
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse
from starlette.background import BackgroundTask
from starlette.staticfiles import StaticFiles

from .models import (
    CompensationRequest,
    DesignRequest,
    PushRequest,
    RecordNameRequest,
    field_errors,
    message_field,
    schema,
)
from .security import COOKIE, Guard
from .stream import SampleStream

__all__ = ["STATIC_DIR", "Hub", "create_app"]

STATIC_DIR = Path(__file__).parent / "static"
_FILE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}\.(dat|csv)$")
log = logging.getLogger("frictionlab.console")


def json_safe(obj):
    """A JSON-safe copy: NaN and infinities become None, tuples lists, paths strings."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    return obj


def _dumps(obj) -> str:
    return json.dumps(json_safe(obj), separators=(",", ":"), allow_nan=False)


class Hub:
    """Fans plot frames and status out to the connected pages (on the event loop).

    Parameters
    ----------
    stream : SampleStream
    status_fn : callable
        Returns the status dict (:func:`create_app`'s ``full_status``).
    frame_period : float
        Seconds between plot frames.
    status_period : float
        Seconds between status messages (and limit-cycle figure updates).
    lc_window : float
        Window of the running limit-cycle figures (s).
    queue_size : int
        Frames queued per page before the oldest are dropped.
    """

    def __init__(self, stream: SampleStream, status_fn, *, frame_period: float = 0.05,
                 status_period: float = 0.5, lc_window: float = 5.0, queue_size: int = 16):
        self.stream = stream
        self.status_fn = status_fn
        self.frame_period = frame_period
        self.status_period = status_period
        self.lc_window = lc_window
        self.queue_size = queue_size
        self.figures: dict = stream.figures(lc_window)
        self.clients: set[asyncio.Queue] = set()
        self.frames_sent = 0
        self.frames_dropped = 0
        self._task: asyncio.Task | None = None
        self._loop: asyncio.AbstractEventLoop | None = None

    # --- life cycle (event loop) -------------------------------------------------------

    def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self.stream.open()
        self._task = asyncio.create_task(self._run(), name="frictionlab-console-hub")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        self.stream.close()
        for q in list(self.clients):
            self._put(q, None)

    def tick(self) -> None:
        """One frame period's work: drain the samples, send a frame."""
        frame = self.stream.poll()
        if frame is not None:
            self.broadcast(_dumps(frame))

    def update_status(self) -> None:
        """Recompute the limit-cycle figures and send the status."""
        self.figures = self.stream.figures(self.lc_window)
        if self.clients:
            self.broadcast(_dumps({"type": "status", "status": self.status_fn()}))

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        next_frame = loop.time()
        next_status = next_frame
        while True:
            try:
                self.tick()
                now = loop.time()
                if now >= next_status:
                    self.update_status()
                    next_status = now + self.status_period
            except Exception:
                log.exception("console stream")
            next_frame += self.frame_period
            delay = next_frame - loop.time()
            if delay < 0:  # fell behind: skip, do not burst
                next_frame = loop.time()
                delay = 0
            await asyncio.sleep(delay)

    # --- clients -------------------------------------------------------------------------

    def add_client(self) -> asyncio.Queue:
        q: asyncio.Queue = asyncio.Queue(self.queue_size)
        self.clients.add(q)
        return q

    def remove_client(self, q: asyncio.Queue) -> None:
        self.clients.discard(q)

    def _put(self, q: asyncio.Queue, text: str | None) -> None:
        if q.full():
            with contextlib.suppress(asyncio.QueueEmpty):
                q.get_nowait()
            self.frames_dropped += 1
        q.put_nowait(text)

    def broadcast(self, text: str) -> None:
        """Queue ``text`` for every page (call on the event loop, or from any thread)."""
        loop = self._loop
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if loop is not None and running is not loop:
            loop.call_soon_threadsafe(self.broadcast, text)
            return
        for q in list(self.clients):
            self._put(q, text)
        self.frames_sent += 1


class _Console:
    """State of the console between requests: pending and saved recordings, exit."""

    def __init__(self, controller, log_dir: Path | None):
        self.controller = controller
        self.log_dir = log_dir
        self.pending: dict | None = None   # stopped recording awaiting its name
        self.saved: dict | None = None     # the last named recording
        self.exited = False
        self.was_recording = False         # as of the last status
        self.lock = threading.Lock()


def _error(status: int, message: str, field: str | None = None) -> HTTPException:
    return HTTPException(status, detail={"detail": message,
                                         "errors": [{"field": field, "message": message}]
                                         if field else []})


def _config_error(exc: Exception) -> HTTPException:
    msg = str(exc)
    name = message_field(msg)
    field = None
    if name is not None:
        field = f"params.{name}" if msg.startswith("compensation.") else name
    return _error(422, msg, field)


def create_app(controller, token: str | None = None, log_dir=None, *,
               loopback_only: bool = True, autostart: bool = False, on_exit=None,
               frame_period: float = 0.05, status_period: float = 0.5,
               lc_window: float = 5.0, max_body: int | None = None) -> Guard:
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
    console = _Console(controller, log_dir)

    def full_status() -> dict:
        st = dict(controller.status())
        with console.lock:
            if console.was_recording and not st.get("running") and console.pending is None:
                # the run ended (a safety stop, say) while recording: the recording was
                # closed under an automatic name; ask the page for its name
                with contextlib.suppress(RuntimeError, ValueError, OSError):
                    _pending(controller.record_stop(None))
            console.was_recording = bool(st.get("recording"))
        st["console"] = {
            "limit_cycle": hub.figures,
            "clients": len(hub.clients),
            "frames_sent": hub.frames_sent,
            "frames_dropped": hub.frames_dropped,
            "samples_dropped": stream.dropped,
            "pending_recording": console.pending is not None,
            "saved": console.saved,
            "token_required": token is not None,
            "exited": console.exited,
        }
        return json_safe(st)

    hub = Hub(stream, full_status, frame_period=frame_period, status_period=status_period,
              lc_window=lc_window)

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
    app.state.console = console
    app.state.stream = stream

    @app.exception_handler(RequestValidationError)
    async def _validation(request: Request, exc: RequestValidationError):
        errors = field_errors(exc)
        return JSONResponse({"detail": "; ".join(e["message"] for e in errors),
                             "errors": errors}, status_code=422)

    @app.exception_handler(HTTPException)
    async def _http(request: Request, exc: HTTPException):
        body = exc.detail if isinstance(exc.detail, dict) else {"detail": exc.detail,
                                                                 "errors": []}
        return JSONResponse(body, status_code=exc.status_code, headers=exc.headers)

    # --- page ----------------------------------------------------------------------------

    @app.get("/", include_in_schema=False)
    def index(request: Request):
        resp = FileResponse(STATIC_DIR / "index.html", media_type="text/html",
                            headers={"Cache-Control": "no-store"})
        given = request.query_params.get("token")
        if token is not None and given == token:
            resp.set_cookie(COOKIE, token, httponly=True, samesite="strict", path="/")
        return resp

    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")

    # --- status --------------------------------------------------------------------------

    @app.get("/api/status")
    async def status():  # on the event loop thread (see server.py): cheap, non-blocking
        return full_status()

    @app.get("/api/schema")
    def get_schema():
        return schema()

    # --- Start / Stop / Exit -------------------------------------------------------------

    def _guard_exited():
        if console.exited:
            raise _error(409, "the console is exiting")

    @app.post("/api/start")
    def start(body: dict | None = None):
        _guard_exited()
        if controller.running:
            raise _error(409, "the controller is already running")
        try:
            controller.start()
        except RuntimeError as exc:  # includes RigError
            code = 409 if "already running" in str(exc) or "closed" in str(exc) else 502
            raise _error(code, str(exc)) from None
        except ValueError as exc:
            raise _error(409, str(exc)) from None
        return {"ok": True, "status": full_status()}

    @app.post("/api/stop")
    def stop(body: dict | None = None):
        controller.stop("user")
        controller.wait(2.0)
        # a recording running at the stop now waits for its name (see full_status)
        return {"ok": True, "status": full_status()}

    @app.post("/api/exit")
    def exit_(body: dict | None = None):
        console.exited = True
        controller.close()
        hub.broadcast(_dumps({"type": "exit", "status": full_status()}))
        st = full_status()
        task = BackgroundTask(on_exit) if on_exit is not None else None
        return JSONResponse({"ok": True, "status": st}, background=task)

    # --- parameter changes -----------------------------------------------------------------

    def _submit(changes: dict) -> dict:
        _guard_exited()
        try:
            fut = controller.submit(changes)
        except ValueError as exc:  # ConfigError
            raise _config_error(exc) from None
        tick = None
        try:
            tick = fut.result(timeout=1.0)
        except FutureTimeout:
            pass
        return {"ok": True, "applied_tick": tick, "status": full_status()}

    @app.post("/api/design")
    def set_design(req: DesignRequest):
        return _submit(req.changes())

    @app.post("/api/compensation")
    def set_compensation(req: CompensationRequest):
        return _submit(req.changes())

    @app.post("/api/push")
    def push(req: PushRequest):
        _guard_exited()
        try:
            controller.push(req.kick)
        except (RuntimeError, ValueError) as exc:
            raise _error(409, str(exc)) from None
        return {"ok": True, "kick": req.kick}

    # --- Save Data -------------------------------------------------------------------------

    @app.post("/api/record/start")
    def record_start(body: dict | None = None):
        _guard_exited()
        try:
            controller.record_start()
        except RuntimeError as exc:
            raise _error(409, str(exc)) from None
        console.pending = None
        return {"ok": True, "status": full_status()}

    @app.post("/api/record/stop")
    def record_stop(body: dict | None = None):
        try:
            rec = controller.record_stop(None)
        except RuntimeError as exc:
            raise _error(409, str(exc)) from None
        _pending(rec)
        return {"ok": True, "rows": console.pending["rows"], "status": full_status()}

    def _pending(rec: dict) -> None:
        console.pending = {"dat": str(rec["dat"]), "csv": str(rec["csv"]),
                           "rows": int(rec.get("rows", 0))}

    @app.post("/api/record/name")
    def record_name(req: RecordNameRequest):
        rec = console.pending
        if rec is None:
            raise _error(409, "no stopped recording is waiting for a name", "name")
        folder = Path(rec["dat"]).parent
        targets = {ext: folder / f"{req.name}.{ext}" for ext in ("dat", "csv")}
        for path in targets.values():
            if path.exists():
                raise _error(409, f"{path.name} exists in {folder}; choose another name",
                             "name")
        for ext, path in targets.items():
            Path(rec[ext]).replace(path)
        console.pending = None
        console.saved = {"name": req.name, "rows": rec["rows"],
                         "dat": str(targets["dat"]), "csv": str(targets["csv"]),
                         "urls": {"dat": f"/api/files/{req.name}.dat",
                                  "csv": f"/api/files/{req.name}.csv"},
                         "time": time.strftime("%Y-%m-%dT%H:%M:%S")}
        return {"ok": True, **console.saved}

    @app.get("/api/files/{filename}")
    def download(filename: str):
        if log_dir is None or not _FILE_NAME.match(filename):
            raise _error(404, "no such recording")
        path = (log_dir / filename)
        if not path.is_file():
            raise _error(404, "no such recording")
        media = "text/csv" if filename.endswith(".csv") else "text/plain"
        return FileResponse(path, media_type=media, filename=filename)

    # --- stream --------------------------------------------------------------------------

    @app.websocket("/ws")
    async def ws(websocket: WebSocket):
        await websocket.accept()
        q = hub.add_client()
        try:
            await websocket.send_text(_dumps(stream.history(30.0)))
            await websocket.send_text(_dumps({"type": "status", "status": full_status()}))
            receiver = asyncio.create_task(_drain_incoming(websocket))
            while True:
                getter = asyncio.create_task(q.get())
                done, _ = await asyncio.wait({getter, receiver},
                                             return_when=asyncio.FIRST_COMPLETED)
                if receiver in done:
                    getter.cancel()
                    break
                text = getter.result()
                if text is None:
                    break
                await websocket.send_text(text)
            receiver.cancel()
            with contextlib.suppress(RuntimeError, WebSocketDisconnect):
                await websocket.close()
        except (WebSocketDisconnect, RuntimeError, OSError):
            pass
        finally:
            hub.remove_client(q)

    return Guard(app, token, loopback_only=loopback_only,
                 **({} if max_body is None else {"max_body": max_body}))


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


async def _drain_incoming(websocket: WebSocket) -> None:
    """Read (and ignore) what the page sends until it disconnects."""
    with contextlib.suppress(WebSocketDisconnect, RuntimeError, OSError):
        while True:
            msg = await websocket.receive()
            if msg["type"] == "websocket.disconnect":
                return
