"""``firmware/test-hil``: build the firmware and the harness, run the emulated
rig (firmware/hil/rig.py) and ``frictionlab run --backend serial://PTY
--headless --json`` against it, print one JSON line::

    {"run": <the run's JSON>, "pwm_zero_after_stall_ms": MS | null,
     "watchdog_ms": MS, "flash_bytes": N, "ram_bytes": N, "harness": {...}}

``--plant furuta-dc`` (the default): the home-built rig of docs/build-a-rig.md
(frictionlab's DC-motor plant with the HOMEBUILT preset, V = duty x 12 V),
and the controller ``frictionlab run --plant furuta-dc`` with that rig's
``plant.*``, ``friction.*`` and ``design.*`` keys (rig.py: ``homebuilt_keys``)
and ``rig.u_scale`` = 1/12 duty per volt.  ``--plant thesis``: the thesis's
plant, u = duty / rig.u_scale m/s^2, rig.u_scale = -0.022 on both sides.

``--stall-at S``: S seconds into the run (after its first command) the
controller is stopped with
SIGSTOP (and continued 1 s later, when it stops itself as ``paused``);
``pwm_zero_after_stall_ms`` is how long the duty stayed non-zero after that,
in emulated time.  ``harness`` is the harness's report (emulated time, lag
behind the wall clock, bytes each way, AVR resets).
"""

from __future__ import annotations

import argparse
import json
import re
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
FIRMWARE = HERE.parent
MCU = "atmega328p"
#: The controller's calibration for the firmware's readings (docs/build-a-rig.md,
#: "Scales for the controller"); rig.u_scale is the plant's (:func:`plant_sets`).
RIG_SETS = ("rig.theta_scale=3.141592653589793", "rig.theta_bias=0.5",
            "rig.arm_scale=3.141592653589793", "rig.velocity_scale=40", "rig.velocity_bias=0")


def plant_sets(plant: str, u_scale: float | None) -> tuple[list[str], list[str]]:
    """(the emulated rig's ``--set`` arguments, the controller's ``run`` arguments)
    for ``--plant``: the plant's own keys and ``rig.u_scale`` (duty per unit of
    u; default 1/12 V for furuta-dc, the thesis's -0.022 for thesis)."""
    if plant == "furuta-dc":
        from rig import homebuilt_keys

        supply = dict(homebuilt_keys())["plant.voltage_limit"]
        scale = 1.0 / supply if u_scale is None else u_scale
        # the rig: V = duty x supply (rig.py); the controller: u_DA = u x rig.u_scale
        ctrl = ["--plant", "furuta-dc"]
        for key, value in homebuilt_keys():
            ctrl += ["--set", f"{key}={value}"]
        return [], [*ctrl, "--set", f"rig.u_scale={scale!r}"]
    scale = -0.022 if u_scale is None else u_scale
    return ["--set", f"rig.u_scale={scale!r}"], ["--set", f"rig.u_scale={scale!r}"]


def sizes(elf: Path) -> tuple[int, int]:
    """(flash bytes, static RAM bytes) of an AVR ELF: text + data, data + bss."""
    out = subprocess.run(["avr-size", "-A", str(elf)], capture_output=True, text=True,
                         check=True).stdout
    sec = {m.group(1): int(m.group(2)) for m in re.finditer(r"^\.(\w+)\s+(\d+)", out, re.M)}
    return sec.get("text", 0) + sec.get("data", 0), sec.get("data", 0) + sec.get("bss", 0)


