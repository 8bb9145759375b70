"""The rig interface every backend implements (:class:`Rig`), and its errors.

The interface is described in :mod:`.rigs`, which holds the project's own
backends and :func:`.rigs.open_rig`; the QUBE-Servo backend (:mod:`.qube`)
implements it too.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable

from . import protocol as P
from .protocol import SensorReading

__all__ = ["BadReading", "Rig", "RigError"]


class RigError(RuntimeError):
    """The rig cannot be opened or does not support an operation."""


class BadReading(Exception):
    """A reading that must stop the loop (corrupted frame, bad sequence number).

    ``reason`` is the loop's stop reason (``bad_reading``; a backend's subclass
    may name another, e.g. :class:`.qube.RigStop`)."""

    reason = "bad_reading"


class Rig(ABC):
    """Interface of a rig backend (see the module docstring)."""

    name = "rig"
    #: An emulator (push and plant friction available).
    emulated = False
    #: Friction model of the emulated plant (None if unknown, e.g. a real rig).
    plant_friction: str | None = None
    #: Valid frames received from the rig so far (the loop's sign of life).
    rx_frames = 0
    #: The plant moves on in real time whether the loop runs or not (a physical rig;
    #: the in-process simulation unless in lockstep): a gap in the loop makes its state
    #: stale (stop reason ``paused``).
    realtime_plant = True

    #: What the rig said about itself when the session started (protocol ``HELLO_ACK``;
    #: None for the in-process simulation).
    info: P.HelloInfo | None = None

    @abstractmethod
    def open(self, h: float | None = None, cancel: Callable[[], bool] | None = None) -> None:
        """Connect and start a session with the motor off.

        ``h`` is the controller's period (a rig stating another one is
        refused); ``cancel()`` returning True ends the attempt early (see
        :meth:`FramedRig.open`).
        """

    @abstractmethod
    def sample(self, k: int, deadline_ns: int) -> SensorReading | None:
        """The raw reading of tick k, or None if none arrived by ``deadline_ns``."""

    @abstractmethod
    def write(self, k: int, u_da: float) -> None:
        """Output the DAC value of tick k."""

    @abstractmethod
    def stop_motor(self) -> None:
        """Best-effort u_DA = 0; never raises."""

    def close(self) -> None:
        self.stop_motor()

    def warm(self) -> None:  # noqa: B027 - optional hook, a no-op by default
        """Run the code of :meth:`sample` on scratch data, without I/O (cache warming)."""

    def push(self, kick: float) -> None:
        raise RigError(f"push needs an emulated rig; {self.name} is not one")

    def hand(self, action: dict) -> None:
        """The emulated operator's hand (``rig-sim``'s CONTROL ``hand``)."""
        raise RigError(f"the operator's hand can be played by rig-sim over UDP only; "
                       f"{self.name} is not one: do it by hand")

    def counters(self) -> dict:
        """Backend-specific counters for the run's statistics."""
        return {}
