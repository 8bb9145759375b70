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

The server never blocks the control tick: the loop puts each tick's sample
into a bounded subscription and moves on; :class:`Hub` drains it on the
server's event loop every ``frame_period`` seconds and fans the frames out
to the connected pages, each through its own small queue from which the
oldest frames are dropped when that page cannot keep up; its work is per
sample, not per page (a connecting page gets history serialised already).
Changes the model predicts unsafe answer ``422`` with ``confirm_required``
unless the request has ``"confirm": true`` (:func:`_change_error`).  What a server
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
from collections import deque
from concurrent.futures import TimeoutError as FutureTimeout
from contextlib import asynccontextmanager
from pathlib import Path

import numpy as np
from fastapi import FastAPI, HTTPException, Request, WebSocket, WebSocketDisconnect
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse
from starlette.background import BackgroundTask
from starlette.staticfiles import StaticFiles

from ..io.jsonsafe import json_safe
from ..realtime.api import ControllerStateError
from ..realtime.params import ChangeError, UnsafeChange
from .models import (
    CompensationRequest,
    DesignRequest,
    ExperimentRequest,
    PushRequest,
    RecordNameRequest,
    field_errors,
    request_field,
    schema,
)
from .security import COOKIE, Guard
from .stream import PLOT_SIGNALS, SampleStream, decimate, frame_json

__all__ = ["MAX_PAGES", "STATIC_DIR", "Hub", "Page", "create_app"]

STATIC_DIR = Path(__file__).parent / "static"
_FILE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}\.(dat|csv)$")
log = logging.getLogger("frictionlab.console")


def _dumps(obj) -> str:
    return json.dumps(json_safe(obj), separators=(",", ":"), allow_nan=False)


class Page:
    """One connected page: the texts waiting for it, oldest dropped when full.

    Parameters
    ----------
    backlog : list of str
        What the page gets first: a reset, the cached history chunks, the
        frames since the last chunk and the last status (shared texts, not
        copies: connecting serialises nothing).
    queue_size : int
        Live texts queued before the oldest are dropped.
    """

    def __init__(self, backlog: list[str], queue_size: int):
        self.backlog = backlog
        self.queue: asyncio.Queue = asyncio.Queue(queue_size)
        self.dropped = 0

    def put(self, text: str | None) -> bool:
        """Queue ``text`` (None ends the page); True if an older text was dropped."""
        dropped = False
        if self.queue.full():
            with contextlib.suppress(asyncio.QueueEmpty):
                self.queue.get_nowait()
            self.dropped += 1
            dropped = True
        self.queue.put_nowait(text)
        return dropped


#: Pages (WebSocket clients) served at once; one more is refused (503).
MAX_PAGES = 32
#: A page that has not taken a message for this long is disconnected (s).
SEND_TIMEOUT = 10.0
#: Reset message a new page gets first (its plot starts empty).
_RESET_TEXT = json.dumps(frame_json(np.zeros((1 + len(PLOT_SIGNALS), 0)), reset=True),
                         separators=(",", ":"))


