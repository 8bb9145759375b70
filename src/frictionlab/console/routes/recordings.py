"""Save Data: start and stop a recording, the ``out>`` prompt naming it, downloads."""

from __future__ import annotations

import re
import time
from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import FileResponse

from ..errors import http_error
from ..models import RecordNameRequest
from ..state import Context
from .run import guard_exited

__all__ = ["FILE_NAME", "router"]

#: Names ``GET /api/files/NAME`` serves (a full match: no path, no trailing newline).
FILE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,127}\.(dat|csv)")


def router(ctx: Context) -> APIRouter:
    """``POST /api/record/start``, ``/api/record/stop``, ``/api/record/name``,
    ``GET /api/files/NAME``."""
    r = APIRouter()
    controller, console = ctx.controller, ctx.state

    @r.post("/api/record/start")
    def record_start(body: dict | None = None):
        guard_exited(ctx)
        try:
            controller.record_start()
        except RuntimeError as exc:
            raise http_error(409, str(exc)) from None
        console.pending = None
        return {"ok": True, "status": ctx.full_status()}

    @r.post("/api/record/stop")
    def record_stop(body: dict | None = None):
        try:
            rec = controller.record_stop(None)
        except RuntimeError as exc:
            raise http_error(409, str(exc)) from None
        ctx.pending(rec)
        return {"ok": True, "rows": console.pending["rows"], "status": ctx.full_status()}

    @r.post("/api/record/name")
    def record_name(req: RecordNameRequest):
        rec = console.pending
        if rec is None:
            raise http_error(409, "no stopped recording is waiting for a name", "name")
        folder = Path(rec["dat"]).parent
        exts = ("dat", "csv", "json") if rec.get("json") else ("dat", "csv")
        targets = {ext: folder / f"{req.name}.{ext}" for ext in exts}
        for path in targets.values():
            if path.exists():
                raise http_error(409, f"{path.name} exists in {folder}; choose another name",
                                 "name")
        for ext, path in targets.items():
            Path(rec[ext]).replace(path)
        console.pending = None
        console.saved = {"name": req.name, "rows": rec["rows"],
                         "dat": str(targets["dat"]), "csv": str(targets["csv"]),
                         "json": str(targets["json"]) if "json" in targets else None,
                         "urls": {"dat": f"/api/files/{req.name}.dat",
                                  "csv": f"/api/files/{req.name}.csv"},
                         "time": time.strftime("%Y-%m-%dT%H:%M:%S")}
        return {"ok": True, **console.saved}

    @r.get("/api/files/{filename}")
    def download(filename: str):
        log_dir = ctx.log_dir
        if log_dir is None or not FILE_NAME.fullmatch(filename):
            raise http_error(404, "no such recording")
        path = (log_dir / filename)
        if not path.is_file():
            raise http_error(404, "no such recording")
        media = "text/csv" if filename.endswith(".csv") else "text/plain"
        return FileResponse(path, media_type=media, filename=filename)

    return r
