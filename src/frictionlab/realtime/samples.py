"""Per-tick samples, their flags, and non-blocking subscriptions for consumers.

Every tick produces one immutable :class:`Sample` that goes, without
blocking the tick, to the log writer and to every :class:`Subscription`
(the operator console's plot, the thesis's Plot/Read processes of Sec. 7.3).

Flags (bit mask, also the ``flags`` column of the CSV log):

==========  =====  ==========================================================
name        value  meaning
==========  =====  ==========================================================
MISSED      1      deadlines were skipped just before this tick
OVERRUN     2      u of this tick was written after the next deadline
NO_READING  4      the rig did not answer in time: controller not updated,
                   the previous u held (signals of this row are NaN)
COMPENSATE  8      friction compensation active
CHANGED     16     parameter changes were applied just before this tick
STOP        32     the loop stopped at this tick (u = 0 written)
START       64     first tick of the run (arm bias x_0 captured)
SWINGING    128    swing-up: the energy-control law computed u (the
                   ``theta_hat``/``theta_dot_hat`` columns are the swing-up
                   observer's)
CAUGHT      256    swing-up: caught, the balancing controller acts; no flag
                   (after CAUGHT) is balancing
==========  =====  ==========================================================
"""

from __future__ import annotations

import threading
from collections import deque
from typing import NamedTuple

from ..model.simulation import LOGGED

__all__ = [
    "CHANGED",
    "COMPENSATE",
    "FLAG_NAMES",
    "MISSED",
    "NO_READING",
    "OVERRUN",
    "SAMPLE_FIELDS",
    "START",
    "STOP",
    "Sample",
    "Subscription",
]

MISSED, OVERRUN, NO_READING, COMPENSATE, CHANGED, STOP, START = (1, 2, 4, 8, 16, 32, 64)
SWINGING_FLAG, CAUGHT_FLAG = 128, 256
FLAG_NAMES = {MISSED: "missed", OVERRUN: "overrun", NO_READING: "no_reading",
              COMPENSATE: "compensate", CHANGED: "changed", STOP: "stop", START: "start",
              SWINGING_FLAG: "swinging", CAUGHT_FLAG: "caught"}


class Sample(NamedTuple):
    """One tick: time, flags, the ten signals of Sec. 7.1 (SI), raw values, timing."""

    k: int                   # tick number; t = k h
    t: float                 # s since the start of the run
    flags: int
    theta_m: float           # measured pendulum angle (rad)
    theta_hat: float         # estimated pendulum angle (rad)
    theta_dot_hat: float     # estimated pendulum velocity (rad/s)
    u: float                 # control signal (m/s^2)
    arm_m: float             # measured arm angle (rad)
    arm_dot_m: float         # measured arm velocity (rad/s)
    arm_hat: float           # estimated arm angle (rad)
    arm_dot_hat: float       # estimated arm velocity (rad/s)
    friction_hat: float      # friction estimate F_hat (m/s^2)
    z_hat: float             # LuGre bristle estimate z_hat
    y: float                 # raw pendulum reading
    x: float                 # raw arm reading
    v: float                 # raw arm velocity reading
    u_da: float              # DAC value written
    jitter_us: float         # wake-up time minus deadline
    compute_us: float        # the tick's own work: wake-up to u written, less rig_us
    rig_us: float            # reading the rig (request to reply; sim: the plant's step)


SAMPLE_FIELDS = Sample._fields
assert SAMPLE_FIELDS[3:13] == LOGGED


class Subscription:
    """A bounded, non-blocking queue of samples for one consumer.

    The tick calls :meth:`put` (never blocks: when the queue holds
    ``maxlen`` samples the new one is dropped and counted in
    :attr:`dropped`).  The consumer calls :meth:`get` (waits up to a timeout
    for at least one sample, returns all queued) or :meth:`drain`.
    """

    def __init__(self, maxlen: int = 1000):
        if maxlen < 1:
            raise ValueError(f"maxlen must be >= 1, got {maxlen}")
        self.maxlen = maxlen
        self.dropped = 0
        self.closed = False
        self._q: deque[Sample] = deque()
        self._ready = threading.Event()

    def put(self, sample: Sample) -> None:
        if len(self._q) >= self.maxlen:
            self.dropped += 1
            return
        self._q.append(sample)
        if not self._ready.is_set():
            self._ready.set()

    def drain(self) -> list[Sample]:
        """All queued samples (possibly none), oldest first."""
        self._ready.clear()
        q = self._q
        out = []
        while q:
            out.append(q.popleft())
        return out

    def get(self, timeout: float | None = None) -> list[Sample]:
        """Wait up to ``timeout`` s for samples; return all queued (maybe none)."""
        if not self._q:
            self._ready.wait(timeout)
        return self.drain()

    def __len__(self) -> int:
        return len(self._q)
