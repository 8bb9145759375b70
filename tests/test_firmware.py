"""The rig firmware's portable core (firmware/src: protocol session, framing,
CRC, quadrature decoding, watchdog), compiled natively with gcc and driven
through ``firmware/test/unit_tests.c``.  Frames are built and read with
:mod:`frictionlab.realtime.protocol`, so the firmware's encoding and CRC are
checked against the controller's own.  The AVR build in the emulator:
tests/test_firmware_hil.py."""

from __future__ import annotations

import math
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

from frictionlab.realtime import protocol as P

# one gcc build per module (about a second), then each test runs in milliseconds
pytestmark = pytest.mark.slow

FIRMWARE = Path(__file__).resolve().parents[1] / "firmware"
# firmware/src/config.h defaults
PEND_COUNTS = ARM_COUNTS = 2400
WATCHDOG_MS = 50
VEL_WINDOW_MS = 10
VEL_FULL_SCALE = 40.0


@pytest.fixture(scope="module")
def unit_tests(tmp_path_factory):
    out = tmp_path_factory.mktemp("fw")
    subprocess.run(["make", "-s", "-C", str(FIRMWARE), f"HOST_BUILD={out}",
                    f"{out}/unit-tests"], check=True, capture_output=True)
    return out / "unit-tests"


class Rig:
    """One run of the firmware's script driver."""

    def __init__(self, exe):
        self.exe = exe
        self.lines: list[str] = []

    def send(self, *frames: bytes) -> Rig:
        self.lines.append("bytes " + b"".join(frames).hex())
        return self

    def cmd(self, line: str) -> Rig:
        self.lines.append(line)
        return self

    def state(self) -> Rig:
        return self.cmd("state")

    def run(self):
        res = subprocess.run([str(self.exe), "script"], input="\n".join(self.lines) + "\n",
                             capture_output=True, text=True, check=True, timeout=30)
        out = []
        for line in res.stdout.splitlines():
            kind, _, rest = line.partition(" ")
            if kind == "tx":
                out.append(P.decode(bytes.fromhex(rest)))
            elif kind == "state":
                duty, status, bad, trips = rest.split()
                out.append({"duty": float(duty), "status": int(status), "bad": int(bad),
                            "trips": int(trips)})
            elif kind == "quad":
                out.append(tuple(int(v) for v in rest.split()))
            else:
                raise AssertionError(line)
        return out


def hello(seq=0):
    return P.encode(P.MSG_HELLO, seq)


def test_selftest(unit_tests):
    res = subprocess.run([str(unit_tests), "selftest"], capture_output=True, text=True)
    assert res.returncode == 0, res.stdout
    assert res.stdout.startswith("ok ")


def test_hello_ack_advertises_the_real_watchdog_and_period(unit_tests):
    (ack,) = Rig(unit_tests).send(hello(0)).run()
    assert ack.type == P.MSG_HELLO_ACK and ack.seq == 0
    info = P.parse_hello_ack(ack)
    assert info == P.HelloInfo(adc_bits=12, status=0, watchdog_ms=WATCHDOG_MS, h_tenth_ms=50)


