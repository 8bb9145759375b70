"""What the console's routes share: its state between requests and the full status.

:class:`ConsoleState` holds the pending and saved recordings, the Experiments
panel's last experiment and the exit flag; :class:`Context` is what every
router module (:mod:`.routes`) is built over: the controller, that state, the
stream hub and :meth:`Context.full_status`.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from ..io.jsonsafe import json_safe
from ..realtime.datalog import write_json_atomic
from .hub import Hub
from .stream import honest_figures, pendulum_state

__all__ = ["ConsoleState", "Context"]

log = logging.getLogger("frictionlab.console")


class ConsoleState:
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



@dataclass
class Context:
    """The console's shared objects, handed to every router module.

    Attributes
    ----------
    controller
        The :class:`frictionlab.realtime.RealtimeController`.
    state : ConsoleState
    hub : Hub
        Set once the hub exists (it needs :meth:`full_status`).
    token : str or None
        The access token (None: none needed).
    on_exit : callable or None
        Called after Exit stopped the loop (ends the server).
    """

    controller: object
    state: ConsoleState
    token: str | None = None
    on_exit: object = None
    hub: Hub | None = None

    @property
    def log_dir(self) -> Path | None:
        return self.state.log_dir

    def pending(self, rec: dict) -> None:
        """Hold ``rec`` (a stopped recording) until the page names it, with its sidecar.

        The sidecar is the run's (design, ``h``, parameters, events) as the recording
        ended, plus ``recording`` (its rows and the run it is part of), written
        beside the recording's files as ``<name>.json``: ``frictionlab features
        NAME.dat`` then needs no options.
        """
        side = Path(rec["dat"]).with_suffix(".json")
        meta_fn = getattr(self.controller, "sidecar", None)
        if meta_fn is not None:
            meta = meta_fn()
            meta["recording"] = {"rows": int(rec.get("rows", 0)), "run_id": meta.get("run_id"),
                                 "files": {"dat": str(rec["dat"]), "csv": str(rec["csv"])}}
            try:
                write_json_atomic(side, meta)
            except OSError as exc:  # the recording itself is still saved
                log.warning("frictionlab console: no sidecar for the recording: %s", exc)
        self.state.pending = {"dat": str(rec["dat"]), "csv": str(rec["csv"]),
                              "json": str(side) if side.exists() else None,
                              "rows": int(rec.get("rows", 0))}

    def full_status(self) -> dict:
        """The controller's status plus the console's own (``console``): JSON-ready."""
        controller, console, hub = self.controller, self.state, self.hub
        st = dict(controller.status())
        with console.lock:
            if (console.pending is None and not st.get("running")
                    and getattr(controller, "unnamed_recording", None) is not None):
                # the run ended (a safety stop, say) while recording: the recording was
                # closed under an automatic name; ask the page for its name (asked of the
                # controller, not inferred from an earlier status that may be stale)
                with contextlib.suppress(RuntimeError, ValueError, OSError):
                    self.pending(controller.record_stop(None))
        sw = st.get("swing_up") or {}
        state = pendulum_state(hub.figures if hub is not None else {},
                               running=bool(st.get("running")),
                               upright=float((st.get("safety") or {}).get("angle_limit", 0.35)),
                               phase=sw.get("phase"), experiment=bool(st.get("experiment")),
                               stop_reason=st.get("stop_reason"))
        st["console"] = {
            "limit_cycle": honest_figures(hub.figures if hub is not None else {}, state),
            "clients": len(hub.clients) if hub is not None else 0,
            "frames_sent": hub.frames_sent if hub is not None else 0,
            "frames_dropped": hub.frames_dropped if hub is not None else 0,
            "pages_refused": hub.pages_refused if hub is not None else 0,
            "samples_serialised": hub.serialised if hub is not None else 0,
            "samples_dropped": hub.stream.dropped if hub is not None else 0,
            "pending_recording": console.pending is not None,
            "saved": console.saved,
            "token_required": self.token is not None,
            "exited": console.exited,
            "experiment": _experiment_view(console.experiment),
        }
        return json_safe(st)


def _experiment_view(exp: dict | None) -> dict | None:
    """The Experiments panel's last experiment for the status: ``elapsed`` seconds while
    it runs (the page shows them from its first phase on), not the start instant."""
    if exp is None:
        return None
    out = {k: v for k, v in exp.items() if k != "started"}
    if exp.get("state") == "running" and exp.get("started") is not None:
        out["elapsed"] = round(time.monotonic() - exp["started"], 1)
    return out
