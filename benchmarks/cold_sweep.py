r"""The first sweep after an install: numba compiles the batch evaluator into an empty cache.

A fresh process imports frictionlab and runs a small sweep (8 sets of 2 s,
the thread backend, ``evaluate``'s defaults) with ``NUMBA_CACHE_DIR`` set to
an empty folder, as on the first sweep after ``pip install`` or an upgrade
(the package keys its cache on its sources); then a second process with the
same, now filled, cache.  Figures (wall time of the whole process run):

* ``cold_s`` - the first process (imports, compiling every kernel the batch
  calls, the sweep);
* ``warm_s`` - the second (imports, loading the compiled code, the sweep).

Best and median of ``--rounds`` pairs, each with a new empty cache.  Pass
``--src DIR`` to time another checkout's ``src`` (for before/after figures)
with this interpreter.  The last printed line is a JSON object.

Usage::

    .venv/bin/python benchmarks/cold_sweep.py [--rounds 2] [--src DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

from _measure import load_average

SWEEP = """
from frictionlab.config import build_config
from frictionlab.studies.sweep import evaluate
base = build_config("fast", "classical")
evaluate(base, [{"friction.coulomb": 1.0 + 0.1 * k} for k in range(8)], duration=2.0)
"""


def _timed(env: dict) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", SWEEP], env=env, check=True)
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2, help="cold/warm pairs (default 2)")
    ap.add_argument("--src", default=None, help="a checkout's src folder to time instead")
    args = ap.parse_args(argv)
    print(f"load average {load_average()}")
    cold, warm = [], []
    for _ in range(args.rounds):
        with tempfile.TemporaryDirectory() as cache:
            env = {**os.environ, "NUMBA_CACHE_DIR": cache}
            if args.src:
                env["PYTHONPATH"] = os.path.abspath(args.src)
            cold.append(_timed(env))
            warm.append(_timed(env))
        print(f"cold {cold[-1]:.1f} s, warm {warm[-1]:.1f} s", flush=True)
    result = {"cold_s": round(min(cold), 1), "cold_median_s": round(statistics.median(cold), 1),
              "warm_s": round(min(warm), 1), "warm_median_s": round(statistics.median(warm), 1)}
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
