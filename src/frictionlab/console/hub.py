"""The console's plot and status stream: the hub that fans frames out to the pages.

The loop puts each tick's sample into a bounded subscription and moves on;
:class:`Hub` drains it on the server's event loop every ``frame_period``
seconds and fans the frames out to the connected pages, each through its own
small queue (:class:`Page`) from which the oldest frames are dropped when that
page cannot keep up; its work is per sample, not per page (a connecting page
gets history serialised already).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
from collections import deque

import numpy as np

from ..io.jsonsafe import json_safe
from .stream import PLOT_SIGNALS, SampleStream, decimate, frame_json

__all__ = ["MAX_PAGES", "SEND_TIMEOUT", "Hub", "Page", "dumps"]

log = logging.getLogger("frictionlab.console")


def dumps(obj) -> str:
    """Compact JSON of ``obj`` with NaN and infinities made null."""
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
        self.status_text = dumps({"type": "status", "status": self.status_fn()})
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
            self.status_text = dumps({"type": "status", "status": self.status_fn()})
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

