"""The plot and status stream: ``WS /ws`` (20 frames and 2 status messages a second)."""

from __future__ import annotations

import asyncio
import contextlib

from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from fastapi.responses import JSONResponse

from ..hub import MAX_PAGES, SEND_TIMEOUT, Page
from ..state import Context

__all__ = ["drain_incoming", "refuse_page", "router", "serve_page"]


def router(ctx: Context) -> APIRouter:
    """``WS /ws``: the page's backlog, then its live frames, until either side leaves."""
    r = APIRouter()

    @r.websocket("/ws")
    async def ws(websocket: WebSocket):
        hub = ctx.hub
        page = hub.add_client()
        if page is None:
            await refuse_page(websocket)
            return
        try:
            await websocket.accept()
            receiver = asyncio.create_task(drain_incoming(websocket))
            try:
                await serve_page(websocket, page, receiver)
            finally:
                receiver.cancel()
            with contextlib.suppress(RuntimeError, WebSocketDisconnect, OSError):
                await websocket.close()
        except (WebSocketDisconnect, RuntimeError, OSError, TimeoutError):
            pass
        finally:
            hub.remove_client(page)

    return r


async def refuse_page(websocket: WebSocket) -> None:
    """Refuse a page beyond :data:`MAX_PAGES`: 503 (a close where denial is not supported)."""
    body = JSONResponse({"detail": f"too many pages connected (at most {MAX_PAGES})",
                         "errors": []}, status_code=503)
    try:
        await websocket.send_denial_response(body)
    except RuntimeError:
        await websocket.close(code=1013)


async def serve_page(websocket: WebSocket, page: Page, receiver: asyncio.Task) -> None:
    """Send ``page`` its backlog, then its queue, until it or the server leaves.

    A page that takes no message for :data:`SEND_TIMEOUT` seconds is
    disconnected (its queue meanwhile drops the oldest frames).
    """
    for text in page.backlog:
        await asyncio.wait_for(websocket.send_text(text), SEND_TIMEOUT)
    page.backlog = []
    while True:
        getter = asyncio.create_task(page.queue.get())
        try:
            done, _ = await asyncio.wait({getter, receiver},
                                         return_when=asyncio.FIRST_COMPLETED)
        finally:  # the page left, or the server cancelled us: no getter left pending
            if not getter.done():
                getter.cancel()
        if receiver in done:
            return
        text = getter.result()
        if text is None:
            return
        await asyncio.wait_for(websocket.send_text(text), SEND_TIMEOUT)


async def drain_incoming(websocket: WebSocket) -> None:
    """Read (and ignore) what the page sends until it disconnects."""
    with contextlib.suppress(WebSocketDisconnect, RuntimeError, OSError):
        while True:
            msg = await websocket.receive()
            if msg["type"] == "websocket.disconnect":
                return