class Hub:
    """Fans plot frames and status out to the connected pages (on the event loop).

    The work is per sample, never per page: each frame period the new
    samples are serialised once into a frame that every page's queue
    shares, and every ``chunk`` seconds the samples of the last chunk are
    serialised once more, thinned to ``chunk_points``, into a history chunk.
    A page that connects gets the cached chunks (the last ``history``
    seconds), the frames since the last chunk and the last status, all
    texts made already: connecting costs the loop nothing (the whole 30 s
    history serialised at once held the interpreter lock for 25 ms, five
    periods of the loop).  Every serialisation is of at most ``chunk_points``
    samples.

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
        Live texts queued per page before the oldest are dropped.
    history : float
        Seconds of history a new page gets.
    chunk : float
        Seconds per history chunk.
    chunk_points : int
        Samples per history chunk (100 per second: the plot's resolution).
    max_pages : int
        Pages served at once.
    """

    def __init__(self, stream: SampleStream, status_fn, *, frame_period: float = 0.05,
                 status_period: float = 0.5, lc_window: float = 5.0, queue_size: int = 16,
                 history: float = 30.0, chunk: float = 1.0, chunk_points: int = 100,
                 max_pages: int = MAX_PAGES):
        self.stream = stream
        self.status_fn = status_fn
        self.frame_period = frame_period
        self.status_period = status_period
        self.lc_window = lc_window
        self.queue_size = queue_size
        self.chunk = chunk
        self.chunk_points = chunk_points
        self.max_pages = max_pages
        self.figures: dict = stream.figures(lc_window)
        self.clients: set[Page] = set()
        self.history: deque[str] = deque(maxlen=math.ceil(history / chunk))
        self._recent: list[str] = []            # frames since the last chunk
        self._pending: list[np.ndarray] = []    # their samples
        self.status_text: str | None = None
        self.frames_sent = 0
        self.frames_dropped = 0
        self.pages_refused = 0
        self.serialised = 0                     # samples serialised, frames and chunks
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
        for page in list(self.clients):
            page.put(None)

    def _serialise(self, block: np.ndarray, max_points: int, reset: bool = False) -> str:
        block = decimate(block, max_points)
        self.serialised += block.shape[1]
        return json.dumps(frame_json(block, reset=reset), separators=(",", ":"),
                          allow_nan=False)

    def tick(self) -> None:
        """One frame period's work: drain the samples, send a frame, cache history."""
        got = self.stream.poll()
        if got is None:
            return
        block, reset = got
        if reset:
            self.history.clear()
            self._recent.clear()
            self._pending.clear()
        text = self._serialise(block, self.stream.max_points, reset)
        self._recent.append(text)
        self._pending.append(block)
        t0, t1 = self._pending[0][0, 0], block[0, -1]
        if t1 - t0 >= self.chunk - 0.5 * self.stream.h:
            self.history.append(self._serialise(np.hstack(self._pending), self.chunk_points))
            self._recent.clear()
            self._pending.clear()
        self.broadcast(text)

    def update_status(self) -> None:
        """Recompute the limit-cycle figures and send the status."""
        self.figures = self.stream.figures(self.lc_window)
        self.status_text = _dumps({"type": "status", "status": self.status_fn()})
        if self.clients:
            self.broadcast(self.status_text)

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

    def add_client(self) -> Page | None:
        """A new page with its backlog, or None when ``max_pages`` are connected.

        On the event loop: the backlog is the state at this instant and every
        later frame goes to the page's queue, so nothing is missed or doubled.
        """
        if len(self.clients) >= self.max_pages:
            self.pages_refused += 1
            return None
        if self.status_text is None:
            self.status_text = _dumps({"type": "status", "status": self.status_fn()})
        page = Page([_RESET_TEXT, *self.history, *self._recent, self.status_text],
                    self.queue_size)
        self.clients.add(page)
        return page

    def remove_client(self, page: Page) -> None:
        self.clients.discard(page)

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
        for page in list(self.clients):
            if page.put(text):
                self.frames_dropped += 1
        self.frames_sent += 1


class _Console:
    """State of the console between requests: pending and saved recordings, exit."""

    def __init__(self, controller, log_dir: Path | None):
        self.controller = controller
        self.log_dir = log_dir
        self.pending: dict | None = None   # stopped recording awaiting its name
        self.saved: dict | None = None     # the last named recording
        self.exited = False
        self.lock = threading.Lock()
        #: the Experiments panel's last experiment: name, state (running, done,
        #: stopped, failed), estimates, message, log
        self.experiment: dict | None = None

    def run_experiment(self, exp) -> None:
        """Start ``exp`` on the controller and analyse its log when the run ends (in a
        thread of its own)."""
        ctl = self.controller
        with self.lock:
            self.experiment = {"name": exp.name, "state": "running", "estimates": None,
                               "warnings": [], "message": None, "log": None}
        ctl.start(experiment=exp)
        threading.Thread(target=self._analyse, args=(exp,), name="frictionlab-experiment",
                         daemon=True).start()

    def _analyse(self, exp) -> None:
        from ..studies.identification.experiments import IdentificationError
        from ..studies.identification.onrig import analyse_log

        ctl = self.controller
        ctl.wait()
        st = ctl.last_stats or {}
        out = {"log": st.get("log")}
        if st.get("stop_reason") != "finished":
            out.update(state="stopped", message=f"stopped before it finished: "
                       f"{st.get('stop_reason')} ({st.get('stop_detail') or ''}); the motor "
                       "was set to zero")
        elif not st.get("log"):
            out.update(state="failed", message="the run was not logged: nothing to analyse")
        else:
            try:
                from ..io.logs import read_log

                log = read_log(st["log"], ctl.cfg.design.h)
                res = analyse_log(exp.name, log, ctl.cfg, marks=dict(exp.marks))
            except (IdentificationError, ValueError, OSError) as exc:
                out.update(state="failed", message=str(exc))
            else:
                out.update(state="done", message="done",
                           estimates={k: v for k, v in res.items()
                                      if isinstance(v, float) or v is None},
                           warnings=list(res.get("warnings", [])))
        with self.lock:
            if self.experiment is not None:
                self.experiment.update(out)


