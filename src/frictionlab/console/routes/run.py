"""Start, Swing up, Stop and Exit."""

from __future__ import annotations

import asyncio
import time

from fastapi import APIRouter
from fastapi.responses import JSONResponse
from starlette.background import BackgroundTask

from ...realtime.api import ControllerStateError
from ..errors import http_error
from ..hub import dumps
from ..state import Context

__all__ = ["guard_exited", "router"]


def guard_exited(ctx: Context) -> None:
    """409 once Exit was pressed: nothing starts or changes any more."""
    if ctx.state.exited:
        raise http_error(409, "the console is exiting")


def router(ctx: Context) -> APIRouter:
    """``POST /api/start``, ``/api/swingup``, ``/api/stop``, ``/api/exit``."""
    r = APIRouter()
    controller = ctx.controller

    @r.post("/api/start")
    def start(body: dict | None = None):
        return _start(None)

    @r.post("/api/swingup")
    def swingup(body: dict | None = None):
        return _start(True)

    def _start(swing_up: bool | None) -> dict:
        guard_exited(ctx)
        if controller.running:
            raise http_error(409, "the controller is already running")
        try:
            if swing_up is None:
                controller.start()
            else:
                # Swing up starts with the pendulum hanging at rest on an emulated rig
                # (sim, rig-sim over UDP); a real rig starts from where the pendulum is
                controller.start(swing_up=swing_up, hanging=True)
        except RuntimeError as exc:  # includes RigError
            code = 409 if isinstance(exc, ControllerStateError) else 502
            raise http_error(code, str(exc)) from None
        except ValueError as exc:
            raise http_error(409, str(exc)) from None
        return {"ok": True, "status": ctx.full_status()}

    # Stop and Exit run on the event loop, not in the thread pool a flood of slow
    # requests could fill: they always get through.
    async def _wait_stopped(timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while controller.running and time.monotonic() < deadline:
            await asyncio.sleep(0.005)

    @r.post("/api/stop")
    async def stop(body: dict | None = None):
        controller.stop("user")
        await _wait_stopped(2.0)
        # a recording running at the stop now waits for its name (see full_status)
        return {"ok": True, "status": ctx.full_status()}

    @r.post("/api/exit")
    async def exit_(body: dict | None = None):
        ctx.state.exited = True
        if controller.running:
            controller.stop("exit")
            await _wait_stopped(10.0)
        controller.close()  # the loop has stopped: returns at once
        ctx.hub.broadcast(dumps({"type": "exit", "status": ctx.full_status()}))
        st = ctx.full_status()
        task = BackgroundTask(ctx.on_exit) if ctx.on_exit is not None else None
        return JSONResponse({"ok": True, "status": st}, background=task)

    return r
