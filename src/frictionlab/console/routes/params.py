"""The State Feedback / Kalman Filter panels, Compensation, and the push."""

from __future__ import annotations

import math
from concurrent.futures import TimeoutError as FutureTimeout

from fastapi import APIRouter

from ...realtime.params import ChangeError
from ..errors import change_error, http_error
from ..models import CompensationRequest, DesignRequest, PushRequest
from ..state import Context
from .run import guard_exited

__all__ = ["router"]


def router(ctx: Context) -> APIRouter:
    """``POST /api/design``, ``/api/compensation``, ``/api/push``."""
    r = APIRouter()
    controller = ctx.controller

    def _submit(changes: dict, confirm: bool) -> dict:
        guard_exited(ctx)
        try:
            fut = controller.submit(changes, confirm=confirm)
        except ChangeError as exc:
            raise change_error(exc) from None
        tick = None
        try:
            tick = fut.result(timeout=1.0)
        except FutureTimeout:
            pass
        return {"ok": True, "applied_tick": tick, "status": ctx.full_status()}

    @r.post("/api/design")
    def set_design(req: DesignRequest):
        cfg = controller.cfg
        if cfg.motor and req.omega0 is not None and not math.isclose(
                req.omega0, cfg.plant.omega0, rel_tol=1e-5):  # the page's 6 digits pass
            # a motor plant's designs are made on its own linearisation, with its
            # omega_0: another value would be shown but change nothing
            raise http_error(422, f"design.omega0 = {req.omega0:g} rad/s refused: the "
                             f"{cfg.plant_kind} plant's designs use its own omega_0, "
                             f"{cfg.plant.omega0:.6g} rad/s (plant.omega0, set at the start)",
                             "omega0")
        return _submit(req.changes(), req.confirm)

    @r.post("/api/compensation")
    def set_compensation(req: CompensationRequest):
        return _submit(req.changes(), req.confirm)

    @r.post("/api/push")
    def push(req: PushRequest):
        guard_exited(ctx)
        try:
            controller.push(req.kick)
        except (RuntimeError, ValueError) as exc:
            raise http_error(409, str(exc)) from None
        return {"ok": True, "kick": req.kick}

    return r