def _error(status: int, message: str, field: str | None = None) -> HTTPException:
    return HTTPException(status, detail={"detail": message,
                                         "errors": [{"field": field, "message": message}]
                                         if field else []})


def _change_error(exc: ChangeError) -> HTTPException:
    """422 for a refused change, each refused key located at its request field.

    An :class:`~frictionlab.realtime.params.UnsafeChange` also carries the
    model's diagnostics (``check``), what would pass (``safe``, by request
    field) and ``confirm_required``: the same request with ``"confirm": true``
    applies it anyway.
    """
    message = str(exc)
    fields = [request_field(k) for k in exc.keys]
    if not isinstance(exc, UnsafeChange):
        return HTTPException(422, detail={"detail": message, "errors": [
            {"field": f, "message": message} for f in fields]})
    check = exc.check
    summary = _VERDICT_TEXT[check.verdict](check)
    values = exc.safe.get("values", {})
    errors = []
    for key, f in zip(exc.keys, fields, strict=True):
        text = summary
        if key in values:
            text += f"; the check passes up to {values[key]:g}"
        elif key == "error_signal" and "error_signals" in exc.safe:
            text += "; passing: " + (", ".join(exc.safe["error_signals"]) or "none")
        errors.append({"field": f, "message": text})
    safe = {request_field(k): v for k, v in values.items()}
    if "error_signals" in exc.safe:
        safe["error_signal"] = exc.safe["error_signals"]
    return HTTPException(422, detail={"detail": message, "errors": errors,
                                      "confirm_required": True, "check": check.to_json(),
                                      "safe": safe})


