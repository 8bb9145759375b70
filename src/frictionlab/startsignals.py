"""Stop signals from the first instruction of ``frictionlab run``.

A real-time run must end on SIGINT, SIGTERM, SIGHUP or SIGQUIT whenever they
come, before the motor has moved, whatever disposition the process inherited:
the default, or ignored (a job a script starts with ``&``, or ``nohup``).
Importing the command line and the real-time loop (numpy, numba, the compiled
kernels) takes a second or more on a busy machine, and the run's own handlers
(``frictionlab.cli.run``) are installed only after it; a signal ignored until
then is lost, and the run would then drive the motor for its whole duration.

The executable's entry point (:mod:`frictionlab.__main__`) therefore calls
:func:`install` for ``run`` before it imports anything else (this module
imports only the standard library, and ``import frictionlab`` imports nothing).
The handler remembers the first stop signal and raises :class:`Interrupted`,
which ends the start-up at once: nothing has been opened or logged and no
command has been written.  When the run's own handlers take over
(:func:`take_over`), they read the signal remembered, if any, and the handler
here raises no more.
"""

from __future__ import annotations

import signal

__all__ = ["NAMES", "Interrupted", "install", "installed", "interface_stats", "not_started",
           "received", "take_over"]

#: The stop signals, by name (those the platform has are handled).
NAMES = ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT")

#: The module's state: the first signal's name, whether the handler still raises,
#: and the dispositions it replaced.
_state: dict = {"received": None, "raising": False, "previous": {}}


class Interrupted(BaseException):
    """A stop signal came before the run's own handlers took over (``name``: its
    name).  A ``BaseException``, so that no ``except Exception`` on the way
    swallows it."""

    def __init__(self, name: str):
        super().__init__(name)
        self.name = name


def _on_signal(signum, frame) -> None:
    name = signal.Signals(signum).name
    if _state["received"] is None:
        _state["received"] = name
    if _state["raising"]:
        _state["raising"] = False  # once: the unwinding is not interrupted again
        raise Interrupted(name)


def install() -> None:
    """Catch the stop signals now, whatever their inherited disposition: the first
    is remembered and raises :class:`Interrupted` in the main thread."""
    _state["raising"] = True
    for name in NAMES:
        sig = getattr(signal, name, None)
        if sig is not None:
            _state["previous"][sig] = signal.signal(sig, _on_signal)


def installed() -> bool:
    """Whether :func:`install` ran in this process."""
    return bool(_state["previous"])


def take_over() -> str | None:
    """The run's own handlers are being installed: raise no more (a signal that
    comes until they are in place is still remembered).  Returns the name of the
    stop signal that came since :func:`install`, or None."""
    _state["raising"] = False
    return _state["received"]


def received() -> str | None:
    """The name of the first stop signal since :func:`install`, or None."""
    return _state["received"]


def not_started(name: str) -> dict:
    """The statistics of a run that the signal ``name`` ended before it started
    (no tick, no log; ``frictionlab run``'s report)."""
    none3 = {"p50": None, "p99": None, "max": None}
    return {"ticks": 0, "missed": 0, "overruns": 0, "rig_timeouts": 0, "jitter_ms": none3,
            "compute_us": dict(none3), "stop_reason": "signal",
            "stop_detail": f"{name} before the run started", "log": None}


def interface_stats(st: dict) -> dict:
    """The fields ``frictionlab run --headless --json`` prints (docs/cli.md), from the
    run's full statistics (all of which are in the run's JSON sidecar)."""
    j, c = st["jitter_ms"], st["compute_us"]
    return {"ticks": st["ticks"], "missed": st["missed"], "overruns": st["overruns"],
            "jitter_ms": {"p50": j["p50"], "p99": j["p99"], "max": j["max"]},
            "compute_us": {"p50": c["p50"], "p99": c["p99"]},
            "stop_reason": st["stop_reason"], "log": st["log"],
            **({"swing_up": st["swing_up"]} if st.get("swing_up") is not None else {})}
