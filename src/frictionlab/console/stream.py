"""The console's view of the loop: samples read off the tick thread, plot frames, figures.

The thesis's plot module has a periodic Read process (0.1 s) that takes the
regulator's data into a buffer, and a low-priority Plot process that draws
it (Sec. 7.3).  :class:`SampleStream` is the Read side: the console's
server calls :meth:`SampleStream.poll` at its own rate; it drains the
controller's non-blocking subscription (the tick never waits for it: a
full subscription drops samples and counts them), keeps the last
``history`` seconds in a ring buffer, and returns the block of new samples;
:func:`frame_json` makes a page's *frame* of a block (:func:`decimate`: at
most so many points, evenly spaced).  :meth:`SampleStream.figures` gives the running
limit-cycle figures (:func:`frictionlab.model.limit_cycles.features` of the
measured angle over the last seconds) that the status line shows, computed
here, off the tick thread.
"""

from __future__ import annotations

import math

import numpy as np

from ..model.limit_cycles import features

__all__ = ["FIGURE_KEYS", "HANGING_BAND", "PLOT_SIGNALS", "RingBuffer", "SampleStream",
           "decimate", "frame_json", "honest_figures", "pendulum_state"]

#: Signals sent to the page: the ten logged signals less z_hat, in SI units.
PLOT_SIGNALS = ("theta_m", "arm_m", "arm_dot_m", "u", "theta_hat", "theta_dot_hat", "arm_hat",
                "arm_dot_hat", "friction_hat")
_COLUMNS = ("t", *PLOT_SIGNALS)


class RingBuffer:
    """Fixed-capacity columns of floats; appending never allocates.

    Parameters
    ----------
    columns : tuple of str
    capacity : int
    """

    def __init__(self, columns: tuple[str, ...], capacity: int):
        if capacity < 2:
            raise ValueError(f"capacity must be >= 2, got {capacity}")
        self.columns = columns
        self.capacity = capacity
        self._data = np.full((len(columns), capacity), np.nan)
        self._n = 0        # samples held
        self._end = 0      # next write position

    def __len__(self) -> int:
        return self._n

    def clear(self) -> None:
        self._n = 0
        self._end = 0

    def extend(self, block: np.ndarray) -> None:
        """Append ``block`` (columns x n), dropping the oldest samples when full."""
        n = block.shape[1]
        if n >= self.capacity:
            block, n = block[:, -self.capacity:], self.capacity
        first = min(n, self.capacity - self._end)
        self._data[:, self._end:self._end + first] = block[:, :first]
        if first < n:
            self._data[:, :n - first] = block[:, first:]
        self._end = (self._end + n) % self.capacity
        self._n = min(self._n + n, self.capacity)

    def last(self, n: int | None = None) -> np.ndarray:
        """The last ``n`` samples (all if None), oldest first, as a copy."""
        n = self._n if n is None else min(n, self._n)
        start = (self._end - n) % self.capacity
        if start + n <= self.capacity:
            return self._data[:, start:start + n].copy()
        return np.concatenate([self._data[:, start:], self._data[:, :self._end]], axis=1)


def decimate(block: np.ndarray, max_points: int) -> np.ndarray:
    """At most ``max_points`` evenly spaced samples (columns) of ``block``, first and last kept."""
    n = block.shape[1]
    if n <= max_points:
        return block
    idx = np.unique(np.linspace(0, n - 1, max_points).round().astype(int))
    return block[:, idx]


def _column(values: np.ndarray, digits: int) -> list:
    out = np.round(values, digits).tolist()
    if not np.isfinite(values).all():
        out = [v if math.isfinite(v) else None for v in out]
    return out


def frame_json(block: np.ndarray, kind: str = "samples", **extra) -> dict:
    """A JSON-ready frame ``{"type", "t": [...], signal: [...], ...}`` (NaN -> null)."""
    frame = {"type": kind, **extra, "t": _column(block[0], 4)}
    for i, name in enumerate(PLOT_SIGNALS, start=1):
        frame[name] = _column(block[i], 6)
    return frame


