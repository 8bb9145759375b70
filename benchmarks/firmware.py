"""The rig firmware's figures (docs/build-a-rig.md, docs/performance.md "Rig firmware").

    python benchmarks/firmware.py [--json]

Builds the firmware and the simavr harness, then, with the emulator running as
fast as the host can (no real-time pacing), prints:

* flash and static RAM of the ATmega328P build;
* the reply time in emulated time: from a SAMPLE's last byte into the UART to
  the SENSOR's last byte out (mean over 200 requests);
* the host's CPU per emulated millisecond, the plant (the home-built rig,
  ``--plant furuta-dc``) held and stepping;
* lost encoder counts with both encoders turning at a given speed for 0.3 s
  (``--plant spin``), for a few speeds.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import math
import os
import subprocess
import sys
import time
import tty
from pathlib import Path

from _measure import load_average

ROOT = Path(__file__).resolve().parents[1]
FW = ROOT / "firmware"
sys.path.insert(0, str(FW / "hil"))
import rig as R  # noqa: E402  (firmware/hil/rig.py)

from frictionlab.realtime import protocol as P  # noqa: E402

ELF = FW / "build" / "atmega328p" / "rig.elf"
LIB = FW / "build" / "host" / "libhil.so"


class Args:
    design, friction, set, theta0 = "fast", "classical", [], 0.05
    spin_speed, spin_time = 100.0, 0.3


def session(plant):
    """A fresh emulator (in a child process: simavr keeps global state) is not
    needed for one measurement at a time; each call runs in its own process."""
    lib = R.load(str(LIB))
    c = R.counts(*plant.angles())
    assert lib.hil_open(str(ELF).encode(), b"atmega328p", c[0], c[1], 20, -1.0) == 0
    lib.hil_free_run(1)
    fd = os.open(lib.hil_pty().decode(), os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    tty.setraw(fd)
    return lib, fd


def drain(fd) -> bytes:
    try:
        return os.read(fd, 4096)
    except BlockingIOError:
        return b""


def run_ms(lib, plant, n: int, stepping: bool = True) -> None:
    for _ in range(n):
        d = lib.hil_duty()
        if stepping and not lib.hil_held():
            plant.step(d)
        lib.hil_set_counts(*R.counts(*plant.angles()))
        lib.hil_run_ms()


def measure_reply_and_cpu() -> dict:
    plant = R.PLANTS["furuta-dc"](Args)  # the home-built rig, test-hil's default
    lib, fd = session(plant)
    os.write(fd, P.encode(P.MSG_HELLO, 0))
    run_ms(lib, plant, 20)
    drain(fd)
    replies = []
    rx, tx = ctypes.c_double(), ctypes.c_double()
    for k in range(200):
        os.write(fd, P.sample_frame(k))
        got = b""
        while len(got) < 31:
            run_ms(lib, plant, 1, stepping=False)
            got += drain(fd)
        lib.hil_last_io(ctypes.byref(rx), ctypes.byref(tx))
        replies.append(tx.value - rx.value)
    out = {"reply_ms_emulated": sum(replies) / len(replies)}
    for stepping in (False, True):
        if stepping:  # release the pendulum: it falls, the encoders move
            os.write(fd, P.command_frame(1000, 0.0))
        cpu = time.process_time()
        run_ms(lib, plant, 2000, stepping)
        key = "cpu_us_per_ms_stepping" if stepping else "cpu_us_per_ms_held"
        out[key] = (time.process_time() - cpu) / 2000 * 1e6
    return out


def lost_counts(speed: float) -> dict:
    args = Args()
    args.spin_speed = speed
    plant = R.SpinPlant(args)
    lib, fd = session(plant)
    dec = P.FrameDecoder()
    os.write(fd, P.encode(P.MSG_HELLO, 0))
    run_ms(lib, plant, 5)
    os.write(fd, P.command_frame(0, 0.0))
    run_ms(lib, plant, round(args.spin_time * 1e3) + 50)
    drain(fd)
    os.write(fd, P.sample_frame(1))
    frames = []
    while not frames:
        run_ms(lib, plant, 1)
        frames = [f for f in dec.feed(drain(fd)) if isinstance(f, P.Frame)
                  and f.type == P.MSG_SENSOR]
    r = P.parse_sensor(frames[0])
    n = R.COUNTS
    pend, arm = R.counts(*plant.angles())
    got_pend = round((r.y + 1) * n / 2) - 3 * n // 4
    got_arm = round((r.x + 1) * n / 2) - n // 2
    lost_p = (pend - got_pend) % n
    lost_a = (arm - got_arm) % n
    return {"speed_rad_s": speed, "edges_per_s": speed * n / (2 * math.pi),
            "lost_pendulum": min(lost_p, n - lost_p), "lost_arm": min(lost_a, n - lost_a)}


def in_child(func, *args):
    """Run func in a fresh process (simavr's state is global)."""
    code = (f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); "
            f"import firmware as B, json; print(json.dumps(B.{func}(*{list(args)!r})))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=Path(__file__).parent)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    subprocess.run(["make", "-s", "-C", str(FW), "hil"], check=True, stdout=subprocess.DEVNULL)
    size = subprocess.run(["avr-size", "-A", str(ELF)], capture_output=True, text=True).stdout
    sec = {line.split()[0]: int(line.split()[1]) for line in size.splitlines()
           if line.startswith(".")}
    res = {"flash_bytes": sec[".text"] + sec[".data"], "ram_bytes": sec[".data"] + sec[".bss"],
           **in_child("measure_reply_and_cpu"),
           "lost_counts": [in_child("lost_counts", s) for s in (100.0, 150.0, 200.0, 300.0)],
           "load_average": load_average()}
    if args.json:
        print(json.dumps(res))
        return 0
    print(f"flash {res['flash_bytes']} bytes, static RAM {res['ram_bytes']} bytes")
    print(f"SAMPLE -> SENSOR: {res['reply_ms_emulated']:.3f} ms emulated")
    print(f"host CPU per emulated ms: {res['cpu_us_per_ms_held']:.0f} us held, "
          f"{res['cpu_us_per_ms_stepping']:.0f} us stepping")
    for r in res["lost_counts"]:
        print(f"{r['speed_rad_s']:5.0f} rad/s ({r['edges_per_s']:6.0f} edges/s each): lost "
              f"{r['lost_pendulum']} pendulum, {r['lost_arm']} arm counts")
    print(f"load average {res['load_average']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
