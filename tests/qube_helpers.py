"""Shared by the QUBE-Servo tests: the emulated board on the path, and what its
record of calls says (tests/fake_quanser, docs/qube.md)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

FAKE = str(Path(__file__).parent / "fake_quanser")


def load_fake(clock=None):
    """Import the emulated ``quanser.hardware`` (``tests/fake_quanser`` first on
    ``sys.path``), its board time the ``clock``'s (a FakeClock) if given."""
    if FAKE not in sys.path:
        sys.path.insert(0, FAKE)
    from quanser import hardware

    hardware.BOARDS.clear()
    if clock is not None:
        hardware.CLOCK = clock.now_ns
    return hardware


def unload_fake() -> None:
    """Take the emulation off the path and out of ``sys.modules``."""
    while FAKE in sys.path:
        sys.path.remove(FAKE)
    for name in [m for m in sys.modules if m == "quanser" or m.startswith("quanser.")]:
        del sys.modules[name]


def read_record(path) -> list[tuple[float, float, str, list]]:
    """A ``FAKE_QUANSER_LOG`` file as ``(t, mono, call, args)`` tuples."""
    out = []
    for line in Path(path).read_text().splitlines():
        e = json.loads(line)
        out.append((e["t"], e["mono"], e["call"], e["args"]))
    return out


def calls_of(board) -> list[tuple[float, float, str, list]]:
    """An in-process board's record in the same form (mono = board time)."""
    return [(t, t, name, list(args)) for t, name, args in board.calls]


def index(calls, name, pred=lambda args: True) -> int | None:
    """Position of the first call ``name`` whose args satisfy ``pred`` (None: none)."""
    for i, (_t, _m, n, args) in enumerate(calls):
        if n == name and pred(args):
            return i
    return None


def voltages(calls) -> list[tuple[int, float, float]]:
    """``(position, mono time, V)`` of every write to analog output 0."""
    return [(i, m, args[1][0]) for i, (_t, m, n, args) in enumerate(calls)
            if n == "write_analog"]


def check_safe_sequence(calls) -> None:
    """The order the backend must keep on the motor, whatever the run did.

    Expiration states set and the watchdog started before the amplifier is
    enabled; the amplifier enabled before the first non-zero voltage; |V| <= 10
    throughout; the end: 0 V, amplifier off, watchdog stopped, board closed.
    """
    names = [c[2] for c in calls]
    enable = index(calls, "write_digital", lambda a: a[1][0] == 1)
    first_v = next((i for i, _m, v in voltages(calls) if v != 0.0), None)
    if enable is not None:
        exp_a = index(calls, "watchdog_set_analog_expiration_state")
        exp_d = index(calls, "watchdog_set_digital_expiration_state")
        start = index(calls, "watchdog_start")
        assert exp_a is not None and exp_d is not None and start is not None
        assert exp_a < start and exp_d < start < enable
        assert calls[exp_a][3][1] == [0.0] and calls[exp_d][3][1] == [0]  # 0 V, LOW
    if first_v is not None:
        assert enable is not None and enable < first_v
    assert all(abs(v) <= 10.0 for _i, _m, v in voltages(calls))
    assert names[-1] == "close"
    last_v = max(i for i, _m, _v in voltages(calls))
    assert calls[last_v][3][1] == [0.0]
    last_d = max(i for i, c in enumerate(calls) if c[2] == "write_digital")
    assert calls[last_d][3][1] == [0]
    if "watchdog_start" in names:
        assert "watchdog_stop" in names[names.index("watchdog_start"):]


def pendulum_from_upright(counts1: int, sign: int = 1) -> float:
    """The project's theta from encoder 1 (docs/qube.md), wrapped to [-pi, pi)."""
    return math.remainder(math.pi - sign * 2 * math.pi * counts1 / 2048, 2 * math.pi)
