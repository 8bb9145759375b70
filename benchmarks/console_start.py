"""Benchmark: does the console's printed address answer when it is printed?

Starts ``frictionlab run --port 0`` (the default console: sim backend, the loop
started automatically) and measures, from the process's start:

* ``printed_s``: until the line ``frictionlab console: http://...`` appears;
* ``answered_s``: until ``GET /api/status`` at that address first answers 200
  (polled every 10 ms from the moment the line appears);
* ``gap_s``: ``answered_s - printed_s``, the time an operator who opens the
  address at once waits (refused connections) - the figure the address must
  keep near zero.

The first start uses an empty numba cache of its own (``NUMBA_CACHE_DIR`` in a
temporary folder: every kernel compiles, as after an install); the later starts
reuse that cache (as every start after the first).  Each start ends with Exit.

    .venv/bin/python benchmarks/console_start.py [--repeats 3]

The last line is JSON: ``{"first": {...}, "later": [{...}, ...]}``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request

_URL = re.compile(r"frictionlab console: (http://\S+)")


def _post(url: str) -> None:
    req = urllib.request.Request(url, data=b"{}", method="POST",
                                 headers={"Content-Type": "application/json"})
    urllib.request.urlopen(req, timeout=30).read()


def one_start(cache_dir: str, log_dir: str) -> dict:
    """One ``frictionlab run`` from spawn to its console answering; then Exit."""
    env = {**os.environ, "NUMBA_CACHE_DIR": cache_dir, "PYTHONUNBUFFERED": "1"}
    env.pop("FRICTIONLAB_TOKEN", None)
    t0 = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "frictionlab", "run", "--port", "0",
                             "--log-dir", log_dir, "--sim-lockstep"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                            env=env)
    try:
        url = None
        for line in proc.stdout:
            m = _URL.search(line)
            if m:
                url = m.group(1)
                break
        printed = time.monotonic() - t0
        if url is None:
            raise RuntimeError("frictionlab run printed no address")
        refused = 0
        while True:
            try:
                with urllib.request.urlopen(url + "api/status", timeout=30) as resp:
                    if resp.status == 200:
                        break
            except (urllib.error.URLError, ConnectionError):
                refused += 1
            time.sleep(0.01)
        answered = time.monotonic() - t0
        _post(url + "api/exit")
        proc.wait(30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return {"printed_s": round(printed, 3), "answered_s": round(answered, 3),
            "gap_s": round(answered - printed, 3), "refused_polls": refused}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3, help="later starts (default 3)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        cache = os.path.join(tmp, "numba-cache")
        os.mkdir(cache)
        first = one_start(cache, tmp)
        print(f"first start (empty numba cache): address printed after "
              f"{first['printed_s']:.2f} s, answering after {first['answered_s']:.2f} s "
              f"(gap {first['gap_s']:.3f} s)")
        later = []
        for i in range(args.repeats):
            r = one_start(cache, tmp)
            later.append(r)
            print(f"start {i + 2}: address printed after {r['printed_s']:.2f} s, answering "
                  f"after {r['answered_s']:.2f} s (gap {r['gap_s']:.3f} s)")
    print(json.dumps({"first": first, "later": later, "load": os.getloadavg()[0]}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