def watchdog_ms() -> int:
    text = (FIRMWARE / "src" / "config.h").read_text()
    return int(re.search(r"#define WATCHDOG_MS (\d+)", text).group(1))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="the rig firmware in simavr against frictionlab run")
    p.add_argument("--duration", type=float, default=10.0, help="the run's --duration (s)")
    p.add_argument("--stall-at", type=float, default=None, metavar="S",
                   help="SIGSTOP the controller S seconds into the run")
    p.add_argument("--plant", default="furuta-dc",
                   help="the plant of firmware/hil/rig.py (furuta-dc: the home-built rig)")
    p.add_argument("--u-scale", type=float, default=None,
                   help="the controller's rig.u_scale: duty per unit of u (default the "
                        "plant's: 1/12 per volt for furuta-dc, -0.022 per m/s^2 for thesis, "
                        "which the thesis plant takes too)")
    p.add_argument("--strict", action="store_true",
                   help="the controller's own safety limits; by default the run gets the test "
                        "suite's slack for a busy host (--silent-periods 100 --max-pause 0.5)")
    p.add_argument("--keep", default=None, metavar="DIR",
                   help="keep the run's log in DIR (default: a temporary folder)")
    args = p.parse_args(argv)
    if not args.duration > 0:
        p.error("--duration must be > 0")

    build = FIRMWARE / "build"
    subprocess.run(["make", "-s", "-C", str(FIRMWARE), f"MCU={MCU}", "hil"], check=True,
                   stdout=subprocess.DEVNULL)
    elf = build / MCU / "rig.elf"
    flash, ram = sizes(elf)
    tmp = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="test-hil-"))
    tmp.mkdir(parents=True, exist_ok=True)
    rig_args, ctrl_args = plant_sets(args.plant, args.u_scale)
    rig = subprocess.Popen(
        [sys.executable, str(HERE / "rig.py"), "--lib", str(build / "host" / "libhil.so"),
         "--elf", str(elf), "--mcu", MCU, "--plant", args.plant, *rig_args],
        stdout=subprocess.PIPE, stderr=open(tmp / "rig.err", "w"), text=True,
        process_group=0)
    ctrl = None
    try:
        line = rig.stdout.readline()
        if not line.startswith("pty "):
            raise RuntimeError(f"the emulated rig did not start: {(tmp / 'rig.err').read_text()}")
        pty = line.split(None, 1)[1].strip()
        log_dir = tmp / "runs"
        cmd = [sys.executable, "-m", "frictionlab", "run", "--backend", f"serial://{pty}",
               "--headless", "--json", "--duration", str(args.duration),
               "--log-dir", str(log_dir)]
        if not args.strict:
            cmd += ["--silent-periods", "100", "--max-pause", "0.5"]
        for s in RIG_SETS:
            cmd += ["--set", s]
        cmd += ctrl_args
        ctrl = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=open(tmp / "run.err", "w"),
                                text=True, process_group=0)
        if args.stall_at is not None:
            # the run's t = 0: its first COMMAND released the pendulum
            end = time.monotonic() + 300
            while True:
                ready, _, _ = select.select([rig.stdout], [], [], 0.1)
                if ready and rig.stdout.readline().strip() == "released":
                    break
                if ctrl.poll() is not None or time.monotonic() > end:
                    raise RuntimeError("the run did not start: "
                                       + (tmp / "run.err").read_text()[-2000:])
            time.sleep(args.stall_at)
            ctrl.send_signal(signal.SIGSTOP)
            rig.send_signal(signal.SIGUSR1)
            time.sleep(1.0)  # longer than --max-pause: the controller stops as paused
            ctrl.send_signal(signal.SIGCONT)
        out, _ = ctrl.communicate(timeout=args.duration + 120)
        try:
            run = json.loads(out.strip().splitlines()[-1])
        except (ValueError, IndexError):
            run = {"error": (tmp / "run.err").read_text().strip()[-2000:],
                   "returncode": ctrl.returncode}
    finally:
        if ctrl is not None and ctrl.poll() is None:
            ctrl.kill()
        rig.send_signal(signal.SIGTERM)
        try:
            rest, _ = rig.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            rig.kill()
            rest = ""
    harness = json.loads(rest.strip().splitlines()[-1]) if rest.strip() else {}
    result = {"run": run,
              "pwm_zero_after_stall_ms": (harness.get("pwm_nonzero_after_mark_ms")
                                          if args.stall_at is not None else None),
              "watchdog_ms": watchdog_ms(), "flash_bytes": flash, "ram_bytes": ram,
              "harness": harness}
    print(json.dumps(result))
    if not args.keep:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0 if "error" not in run else 1


if __name__ == "__main__":
    sys.exit(main())
