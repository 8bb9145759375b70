"""Benchmark: the real-time loop's timing while the operator console streams to a browser.

Starts ``frictionlab run`` (console on loopback port 0, the port the kernel picked
read from the printed address; sim backend unless ``--backend`` says otherwise),
opens the console in headless chromium (Debian's ``/usr/bin/chromium`` driven by
Playwright), lets the loop run for ``--duration`` seconds of loop time with the
plot streaming, then reads the loop's statistics (over the whole run, start-up and
browser launch included) from ``/api/status`` and presses Exit.  ``--no-browser``
measures the same without a page connected (the server still runs).

Prints the figures; the last line is JSON: the statistics of
``frictionlab run --headless --json`` plus ``console`` (frames
sent and received, frame rate, samples the console dropped).

    .venv/bin/python benchmarks/console.py --duration 120 [--backend udp] [--no-browser]

``--clients`` measures instead what connecting pages cost the loop (no browser;
WebSocket clients in this process), in phases of loop time, each preceded by
a quiet phase of the same length for comparison:

* ``connect30``: 30 pages connect at the same moment, each reads its backlog
  (the last 30 s of the plot) until the status arrives, then stays for the rest
  of the phase;
* ``reconnect10``: 10 pages connect, read their backlog and disconnect, over
  and over, for ``--reconnect-seconds`` (10 s);
* ``stalled5``: 5 pages connect and never read.

For each phase it prints the missed deadlines (and those of the quiet phase
before it), the connections made, and whether the loop still runs (a fall
stops it: ``angle_limit``).  Exit status 1 when a load phase cost more than
``--max-missed`` (10) missed deadlines or the loop stopped.

    .venv/bin/python benchmarks/console.py --clients [--reconnect-seconds 10]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request

CHROMIUM_ARGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]


def _status(port: int) -> dict:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/status", timeout=10) as r:
        return json.loads(r.read())


def _post(port: int, path: str) -> None:
    req = urllib.request.Request(f"http://127.0.0.1:{port}{path}", data=b"{}",
                                 method="POST", headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=30) as r:
        r.read()


async def _page(ws_url: str, stay: float | None, read: bool = True) -> int:
    """One page: connect, read up to the status (the backlog), stay ``stay`` s; 1 = done."""
    import asyncio

    from websockets.asyncio.client import connect

    async with connect(ws_url, max_size=2**22, open_timeout=30) as ws:
        if read:
            while json.loads(await asyncio.wait_for(ws.recv(), 30))["type"] != "status":
                pass
        if stay:
            end = time.monotonic() + stay
            while (left := end - time.monotonic()) > 0:
                if read:
                    try:
                        await asyncio.wait_for(ws.recv(), left)
                    except TimeoutError:
                        break
                else:
                    await asyncio.sleep(left)
    return 1


async def _connect_at_once(ws_url: str, n: int, stay: float, read: bool = True) -> int:
    import asyncio

    return sum(await asyncio.gather(*[_page(ws_url, stay, read) for _ in range(n)]))


async def _reconnecting(ws_url: str, n: int, seconds: float) -> int:
    import asyncio

    end = time.monotonic() + seconds

    async def client():
        count = 0
        while time.monotonic() < end:
            count += await _page(ws_url, None)
        return count

    return sum(await asyncio.gather(*[client() for _ in range(n)]))


def _load_phases(port: int, args) -> int:
    """The ``--clients`` measurement (see the module docstring)."""
    import asyncio

    ws_url = f"ws://127.0.0.1:{port}/ws"
    phases = [
        ("connect30", lambda: _connect_at_once(ws_url, 30, 3.0)),
        ("reconnect10", lambda: _reconnecting(ws_url, 10, args.reconnect_seconds)),
        ("stalled5", lambda: _connect_at_once(ws_url, 5, args.reconnect_seconds, read=False)),
    ]
    st = _status(port)
    while st["t"] < 31.0 and st["running"]:  # a full 30 s history for every page
        time.sleep(0.5)
        st = _status(port)
    results, ok = {}, True
    for name, make in phases:
        q0 = _status(port)
        quiet_wall = args.reconnect_seconds + 3.0
        time.sleep(quiet_wall)
        q1 = _status(port)
        t0 = time.monotonic()
        connections = asyncio.run(make())
        wall = time.monotonic() - t0
        time.sleep(1.0)  # what the load left behind
        st = _status(port)
        row = {"missed": st["missed"] - q1["missed"], "quiet_missed": q1["missed"] - q0["missed"],
               "quiet_seconds": round(quiet_wall, 1), "seconds": round(wall + 1.0, 1),
               "connections": connections, "running": st["running"],
               "stop_reason": st["stop_reason"],
               "max_stall_ms": st.get("max_stall_ms"),
               "frames_dropped": st["console"]["frames_dropped"],
               "pages_refused": st["console"].get("pages_refused")}
        results[name] = row
        good = row["running"] and row["missed"] <= args.max_missed
        ok = ok and good
        print(f"  {name}: {connections} connections in {wall:.1f} s; missed {row['missed']} "
              f"(quiet {quiet_wall:.0f} s before: {row['quiet_missed']}); "
              f"{'running' if st['running'] else 'STOPPED: ' + str(st['stop_reason'])}"
              f"{'' if good else '  <-- over the limit'}", flush=True)
        if not st["running"]:
            break
    print(json.dumps({"clients": results, "max_missed": args.max_missed, "ok": ok}))
    return 0 if ok else 1


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=120.0, help="seconds of loop time")
    ap.add_argument("--backend", default="sim",
                    help="sim (default), udp (starts frictionlab rig-sim on a free port) or "
                         "any backend of frictionlab run")
    ap.add_argument("--no-browser", action="store_true", help="no page connected (baseline)")
    ap.add_argument("--chromium", default="/usr/bin/chromium")
    ap.add_argument("--clients", action="store_true",
                    help="measure connecting pages (30 at once, 10 reconnecting, 5 stalled)")
    ap.add_argument("--reconnect-seconds", type=float, default=10.0)
    ap.add_argument("--max-missed", type=int, default=10,
                    help="missed deadlines a load phase may cost (--clients)")
    args = ap.parse_args(argv)

    rig = None
    backend = args.backend
    if backend == "udp":
        rig = subprocess.Popen([sys.executable, "-m", "frictionlab", "rig-sim", "--port", "0",
                                "--json"], stdout=subprocess.PIPE, text=True)
        backend = f"udp://127.0.0.1:{json.loads(rig.stdout.readline())['port']}"
    log_dir = tempfile.mkdtemp(prefix="frictionlab-console-bench-")
    env = {k: v for k, v in os.environ.items() if k != "FRICTIONLAB_TOKEN"}
    proc = subprocess.Popen([sys.executable, "-m", "frictionlab", "run", "--port", "0",
                             "--backend", backend, "--log-dir", log_dir],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    err: list[str] = []
    threading.Thread(target=lambda: err.extend(proc.stderr), daemon=True).start()
    url = None
    for line in proc.stdout:
        m = re.search(r"frictionlab console: (http://127\.0\.0\.1:(\d+)/\S*)", line)
        if m:
            url, port = m.group(1), int(m.group(2))
            break
    if url is None:
        print("".join(err), file=sys.stderr)
        return 1
    threading.Thread(target=lambda: [None for _ in proc.stdout], daemon=True).start()

    pw = browser = page = None
    try:
        started = False
        while not (st := _status(port))["running"] or st["ticks"] == 0:
            if not st["running"] and not started and backend != "sim":
                _post(port, "/api/start")  # a rig's loop waits for Start
                started = True
            if proc.poll() is not None:
                raise SystemExit("frictionlab run ended: " + "".join(err))
            time.sleep(0.1)
        if args.clients:
            print(f"console load benchmark: backend {args.backend}", flush=True)
            return _load_phases(port, args)
        if not args.no_browser:
            from playwright.sync_api import sync_playwright

            pw = sync_playwright().start()
            browser = pw.chromium.launch(executable_path=args.chromium, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.goto(url)
            page.wait_for_selector("#conn.live", timeout=30_000)
        t0 = _status(port)["t"]
        frames0 = page.evaluate("() => window.__console.frames") if page else 0
        wall0 = time.monotonic()
        while (st := _status(port))["t"] < t0 + args.duration:
            if not st["running"]:
                break
            time.sleep(0.5)
        wall = time.monotonic() - wall0
        frames = (page.evaluate("() => window.__console.frames") - frames0) if page else 0
        st = _status(port)
    finally:
        if browser is not None:
            browser.close()
        if pw is not None:
            pw.stop()
        try:
            _post(port, "/api/exit")
        except OSError:
            proc.send_signal(signal.SIGTERM)
        proc.wait(30)
        if rig is not None:
            rig.send_signal(signal.SIGTERM)
            rig.wait(10)

    con = st["console"]
    out = {
        "ticks": st["ticks"], "missed": st["missed"], "overruns": st["overruns"],
        "jitter_ms": {k: st["jitter_ms"][k] for k in ("p50", "p99", "max")},
        "compute_us": {k: st["compute_us"][k] for k in ("p50", "p99")},
        "max_stall_ms": st.get("max_stall_ms"),
        "stop_reason": st["stop_reason"], "log": st.get("log"),
        "missed_fraction": st["missed"] / max(st["ticks"] + st["missed"], 1),
        "dropped_log_samples": st.get("dropped_log_samples"),
        "console": {"browser": not args.no_browser, "frames_sent": con["frames_sent"],
                    "frames_received": frames,
                    "frames_per_s": round(frames / wall, 2) if wall > 0 else None,
                    "frames_dropped": con["frames_dropped"],
                    "samples_dropped": con["samples_dropped"]},
        "duration_s": args.duration, "backend": args.backend,
    }
    j, c = out["jitter_ms"], out["compute_us"]
    print(f"console benchmark: {args.duration:g} s of loop time, backend {args.backend}, "
          f"{'browser connected' if not args.no_browser else 'no browser'}; loop "
          f"{'still running' if st['running'] else 'stopped: ' + str(st['stop_reason'])}")
    print(f"  ticks {out['ticks']}, missed {out['missed']} ({100 * out['missed_fraction']:.3f}%), "
          f"overruns {out['overruns']}, max stall {out['max_stall_ms']} ms")
    print(f"  jitter p50 {j['p50']} ms, p99 {j['p99']} ms, max {j['max']} ms; "
          f"compute p50 {c['p50']} us, p99 {c['p99']} us")
    print(f"  page: {frames} frames ({out['console']['frames_per_s']} /s), console dropped "
          f"{con['samples_dropped']} samples, {con['frames_dropped']} frames")
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