class SampleStream:
    """Drains a controller subscription into a ring buffer and plot frames.

    Parameters
    ----------
    controller
        Anything with ``subscribe(maxlen)`` / ``unsubscribe(sub)`` (the
        :class:`frictionlab.realtime.RealtimeController` interface).
    h : float
        Sampling period of the loop (s), for the buffer's size.
    history : float
        Seconds kept (the longest plot window plus margin).
    max_points : int
        Most samples in one frame.
    """

    def __init__(self, controller, h: float = 0.005, history: float = 40.0,
                 max_points: int = 50):
        self.controller = controller
        self.h = h
        self.max_points = max_points
        self.buffer = RingBuffer(_COLUMNS, math.ceil(history / h) + 1)
        self.sub = None
        self.samples = 0
        self.resets = 0
        self._last_t = -math.inf

    def open(self, maxlen: int = 4000) -> None:
        """Subscribe (``maxlen`` samples of slack: 20 s at 200 Hz)."""
        if self.sub is None:
            self.sub = self.controller.subscribe(maxlen)

    def close(self) -> None:
        if self.sub is not None:
            self.controller.unsubscribe(self.sub)
            self.sub = None

    @property
    def dropped(self) -> int:
        """Samples the subscription dropped because the console fell behind."""
        return 0 if self.sub is None else self.sub.dropped

    def poll(self) -> tuple[np.ndarray, bool] | None:
        """Take the new samples: ``(block, reset)``, or None if there were none.

        ``block`` is the samples' columns (``t`` and :data:`PLOT_SIGNALS`).
        A new run (time going back) clears the buffer and sets ``reset``, so
        the page clears its plot too.
        """
        if self.sub is None:
            return None
        samples = self.sub.drain()
        if not samples:
            return None
        block = np.array([[getattr(s, c) for c in _COLUMNS] for s in samples]).T
        reset = False
        if block[0, 0] < self._last_t:
            self.buffer.clear()
            self.resets += 1
            reset = True
        # a restart within this block (time going back inside it): keep the new run only
        back = np.nonzero(np.diff(block[0]) < 0)[0]
        if len(back):
            block = block[:, back[-1] + 1:]
            self.buffer.clear()
            self.resets += 1
            reset = True
        self._last_t = float(block[0, -1])
        self.samples += block.shape[1]
        self.buffer.extend(block)
        return block, reset

    def warm(self, window: float = 5.0) -> None:
        """Load the feature kernels now: :func:`features` of a synthetic limit cycle.

        The first :meth:`figures` of a process loads
        :func:`~frictionlab.model.limit_cycles.features`' compiled kernels from
        numba's cache, about 0.3 s holding the GIL; on the server's thread
        while the loop runs, that stalled the loop for 5-9 ms.  The synthetic
        signals have the layout :meth:`figures` passes (contiguous float64),
        so the real calls find the same specialisations loaded.

        Parameters
        ----------
        window : float
            Length of the synthetic signals (s), as in :meth:`figures`.
        """
        t = np.arange(round(window / self.h) + 1) * self.h
        theta = 0.1 * np.sin(2.0 * np.pi * t)
        features(t, theta, np.cos(2.0 * np.pi * t), np.sin(4.0 * np.pi * t),
                 window=float(t[-1] - t[0]))

    def figures(self, window: float = 5.0) -> dict:
        """Running limit-cycle figures of the measured angle over the last ``window`` s.

        Returns ``{"window", "span", "status", "peak_to_peak", "period", "peak1",
        "max_u", "max_arm_velocity", "max_angle", "last_angle",
        "min_angle_last_second"}`` (None where not defined yet; the angles are
        |theta| from upright, wrapped: over the window, at its end, the least in its
        last second).  Whether the figures mean anything is
        :func:`pendulum_state`'s to say.
        """
        n = round(window / self.h) + 1
        data = self.buffer.last(n)
        out = {"window": window, "span": 0.0, "status": None, "peak_to_peak": None,
               "period": None, "peak1": None, "max_u": None, "max_arm_velocity": None,
               "max_angle": None, "last_angle": None, "min_angle_last_second": None,
               "max_angle_last_second": None}
        if data.shape[1] < 3:
            return out
        t, theta, arm_dot, u = data[0], data[1], data[3], data[4]
        ok = np.isfinite(theta) & np.isfinite(u) & np.isfinite(arm_dot)
        if ok.sum() < 3:
            return out
        t, theta, arm_dot, u = t[ok], theta[ok], arm_dot[ok], u[ok]
        span = float(t[-1] - t[0])
        if span <= 0.0:
            return out
        f = features(t, theta, u, arm_dot, window=span)
        wrapped = np.abs(np.mod(theta + np.pi, 2.0 * np.pi) - np.pi)  # |theta| from upright
        out.update({"span": span, "status": f.status, "peak_to_peak": f.peak_to_peak,
                    "period": f.period, "peak1": f.peak1, "max_u": f.max_u,
                    "max_arm_velocity": f.max_arm_velocity,
                    "max_angle": float(wrapped.max()), "last_angle": float(wrapped[-1]),
                    "min_angle_last_second": float(wrapped[t >= t[-1] - 1.0].min()),
                    "max_angle_last_second": float(wrapped[t >= t[-1] - 1.0].max())})
        return out


