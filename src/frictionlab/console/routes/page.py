"""The page (``GET /``), its static files, the status and the panels' schema."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, Request
from fastapi.responses import FileResponse

from ..models import schema
from ..security import COOKIE
from ..state import Context

__all__ = ["STATIC_DIR", "router"]

STATIC_DIR = Path(__file__).resolve().parent.parent / "static"


def router(ctx: Context) -> APIRouter:
    """``GET /``, ``GET /api/status``, ``GET /api/schema`` (the static files are mounted by
    :func:`frictionlab.console.create_app`)."""
    r = APIRouter()

    @r.get("/", include_in_schema=False)
    def index(request: Request):
        resp = FileResponse(STATIC_DIR / "index.html", media_type="text/html",
                            headers={"Cache-Control": "no-store"})
        given = request.query_params.get("token")
        if ctx.token is not None and given == ctx.token:
            resp.set_cookie(COOKIE, ctx.token, httponly=True, samesite="strict", path="/")
        return resp

    @r.get("/api/status")
    async def status():  # on the event loop thread (see server.py): cheap, non-blocking
        return ctx.full_status()

    @r.get("/api/schema")
    def get_schema():
        return schema(ctx.controller.cfg)

    return r
