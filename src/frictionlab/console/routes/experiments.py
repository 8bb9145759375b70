"""The Experiments panel: an identification experiment run on the rig, then analysed."""

from __future__ import annotations

import threading

from fastapi import APIRouter, HTTPException

from ...realtime.api import ControllerStateError
from ..errors import http_error
from ..models import ExperimentRequest
from ..state import Context
from .run import guard_exited

__all__ = ["router", "run_experiment"]


def run_experiment(ctx: Context, exp) -> None:
    """Start ``exp`` on the controller and analyse its log when the run ends (in a
    thread of its own)."""
    state = ctx.state
    with state.lock:
        state.experiment = {"name": exp.name, "state": "running", "estimates": None,
                            "warnings": [], "message": None, "log": None}
    ctx.controller.start(experiment=exp)
    threading.Thread(target=_analyse, args=(ctx, exp), name="frictionlab-experiment",
                     daemon=True).start()


def _analyse(ctx: Context, exp) -> None:
    # the identification analysis (scipy.optimize) loads on first use, not at start-up
    from ...io.logs import read_log
    from ...studies.identification.experiments import IdentificationError
    from ...studies.identification.onrig import analyse_log

    ctl = ctx.controller
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
            log = read_log(st["log"], ctl.cfg.design.h)
            res = analyse_log(exp.name, log, ctl.cfg, marks=dict(exp.marks))
        except (IdentificationError, ValueError, OSError) as exc:
            out.update(state="failed", message=str(exc))
        else:
            out.update(state="done", message="done",
                       estimates={k: v for k, v in res.items()
                                  if isinstance(v, float) or v is None},
                       warnings=list(res.get("warnings", [])))
    with ctx.state.lock:
        if ctx.state.experiment is not None:
            ctx.state.experiment.update(out)


def router(ctx: Context) -> APIRouter:
    """``POST /api/experiment``."""
    r = APIRouter()
    controller = ctx.controller

    @r.post("/api/experiment")
    def experiment(req: ExperimentRequest):
        # the experiments' schedules load on first use, not at start-up
        from ...realtime.experiment import Limits
        from ...studies.identification.onrig import make_rig_experiment

        guard_exited(ctx)
        if controller.running:
            raise http_error(409, "the controller is running: stop it before an experiment")
        try:
            limits = Limits(**req.limits)
        except ValueError as exc:
            raise http_error(422, str(exc), "limits") from None
        try:
            exp = make_rig_experiment(req.name, controller.cfg, limits, **req.options)
        except (TypeError, ValueError) as exc:
            raise http_error(422, f"{req.name}: {exc}", "options") from None
        if not req.confirm:
            message = (f"the {req.name} experiment drives the motor: the arm will move (limits:"
                       f" arm speed {limits.max_speed:g} rad/s, travel {limits.max_travel:g} "
                       f"rad, |u_DA| {limits.max_u_da:g}); Stop zeroes the motor at once. "
                       "Send the request with \"confirm\": true to run it")
            raise HTTPException(422, detail={"detail": message, "errors": [],
                                             "confirm_required": True})
        try:
            run_experiment(ctx, exp)
        except RuntimeError as exc:  # includes RigError
            code = 409 if isinstance(exc, ControllerStateError) else 502
            raise http_error(code, str(exc)) from None
        return {"ok": True, "status": ctx.full_status()}

    return r
