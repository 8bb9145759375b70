"""The rig firmware's AVR build in the simavr emulator (firmware/hil): against
the real controller (``firmware/test-hil``: the home-built rig), the encoders
at high speed, and the AVR's hardware watchdog.  Needs avr-gcc, avr-libc and libsimavr-dev
(scripts/install-system-deps).  The portable core's unit tests:
tests/test_firmware.py."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from frictionlab.io.logs import read_log
from frictionlab.realtime import protocol as P

FIRMWARE = Path(__file__).resolve().parents[1] / "firmware"
BUILD = FIRMWARE / "build"
COUNTS = 2400
PERIOD_MS = 5.0

pytestmark = [pytest.mark.slow, pytest.mark.realtime]


def raw_theta(count: int) -> float:
    """The firmware's pendulum channel: hanging (count 0) reads 0.5."""
    return 2 * ((count + 3 * COUNTS // 4) % COUNTS) / COUNTS - 1


def test_hil(*args: str) -> dict:
    res = subprocess.run([str(FIRMWARE / "test-hil"), *args], capture_output=True, text=True,
                         timeout=300, env={"PYTHON": sys.executable, "PATH": "/usr/bin:/bin"},
                         process_group=0)
    assert res.returncode == 0, res.stderr[-3000:] + res.stdout[-3000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


test_hil.__test__ = False  # a helper, not a test


def test_the_controller_balances_the_emulated_rig_and_a_stall_zeroes_the_motor(tmp_path):
    """The two acceptance runs in one (CI time): ``run --plant furuta-dc``
    balances the emulated home-built rig (the DC-motor plant with the HOMEBUILT
    preset, driven by the duty times 12 V) for 5 s (at most 1 % missed
    deadlines, |theta| < 0.2 rad over the 3 s before the stall), then is
    stopped with SIGSTOP: the duty is zero within the advertised watchdog time
    plus 2 periods.  (A run that ends by its duration: firmware/test-hil
    --duration 10, docs/performance.md.)"""
    for attempt in range(3):
        out = test_hil("--duration", "10", "--stall-at", "5", "--keep",
                       str(tmp_path / str(attempt)))
        try:
            log = read_log(out["run"]["log"])
            t, theta = log["t"], log["theta_m"]
        except ValueError:  # no samples: the loop stopped before its first tick
            t = theta = np.zeros(0)
        # the ticks before the stall: up to its 1 s gap in the loop's time axis when
        # the loop woke up after it, or all of them when the stall caught the loop
        # waiting for a reply (it stops in that tick: "reply taken 1000 ms late")
        gaps = np.diff(t)
        end = int(np.argmax(gaps)) + 1 if gaps.size and gaps.max() > 0.5 else len(t)
        reached = end > 0 and t[end - 1] > 4.5  # the loop ran up to the stall
        t, theta = t[:end], theta[:end]
        missed = np.sum(np.round(np.diff(t) / (PERIOD_MS / 1e3)) - 1)
        silent = out["run"]["stop_reason"] == "rig_silent"
        # the limit cycle's u passes through zero: in 0.4 % of its ticks the duty
        # rounds to 0 (|u| < 12 V / 1600), and a stall then shows no watchdog
        ran = out["harness"]["duty_at_mark"] != 0.0
        if missed <= 0.01 * len(t) and not silent and reached and ran:
            break
        # a timing statistic, the loop's own stop for a host that held it (reason
        # paused or rig_silent before the stall), or a stall at a zero duty: run once
        # more (docs/development.md, "A busy machine"); the stop itself zeroed the
        # motor, which other tests check
        warnings.warn(f"test-hil: {missed:.0f} deadlines missed before the stall in "
                      f"{len(t)} ticks (up to t = {t[-1] if len(t) else 0.0:.2f} s), stop "
                      f"{out['run']['stop_reason']}, duty at the stall "
                      f"{out['harness']['duty_at_mark']}; running it again",
                      stacklevel=1)
    assert reached, out
    assert missed <= 0.01 * len(t), (missed, out)
    run = out["run"]
    assert out["flash_bytes"] <= 32 * 1024 and out["ram_bytes"] <= 1536
    assert out["watchdog_ms"] == 50
    assert out["harness"]["duty_at_mark"] != 0.0, out  # the motor ran when it stalled
    assert out["pwm_zero_after_stall_ms"] <= out["watchdog_ms"] + 2 * PERIOD_MS, out
    assert run["stop_reason"] in ("paused", "rig_fault"), out
    assert t[-1] > 3.0
    last = t > t[-1] - 3.0
    assert np.nanmax(np.abs(theta[last])) < 0.2
    assert np.isfinite(theta[last]).mean() > 0.9  # readings arrived
    assert out["harness"]["resets"] == 0 and out["harness"]["released"]


class Rig:
    """firmware/hil/rig.py as a process, and a serial line to its pty."""

    def __init__(self, *args: str, elf: str = "rig.elf"):
        subprocess.run(["make", "-s", "-C", str(FIRMWARE), "hil"], check=True,
                       capture_output=True)
        self.proc = subprocess.Popen(
            [sys.executable, str(FIRMWARE / "hil" / "rig.py"),
             "--lib", str(BUILD / "host" / "libhil.so"),
             "--elf", str(BUILD / "atmega328p" / elf), *args],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, process_group=0)
        line = self.proc.stdout.readline()
        assert line.startswith("pty "), line
        import serial

        self.port = serial.Serial(line.split()[1], 1_000_000, timeout=0.2)
        self.decoder = P.FrameDecoder()
        self.seq = 0

    def ask(self, frame: bytes, msg_type: int) -> P.Frame:
        self.port.write(frame)
        end = time.monotonic() + 10
        while time.monotonic() < end:
            # at least one byte (a timeout of 0.2 s), then whatever has arrived
            for f in self.decoder.feed(self.port.read(max(1, self.port.in_waiting))):
                assert isinstance(f, P.Frame), f
                if f.type == msg_type:
                    return f
        raise AssertionError("no reply from the emulated rig")

    def sample(self) -> P.SensorReading:
        self.seq += 1
        return P.parse_sensor(self.ask(P.sample_frame(self.seq), P.MSG_SENSOR))

    def report(self) -> dict:
        self.port.close()
        self.proc.send_signal(signal.SIGTERM)
        out, _ = self.proc.communicate(timeout=30)
        return json.loads(out.strip().splitlines()[-1])

    def kill(self):
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


def test_no_lost_counts_at_three_times_the_arms_top_speed_and_a_hung_firmware_resets():
    """One emulated rig (the test build that can hang; CI time), two checks.

    The encoders: both turn at 100 rad/s (38 000 edges a second each; the arm's
    top speed is about 30 rad/s, docs/build-a-rig.md) for 0.3 s; the readings
    after it are the counts to the edge.  The hand also raised the pendulum at
    50 000 edges a second before the session.

    The hardware watchdog: with the motor on, the main loop hangs (interrupts
    still running, nothing kicks the watchdog): the AVR resets within WDTO_30MS
    (32 ms at 128 kHz) with the motor off, and reports WATCHDOG until a HELLO.
    """
    speed, seconds, theta0 = 100.0, 0.3, 0.05
    rig = Rig("--plant", "spin", "--spin-speed", str(speed), "--spin-time", str(seconds),
              "--theta0", str(theta0), elf="rig-hang.elf")
    try:
        rig.ask(P.encode(P.MSG_HELLO, 0), P.MSG_HELLO_ACK)
        start = rig.sample()
        pend0 = round((theta0 - math.pi) * COUNTS / (2 * math.pi))
        assert start.y == pytest.approx(raw_theta(pend0), abs=1e-6)
        rig.port.write(P.command_frame(rig.seq, 0.0))  # the hand lets go: the spin starts
        # until the shafts have turned and rest: the velocity window reads 0 and two
        # readings agree (just after the start the window can read 0 too)
        prev, r = None, rig.sample()
        end = time.monotonic() + 60
        while (r.v != 0.0 or r.x == 0.0 or prev is None or (prev.x, prev.y) != (r.x, r.y)) \
                and time.monotonic() < end:
            prev, r = r, rig.sample()
        turned = round(speed * seconds * COUNTS / (2 * math.pi))
        pend = round((theta0 + speed * seconds - math.pi) * COUNTS / (2 * math.pi))
        assert r.y == pytest.approx(raw_theta(pend), abs=1e-6)
        assert r.x == pytest.approx(2 * ((turned + COUNTS // 2) % COUNTS) / COUNTS - 1,
                                    abs=1e-6)

        def command(u: float) -> None:
            rig.seq += 1
            rig.port.write(P.command_frame(rig.seq, u))

        # a new session (the protocol's watchdog tripped during the spin), the motor on
        rig.ask(P.encode(P.MSG_HELLO, 0), P.MSG_HELLO_ACK)
        rig.seq = -1
        command(0.5)
        assert rig.sample().u_da == 0.5
        rig.proc.send_signal(signal.SIGUSR2)  # the main loop hangs now
        end = time.monotonic() + 0.5
        while time.monotonic() < end:  # commands keep the protocol's watchdog fed
            command(0.5)
            time.sleep(0.004)
        r = rig.sample()
        assert r.status & P.STATUS_WATCHDOG and r.u_da == 0.0
        ack = P.parse_hello_ack(rig.ask(P.encode(P.MSG_HELLO, 0), P.MSG_HELLO_ACK))
        assert ack.status == 0
        rep = rig.report()
        assert rep["resets"] == 1, rep
        assert rep["duty_at_hang"] == pytest.approx(0.5, abs=2e-3), json.dumps(rep)
        assert 0 < rep["pwm_nonzero_after_hang_ms"] <= 33.0
    finally:
        rig.kill()
