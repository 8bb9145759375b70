"""Benchmark: a stop signal during ``frictionlab run``'s start-up.

Starts ``frictionlab run --headless --json --duration 5`` (``python -m
frictionlab``) against an emulated rig over UDP whose pendulum is upright (a run
that starts writes u != 0 at once) and that records every command; sends SIGINT
``--delays`` seconds after the process started (0.1, 0.35, 0.6 by default), with the
inherited SIGINT disposition default or ignored (as under ``nohup`` or ``&`` in a
script), ``--repeat`` times each.  Reports, per case, the time from the signal to
the process's exit (min / median / max), the stop reasons, the ticks run and the
largest |u_DA| the rig received.  A signal that comes before the interpreter has run
frictionlab's first line (Python's own start-up) cannot be caught when it is ignored:
the time from the start to the handler (``/proc/PID/status``, SigCgt) is reported
too.  The last line is one JSON object.

    .venv/bin/python benchmarks/start_signals.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time

from frictionlab.config import build_config
from frictionlab.realtime import protocol as P
from frictionlab.realtime.clock import MonotonicClock
from frictionlab.realtime.rigsim import RigEmulator, serve_udp


class Watching(RigEmulator):
    def handle_frame(self, frame):
        if isinstance(frame, P.Frame) and frame.type == P.MSG_COMMAND:
            self.commands.append(P.parse_command(frame))
        return super().handle_frame(frame)


def catches_sigterm(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/status") as fh:
            for line in fh:
                if line.startswith("SigCgt:"):
                    return bool(int(line.split()[1], 16) >> (signal.SIGTERM - 1) & 1)
    except OSError:
        pass
    return False


def one(port: int, emu: Watching, delay: float, ignored: bool) -> dict:
    emu.commands = []
    with tempfile.TemporaryDirectory() as logs:
        t0 = time.monotonic()
        proc = subprocess.Popen(
            [sys.executable, "-m", "frictionlab", "run", "--headless", "--json",
             "--duration", "5", "--backend", f"udp://127.0.0.1:{port}", "--log-dir", logs],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, process_group=0,
            preexec_fn=(lambda: signal.signal(signal.SIGINT, signal.SIG_IGN)) if ignored
            else None)
        handler = None
        while proc.poll() is None and time.monotonic() - t0 < delay:
            if handler is None and catches_sigterm(proc.pid):
                handler = time.monotonic() - t0
            time.sleep(0.001)
        t_sig = time.monotonic()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
        t_end = time.monotonic()
    try:
        st = json.loads(out)
    except ValueError:
        st = {"stop_reason": f"exit {proc.returncode}: {err.strip()[-120:]}", "ticks": None}
    return {"exit_s": t_end - t_sig, "handler_s": handler, "stop_reason": st["stop_reason"],
            "ticks": st["ticks"], "returncode": proc.returncode,
            "max_u_da": max((abs(c) for c in emu.commands), default=0.0)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--delays", default="0.1,0.35,0.6")
    args = ap.parse_args()
    emu = Watching(build_config("fast", "classical"), MonotonicClock())
    emu.commands = []
    stop, addr = threading.Event(), []
    threading.Thread(target=serve_udp, args=(emu, "127.0.0.1", 0, stop),
                     kwargs={"ready": addr.append, "prewarm_us": 0}, daemon=True).start()
    while not addr:
        time.sleep(0.01)
    results = {}
    for delay in (float(d) for d in args.delays.split(",")):
        for ignored in (False, True):
            runs = [one(addr[0][1], emu, delay, ignored) for _ in range(args.repeat)]
            ex = [r["exit_s"] for r in runs]
            key = f"{delay:g}s_{'ignored' if ignored else 'default'}"
            results[key] = {
                "exit_s": {"min": min(ex), "median": statistics.median(ex), "max": max(ex)},
                "stop_reasons": sorted({str(r["stop_reason"]) for r in runs}),
                "ticks": sorted({r["ticks"] for r in runs}, key=str),
                "max_u_da": max(r["max_u_da"] for r in runs),
                "handler_s": [r["handler_s"] for r in runs]}
            r = results[key]
            print(f"SIGINT at {delay:g} s, inherited {'ignored' if ignored else 'default'}: "
                  f"exit {r['exit_s']['min']:.2f} / {r['exit_s']['median']:.2f} / "
                  f"{r['exit_s']['max']:.2f} s after the signal; {r['stop_reasons']}, "
                  f"ticks {r['ticks']}, largest |u_DA| at the rig {r['max_u_da']:g}")
    stop.set()
    print(json.dumps(results))


if __name__ == "__main__":
    main()
