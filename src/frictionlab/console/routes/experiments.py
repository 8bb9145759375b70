"""The Experiments panel: an identification experiment run on the rig, then analysed."""

from __future__ import annotations

import inspect
import math
import threading
import time

from fastapi import APIRouter, HTTPException

from ...config import describe_keys
from ...model.params import ParamError
from ...realtime.api import ControllerStateError
from ...realtime.experiment import EXPERIMENT_CLASSES, Limits
from ...studies.identification.onrig import make_rig_experiment
from ..errors import http_error
from ..models import ExperimentRequest
from ..state import Context
from .run import guard_exited

__all__ = ["MAX_SECONDS", "check_options", "router", "run_experiment", "worst_case_seconds"]

#: The longest experiment the panel runs (s): one that could take longer is refused.
MAX_SECONDS = 1800.0


def run_experiment(ctx: Context, exp) -> None:
    """Start ``exp`` on the controller and analyse its log when the run ends (in a
    thread of its own)."""
    state = ctx.state
    with state.lock:
        state.experiment = {"name": exp.name, "state": "running", "estimates": None,
                            "units": {}, "warnings": [], "message": None, "log": None,
                            "started": time.monotonic()}
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
            estimates = {k: v for k, v in res.items() if isinstance(v, float) or v is None}
            out.update(state="done", message="done", estimates=estimates,
                       units={k: estimate_unit(k, ctl.cfg) for k in estimates},
                       warnings=list(res.get("warnings", [])))
    with ctx.state.lock:
        if ctx.state.experiment is not None:
            ctx.state.experiment.update(out)


#: Units of the estimates that are not parameters of a dataclass (the rest are looked up).
_UNITS = {"period": "s", "rest_angle": "rad", "residual_rms": "rad/s",
          "breakaway_time_positive": "s", "breakaway_time_negative": "s",
          "pendulum_lap_raw": "ADC units", "arm_lap_raw": "ADC units", "zeta_peaks": "1",
          "omega0_peaks": "rad/s", "input_gain_free": "1", "coulomb_free": "m/s^2"}


def estimate_unit(key: str, cfg) -> str:
    """The unit of an experiment's estimate ``key``: that of the parameter of ``cfg`` (the
    run's configuration: friction, plant, rig scalings) it estimates, in the plant's units
    (friction levels in volts on a motor plant)."""
    if key in _UNITS:
        return _UNITS[key]
    base = key.removesuffix("_positive").removesuffix("_negative")
    units = {k: unit for k, _doc, unit, _rng in describe_keys(cfg.plant_kind)}
    for section in ("friction", "plant", "rig"):
        if f"{section}.{base}" in units:
            return units[f"{section}.{base}"]
    return ""


def check_options(name: str, options: dict) -> None:
    """Refuse (422, at ``options.<key>``) an option the experiment does not take or of the
    wrong kind: a list where it takes a list of levels, a number elsewhere."""
    cls = EXPERIMENT_CLASSES[name]
    params = {p.name: p for p in inspect.signature(cls.__init__).parameters.values()
              if p.kind is inspect.Parameter.KEYWORD_ONLY}
    for key, value in options.items():
        p = params.get(key)
        if p is None:
            known = ", ".join(params) or "none"
            raise http_error(422, f"the {name} experiment has no option {key!r}; its options: "
                             f"{known}", f"options.{key}")
        wants_list = isinstance(p.default, tuple | list)
        if wants_list != isinstance(value, list):
            kind = "a list of numbers" if wants_list else "a number"
            raise http_error(422, f"{key} must be {kind}", f"options.{key}")


def worst_case_seconds(exp) -> float:
    """The longest the experiment ``exp`` can run if the arm never moves (s).

    Only the stiction staircase's length depends on its options beyond their
    ranges: it climbs by ``step`` to the u limit, holding each level ``hold``
    seconds, in each direction (a step of 1e-300 never gets anywhere).  The
    other schedules are bounded by their options' ranges.
    """
    step = getattr(exp, "step_u", None)
    if step is None:
        return 0.0
    # the staircase rounds each level to 1e-12 m/s^2: a smaller step never climbs
    levels = exp.u_max / step if step >= 1e-12 else math.inf
    return 2.0 * (math.ceil(levels) if math.isfinite(levels) else levels) * exp.hold_s


def router(ctx: Context) -> APIRouter:
    """``POST /api/experiment``."""
    r = APIRouter()
    controller = ctx.controller

    @r.post("/api/experiment")
    def experiment(req: ExperimentRequest):
        guard_exited(ctx)
        if controller.running:
            raise http_error(409, "the controller is running: stop it before an experiment")
        try:
            limits = Limits(**req.limits)
        except ParamError as exc:
            raise http_error(422, str(exc),
                             "limits." + exc.field.removeprefix("limits.")) from None
        check_options(req.name, req.options)
        try:
            exp = make_rig_experiment(req.name, controller.cfg, limits, **req.options)
        except ParamError as exc:
            field = exc.field if exc.field in req.options else None
            raise http_error(422, f"{req.name}: {exc}",
                             f"options.{field}" if field else "options") from None
        except (TypeError, ValueError, ArithmeticError) as exc:
            raise http_error(422, f"{req.name}: {exc}", "options") from None
        longest = worst_case_seconds(exp)
        if longest > MAX_SECONDS:
            raise http_error(422, f"{req.name}: step = {exp.step_u:g} m/s^2 would need "
                             f"{longest:.3g} s to reach the u limit {exp.u_max:.3g} m/s^2 "
                             f"holding each level {exp.hold_s:g} s; an experiment must be able "
                             f"to finish within {MAX_SECONDS / 60:g} min: take a larger step",
                             "options.step")
        if not req.confirm:
            message = (f"The {req.name} experiment drives the motor: the arm will move, at "
                       f"most {limits.max_speed:g} rad/s and {limits.max_travel:g} rad from "
                       f"where it starts, with |u_DA| up to {limits.max_u_da:g}. Keep hands "
                       "clear of the arm. Stop sets the motor to zero at once.")
            raise HTTPException(422, detail={"detail": message, "errors": [],
                                             "confirm_required": True})
        try:
            run_experiment(ctx, exp)
        except RuntimeError as exc:  # includes RigError
            code = 409 if isinstance(exc, ControllerStateError) else 502
            raise http_error(code, str(exc)) from None
        return {"ok": True, "status": ctx.full_status()}

    return r