def test_sensor_answers_with_the_request_sequence_number_and_the_wrapped_channels(unit_tests):
    rng = np.random.default_rng(3)
    rig = Rig(unit_tests).send(hello())
    cases = []
    for seq in (0, 1, 7, 2**32 - 3, 2**31):
        p, a = (int(v) for v in rng.integers(-50_000, 50_000, 2))
        d = int(rng.integers(-80, 80))
        cases.append((seq, p, a, d))
        rig.cmd(f"counts {p} {a} {d}").send(P.sample_frame(seq))
    replies = rig.run()[1:]
    assert len(replies) == len(cases)
    for (seq, p, a, d), frame in zip(cases, replies, strict=True):
        assert frame.seq == seq
        r = P.parse_sensor(frame)
        # y: 0.5 hanging at power-up, -0.5 half a turn away; x: 0 at power-up; both wrap
        assert r.y == pytest.approx(2 * ((p + 3 * PEND_COUNTS // 4) % PEND_COUNTS) / PEND_COUNTS
                                    - 1, abs=1e-6)
        assert r.x == pytest.approx(2 * ((a + ARM_COUNTS // 2) % ARM_COUNTS) / ARM_COUNTS - 1,
                                    abs=1e-6)
        v = d * 2 * math.pi / ARM_COUNTS / (VEL_WINDOW_MS * 1e-3) / VEL_FULL_SCALE
        assert r.v == pytest.approx(min(max(v, -1), 1), abs=1e-6)
        assert -1 <= r.y < 1 and -1 <= r.x < 1
        assert r.u_da == 0.0 and r.status == 0


def test_command_is_applied_at_once_clipped_and_echoed(unit_tests):
    out = (Rig(unit_tests).send(hello()).send(P.command_frame(0, 0.25)).state()
           .send(P.sample_frame(1))
           .send(P.command_frame(1, 1.5)).state()
           .send(P.command_frame(2, float("nan"))).state()
           .send(P.command_frame(3, -0.5)).state().run())
    s1, sensor, s2, s3, s4 = out[1:]
    assert s1["duty"] == 0.25 and s1["status"] == 0
    assert P.parse_sensor(sensor).u_da == 0.25
    assert s2["duty"] == 1.0 and s2["status"] == P.STATUS_SATURATED
    assert s3["duty"] == 0.0 and s3["status"] == P.STATUS_SATURATED
    assert s4["duty"] == -0.5 and s4["status"] == 0


def test_stale_commands_are_ignored_by_serial_number_arithmetic(unit_tests):
    out = (Rig(unit_tests).send(hello())
           .send(P.command_frame(2**32 - 2, 0.1)).state()
           .send(P.command_frame(1, 0.2)).state()          # ahead across the wrap
           .send(P.command_frame(2**32 - 1, 0.3)).state()  # behind: stale
           .send(P.command_frame(1, 0.4)).state()          # the same number: applied
           .send(hello()).send(P.command_frame(0, 0.5)).state()  # HELLO forgets it
           .run())
    assert [s["duty"] for s in out if isinstance(s, dict)] == pytest.approx(
        [0.1, 0.2, 0.2, 0.4, 0.5])


def test_commands_before_the_first_hello_are_ignored(unit_tests):
    out = Rig(unit_tests).send(P.command_frame(5, 0.7)).state().run()
    assert out[0]["duty"] == 0.0


def test_hello_turns_the_motor_off(unit_tests):
    out = (Rig(unit_tests).send(hello()).send(P.command_frame(0, -0.9)).state()
           .send(hello(0)).state().run())
    assert out[1]["duty"] == pytest.approx(-0.9) and out[3]["duty"] == 0.0


def test_watchdog_zeroes_the_motor_and_latches_until_hello(unit_tests):
    out = (Rig(unit_tests).send(hello()).cmd(f"tick {5 * WATCHDOG_MS}").state()  # disarmed
           .send(P.command_frame(0, 0.6)).cmd(f"tick {WATCHDOG_MS - 1}").state()
           .send(P.command_frame(1, 0.6)).cmd(f"tick {WATCHDOG_MS - 1}").state()
           .cmd("tick 1").state()
           .send(P.sample_frame(3))
           .send(P.command_frame(3, 0.6)).state()     # not applied while tripped
           .send(hello(0)).state()
           .send(P.command_frame(0, 0.3)).state().run())
    _, idle, before, fed, tripped, sensor, ignored, ack, reopened, after = out
    assert idle["duty"] == 0.0 and idle["trips"] == 0
    assert before["duty"] == pytest.approx(0.6) and fed["duty"] == pytest.approx(0.6)
    assert fed["status"] == 0
    assert tripped["duty"] == 0.0 and tripped["status"] == P.STATUS_WATCHDOG
    r = P.parse_sensor(sensor)
    assert r.u_da == 0.0 and r.status == P.STATUS_WATCHDOG
    assert ignored["duty"] == 0.0 and ignored["status"] == P.STATUS_WATCHDOG
    assert P.parse_hello_ack(ack).status == 0
    assert reopened["duty"] == 0.0 and reopened["status"] == 0
    assert after["duty"] == pytest.approx(0.3) and after["status"] == 0 and after["trips"] == 1


def test_a_reset_by_the_hardware_watchdog_reports_watchdog_until_hello(unit_tests):
    out = (Rig(unit_tests).cmd("reset 1").send(P.sample_frame(4)).send(P.command_frame(4, 0.5))
           .state().send(hello()).run())
    sensor, state, ack = out
    assert P.parse_sensor(sensor).status == P.STATUS_WATCHDOG and state["duty"] == 0.0
    assert P.parse_hello_ack(ack).status == 0


def test_every_single_bit_error_is_rejected_and_the_stream_resynchronises(unit_tests):
    good = P.command_frame(1, 0.5)
    rig = Rig(unit_tests).send(hello())
    for bit in range(len(good) * 8):
        bad = bytearray(good)
        bad[bit // 8] ^= 1 << (bit % 8)
        # the damaged frame, then a SAMPLE right behind it
        rig.send(bytes(bad), P.sample_frame(1000 + bit)).state()
    out = rig.run()[1:]
    sensors = [f for f in out if isinstance(f, P.Frame)]
    states = [s for s in out if isinstance(s, dict)]
    assert [f.seq for f in sensors] == [1000 + b for b in range(len(good) * 8)]
    assert all(s["duty"] == 0.0 for s in states)
    # every damaged frame but those hit in the sync bytes (noise, skipped) is counted
    assert states[-1]["bad"] >= len(good) * 8 - 16


def test_noise_split_frames_and_foreign_messages_between_frames(unit_tests):
    sample = P.sample_frame(9)
    rig = Rig(unit_tests).send(b"\x00\xa5\xa5\x13\x5a")  # power-up noise, half syncs
    rig.send(hello(0))
    for i in range(len(sample)):                          # one byte at a time
        rig.send(sample[i:i + 1])
    rig.send(P.control_frame(3, {"cmd": "status"}))       # for the emulated rig only
    rig.send(P.encode(P.MSG_SENSOR, 4, P.sensor_payload(0, 0, 0, 0, 0)))  # wrong direction
    rig.send(P.encode(P.MSG_COMMAND, 2, b"\x00\x00"))     # wrong length for its type
    rig.send(P.command_frame(2, -0.25)).state()
    ack, sensor, state = rig.run()
    assert ack.type == P.MSG_HELLO_ACK and sensor.seq == 9 and sensor.type == P.MSG_SENSOR
    assert state["duty"] == -0.25 and state["bad"] >= 3


@pytest.mark.parametrize("steps", [1, 10_000])
def test_quadrature_walk_counts_every_edge(unit_tests, steps):
    """A random walk of single edges ends at its net count with no error; a jump
    across two states is an error, not a count."""
    rng = np.random.default_rng(steps)
    order = [0, 2, 3, 1]  # 00 -> 10 -> 11 -> 01: forwards
    moves = rng.choice([-1, 1], size=steps)
    pos = np.concatenate([[0], np.cumsum(moves)])
    states = " ".join(str(order[p % 4]) for p in pos)
    count, errors = Rig(unit_tests).cmd(f"quad {states}").cmd("quad 0 3 0").run()[0]
    assert (count, errors) == (int(pos[-1]), 0)
    (jump,) = Rig(unit_tests).cmd("quad 0 3 1").run()
    assert jump == (1, 1)


def test_float_encoding_matches_struct(unit_tests):
    """u_DA echoes bit for bit (float32 little-endian)."""
    u = struct.unpack("<f", struct.pack("<f", -0.123456789))[0]
    out = Rig(unit_tests).send(hello(), P.command_frame(0, u), P.sample_frame(1)).run()
    assert P.parse_sensor(out[1]).u_da == u


@pytest.mark.parametrize("mcu, flash_kb", [("atmega328p", 32), ("atmega2560", 256)])
def test_the_avr_build_fits(tmp_path, mcu, flash_kb):
    """``make -C firmware`` (and ``MCU=atmega2560``) builds with -Werror; the
    ATmega328P build within 32 KB of flash and 1.5 KB of static RAM."""
    subprocess.run(["make", "-s", "-C", str(FIRMWARE), f"MCU={mcu}", f"BUILD={tmp_path}",
                    f"{tmp_path}/rig.hex"], check=True, capture_output=True)
    out = subprocess.run(["avr-size", "-A", str(tmp_path / "rig.elf")], capture_output=True,
                         text=True, check=True).stdout
    sec = {line.split()[0]: int(line.split()[1]) for line in out.splitlines()
           if line.startswith(".")}
    assert sec[".text"] + sec[".data"] <= min(flash_kb, 32) * 1024
    assert sec[".data"] + sec[".bss"] <= 1536
    assert (tmp_path / "rig.hex").read_text().startswith(":")
