"""The real-time controller (Sec. 7): 200 Hz loop, rig I/O, safety, lossless logging.

Modules: :mod:`.loop` (the periodic tick, safety, timing statistics),
:mod:`.rigs` (backends ``sim``/``udp://``/``serial://``; the interface in
:mod:`.rigbase`), :mod:`.qube` (``qube2://``/``qube3://``: a Quanser QUBE-Servo
through the HIL API), :mod:`.protocol`
(framing, ``docs/protocol.md``), :mod:`.rigsim` (the emulated rig,
``frictionlab rig-sim``), :mod:`.datalog` (writer thread, ``.dat``/``.csv``/
JSON sidecar), :mod:`.params` (validated parameter snapshots for the
mailbox), :mod:`.samples` (per-tick samples and subscriptions),
:mod:`.clock` (monotonic and fake clocks), :mod:`.stats`, :mod:`.api`.
Design notes: ``docs/realtime.md``.

Console-facing API
------------------
Everything the operator console (or a script) needs is one object,
:class:`RealtimeController`; ``frictionlab run --headless`` uses it too.

>>> from frictionlab.config import build_config
>>> ctl = RealtimeController(build_config("fast", "classical"), "sim", log_dir="runs")
>>> ctl.start()                      # doctest: +SKIP

``start()``
    Open the rig (HELLO), the run's log files, and start the loop thread.
    Raises ``RuntimeError`` if already running, ``RigError`` if the rig does
    not answer.  A controller can run again after a stop (a new run id and
    new files each time; the rig session restarts with the pendulum
    upright).
``stop(reason="user", detail=None)``
    Ask the loop to stop; u = 0 is written at the next tick.  Returns at
    once (safe in a signal handler); ``wait(timeout)`` blocks until the run
    has ended.  A stop asked for while ``start()`` is still opening the rig
    ends the ``HELLO`` wait and the run stops at its first tick.  Reasons:
    :data:`STOP_REASONS`.
``status() -> dict``
    JSON-ready: ``running``, ``run_id``, ``backend``, ``h``, ``t``,
    ``stop_reason``/``stop_detail``, ``ticks``, ``missed``, ``overruns``,
    ``rig_timeouts``, ``jitter_ms`` and ``compute_us`` (``p50``, ``p99``,
    ``p999``, ``max``, ``mean``), ``max_stall_ms``,
    ``plant`` (the ``--plant`` name) and ``u_unit`` (u's and the friction
    levels' unit: ``m/s^2``, or ``V`` for a motor plant),
    ``design`` (``preset``, ``spec``, ``L``, ``K``: a motor plant's 4 x 3
    observer gain as rows), ``compensation``
    (``enabled``, ``kind``, ``params``, ``error_signal``), ``friction``
    (the simulated plant's friction model, None for a real rig),
    ``recording``, ``log``/``log_files``, ``dropped_log_samples``,
    ``dropped_console_samples``, ``sched_fifo``, ``pending_changes``,
    ``safety``.
``subscribe(maxlen=1000) -> Subscription``
    A bounded queue that receives every tick's :class:`Sample` (the tick
    never blocks; when full, samples are dropped and counted in
    ``Subscription.dropped``).  Consume with ``sub.get(timeout)`` (waits
    for samples, returns the list of all queued) or ``sub.drain()``;
    ``unsubscribe(sub)`` when done.  Survives restarts of the run.
``submit(changes: dict) -> concurrent.futures.Future``
    The mailbox.  ``changes`` (see :mod:`.params`): ``{"design": "fast" |
    "slow" | DesignSpec | {field: value}, "compensation": "none" |
    "coulomb" | "classical" | "lugre", "compensation_enabled": bool,
    "compensation_params": {field: value}, "set": {"design.omega1": 5},
    "error_signal": ...}``.  Validated at once in the caller's thread
    (raises ``ConfigError``, a ``ValueError`` naming the key, and nothing
    changes); applied atomically between two ticks; the Future resolves to
    the first tick using the change (None when not running: the change
    then applies to the next run).  ``submit(changes, confirm=False)``
    also refuses a change that the model predicts unstable or saturating
    (``UnsafeChange``, with ``check`` and ``safe``; see :mod:`.params` and
    :mod:`frictionlab.model.loopcheck`) unless ``confirm=True``; ``status()``
    carries the applied settings' verdict as ``loop_check``.
``push(kick)``
    Add ``kick`` rad/s to the pendulum's velocity (emulated rigs: ``sim``,
    and ``udp://`` to ``frictionlab rig-sim``); ``RigError`` otherwise.
``record_start()`` / ``record_stop(name=None) -> {"dat", "csv", "rows"}``
    The Save button of Sec. 7.1: the samples between the two calls are
    also written to ``<log_dir>/<name>.dat`` (ten columns) and ``.csv``.
``close()``
    Stop a running loop (reason ``exit``) and wait for it.

Samples (:class:`Sample`, a NamedTuple): ``k, t, flags``, the ten signals
of Sec. 7.1 in SI (``theta_m, theta_hat, theta_dot_hat, u, arm_m,
arm_dot_m, arm_hat, arm_dot_hat, friction_hat, z_hat``), the raw ``y, x,
v, u_da``, and ``jitter_us, compute_us, rig_us`` (``compute_us`` is the tick's
own work, ``rig_us`` the rig read it excludes); flag bits in :mod:`.samples`.
New fields are only ever appended: read them by name.

``frictionlab run`` without ``--headless`` builds the controller and calls
:func:`frictionlab.cli.run.start_console` ``(ctl, host, port, token)``,
which calls ``frictionlab.console.serve(ctl, host, port, token)`` and closes
the controller when it returns.

Threads: the loop thread (SCHED_FIFO 50 where permitted), the log writer
(SCHED_FIFO 10 where permitted), and the caller's.  The console's own
threads should keep their Python work short: the loop shares the GIL
with them (the switch interval is lowered to 0.2 ms during a run).
"""

from .api import RealtimeController
from .clock import FakeClock, MonotonicClock
from .loop import STOP_REASONS, Safety
from .rigs import BadReading, Rig, RigError, open_rig
from .samples import SAMPLE_FIELDS, Sample, Subscription

__all__ = [
    "SAMPLE_FIELDS",
    "STOP_REASONS",
    "BadReading",
    "FakeClock",
    "MonotonicClock",
    "RealtimeController",
    "Rig",
    "RigError",
    "Safety",
    "Sample",
    "Subscription",
    "open_rig",
]