#: Short reasons beside a field, from a check's verdict and numbers.
_VERDICT_TEXT = {
    "unstable": lambda c: f"the loop would be unstable (eigenvalue modulus "
                          f"{c.spectral_radius:.4g} > 1)",
    "compensator_unstable": lambda c: f"the compensator would make the loop unstable "
                                      f"(spectral radius {c.compensator_radius:.4g} > 1)",
    "saturating": lambda c: f"u would saturate (predicted peak {c.peak_u:.3g} > "
                            f"{c.u_max:.3g} m/s^2)",
    "ok": lambda c: "passes",
}


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
            if (console.pending is None and not st.get("running")
                    and getattr(controller, "unnamed_recording", None) is not None):
                # the run ended (a safety stop, say) while recording: the recording was
                # closed under an automatic name; ask the page for its name (asked of the
                # controller, not inferred from an earlier status that may be stale)
                with contextlib.suppress(RuntimeError, ValueError, OSError):
                    _pending(controller.record_stop(None))
        st["console"] = {
            "limit_cycle": hub.figures,
            "clients": len(hub.clients),
            "frames_sent": hub.frames_sent,
            "frames_dropped": hub.frames_dropped,
            "pages_refused": hub.pages_refused,
            "samples_serialised": hub.serialised,
            "samples_dropped": stream.dropped,
            "pending_recording": console.pending is not None,
            "saved": console.saved,
            "token_required": token is not None,
            "exited": console.exited,
            "experiment": None if console.experiment is None else dict(console.experiment),
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
        return _start(None)

    @app.post("/api/swingup")
    def swingup(body: dict | None = None):
        return _start(True)

    def _start(swing_up: bool | None) -> dict:
        _guard_exited()
        if controller.running:
            raise _error(409, "the controller is already running")
        try:
            if swing_up is None:
                controller.start()
            else:
                controller.start(swing_up=swing_up)
        except RuntimeError as exc:  # includes RigError
            code = 409 if isinstance(exc, ControllerStateError) else 502
            raise _error(code, str(exc)) from None
        except ValueError as exc:
            raise _error(409, str(exc)) from None
        return {"ok": True, "status": full_status()}

    # Stop and Exit run on the event loop, not in the thread pool a flood of slow
    # requests could fill: they always get through.
    async def _wait_stopped(timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while controller.running and time.monotonic() < deadline:
            await asyncio.sleep(0.005)

    @app.post("/api/stop")
    async def stop(body: dict | None = None):
        controller.stop("user")
        await _wait_stopped(2.0)
        # a recording running at the stop now waits for its name (see full_status)
        return {"ok": True, "status": full_status()}

    @app.post("/api/exit")
    async def exit_(body: dict | None = None):
        console.exited = True
        if controller.running:
            controller.stop("exit")
            await _wait_stopped(10.0)
        controller.close()  # the loop has stopped: returns at once
        hub.broadcast(_dumps({"type": "exit", "status": full_status()}))
        st = full_status()
        task = BackgroundTask(on_exit) if on_exit is not None else None
        return JSONResponse({"ok": True, "status": st}, background=task)

    # --- parameter changes -----------------------------------------------------------------

    def _submit(changes: dict, confirm: bool) -> dict:
        _guard_exited()
        try:
            fut = controller.submit(changes, confirm=confirm)
        except ChangeError as exc:
            raise _change_error(exc) from None
        tick = None
        try:
            tick = fut.result(timeout=1.0)
        except FutureTimeout:
            pass
        return {"ok": True, "applied_tick": tick, "status": full_status()}

    @app.post("/api/design")
    def set_design(req: DesignRequest):
        return _submit(req.changes(), req.confirm)

    @app.post("/api/compensation")
    def set_compensation(req: CompensationRequest):
        return _submit(req.changes(), req.confirm)

    @app.post("/api/push")
    def push(req: PushRequest):
        _guard_exited()
        try:
            controller.push(req.kick)
        except (RuntimeError, ValueError) as exc:
            raise _error(409, str(exc)) from None
        return {"ok": True, "kick": req.kick}

    # --- Experiments ------------------------------------------------------------------------

    @app.post("/api/experiment")
    def run_experiment(req: ExperimentRequest):
        from ..realtime.experiment import Limits
        from ..studies.identification.onrig import make_rig_experiment

        _guard_exited()
        if controller.running:
            raise _error(409, "the controller is running: stop it before an experiment")
        try:
            limits = Limits(**req.limits)
        except ValueError as exc:
            raise _error(422, str(exc), "limits") from None
        try:
            exp = make_rig_experiment(req.name, controller.cfg, limits, **req.options)
        except (TypeError, ValueError) as exc:
            raise _error(422, f"{req.name}: {exc}", "options") from None
        if not req.confirm:
            message = (f"the {req.name} experiment drives the motor: the arm will move (limits:"
                       f" arm speed {limits.max_speed:g} rad/s, travel {limits.max_travel:g} "
                       f"rad, |u_DA| {limits.max_u_da:g}); Stop zeroes the motor at once. "
                       "Send the request with \"confirm\": true to run it")
            raise HTTPException(422, detail={"detail": message, "errors": [],
                                             "confirm_required": True})
        try:
            console.run_experiment(exp)
        except RuntimeError as exc:  # includes RigError
            code = 409 if isinstance(exc, ControllerStateError) else 502
            raise _error(code, str(exc)) from None
        return {"ok": True, "status": full_status()}

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
        page = hub.add_client()
        if page is None:
            await _refuse_page(websocket)
            return
        try:
            await websocket.accept()
            receiver = asyncio.create_task(_drain_incoming(websocket))
            try:
                await _serve_page(websocket, page, receiver)
            finally:
                receiver.cancel()
            with contextlib.suppress(RuntimeError, WebSocketDisconnect, OSError):
                await websocket.close()
        except (WebSocketDisconnect, RuntimeError, OSError, TimeoutError):
            pass
        finally:
            hub.remove_client(page)

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


async def _refuse_page(websocket: WebSocket) -> None:
    """Refuse a page beyond :data:`MAX_PAGES`: 503 (a close where denial is not supported)."""
    body = JSONResponse({"detail": f"too many pages connected (at most {MAX_PAGES})",
                         "errors": []}, status_code=503)
    try:
        await websocket.send_denial_response(body)
    except RuntimeError:
        await websocket.close(code=1013)


async def _serve_page(websocket: WebSocket, page: Page, receiver: asyncio.Task) -> None:
    """Send ``page`` its backlog, then its queue, until it or the server leaves.

    A page that takes no message for :data:`SEND_TIMEOUT` seconds is
    disconnected (its queue meanwhile drops the oldest frames).
    """
    for text in page.backlog:
        await asyncio.wait_for(websocket.send_text(text), SEND_TIMEOUT)
    page.backlog = []
    while True:
        getter = asyncio.create_task(page.queue.get())
        done, _ = await asyncio.wait({getter, receiver}, return_when=asyncio.FIRST_COMPLETED)
        if receiver in done:
            getter.cancel()
            return
        text = getter.result()
        if text is None:
            return
        await asyncio.wait_for(websocket.send_text(text), SEND_TIMEOUT)


async def _drain_incoming(websocket: WebSocket) -> None:
    """Read (and ignore) what the page sends until it disconnects."""
    with contextlib.suppress(WebSocketDisconnect, RuntimeError, OSError):
        while True:
            msg = await websocket.receive()
            if msg["type"] == "websocket.disconnect":
                return