#: Angles (rad from upright) of a pendulum that hangs: within this of pi for a second.
HANGING_BAND = 0.6
#: What the limit-cycle figures hold that is measured (hidden unless balancing).
FIGURE_KEYS = ("peak_to_peak", "period", "peak1", "max_u", "max_arm_velocity")


def pendulum_state(fig: dict, *, running: bool, upright: float, phase: str | None = None,
                   experiment: bool = False, stop_reason: str | None = None) -> str:
    """What the pendulum is doing, from the last figures' angles and the run.

    ``"balancing"`` (running the balancing controller, and the angle stayed within
    ``upright`` rad of upright over the whole window), ``"catching"`` (upright over
    the last second, not yet over the whole window: a swing-up caught it, the
    figures would still measure the swing), ``"hanging"`` (within
    :data:`HANGING_BAND` of pi over the last second), ``"swinging"`` (running, none of
    these), ``"fallen"`` (stopped, neither upright nor hanging), ``"stopped"``
    (stopped upright), or ``"unknown"`` (no samples).

    Parameters
    ----------
    fig : dict
        :meth:`SampleStream.figures`.
    running : bool
        The loop runs.
    upright : float
        Largest angle from upright that counts as balanced (rad; the loop's angle limit).
    phase : str, optional
        The swing-up's phase (``swinging``, ``caught``, ``balancing``) if it is one.
    experiment : bool
        The run is an identification experiment (the pendulum is not balanced).
    stop_reason : str, optional
        Why the loop stopped: ``angle_limit`` is a fall, whatever the last sample
        the figures hold (the reading past the limit ends the run: it is not in them).
    """
    if fig.get("max_angle") is None:
        return "unknown" if running else "stopped"
    if fig["min_angle_last_second"] >= math.pi - HANGING_BAND:
        return "hanging"
    if not running:
        fell = stop_reason == "angle_limit" or fig["last_angle"] > upright
        return "fallen" if fell else "stopped"
    if experiment or phase == "swinging" or fig["max_angle_last_second"] > upright:
        return "swinging"
    if phase == "caught" or fig["max_angle"] > upright:
        return "catching"
    return "balancing"


def honest_figures(fig: dict, state: str) -> dict:
    """``fig`` as the status shows it: the figures only while ``state`` is balancing,
    else the pendulum's state as the status (never a limit cycle of a hanging pendulum)."""
    out = {**fig, "pendulum": state}
    if state != "balancing":
        out.update({k: None for k in FIGURE_KEYS}, status=state)
    return out
