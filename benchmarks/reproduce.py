r"""``frictionlab reproduce`` benchmark: the whole thesis report, end to end.

Measures:

* ``wall_s`` - the command ``frictionlab reproduce --out DIR --json`` as a user
  runs it: a fresh process (interpreter start, imports, numba's on-disk cache,
  the runs through the sweep engine, the figures, the report), minimum over
  ``--repeats`` (median printed alongside); target under 20 s on the project's
  2-core machine;
* ``seconds`` - the time the command itself reports (from parsing its
  arguments to the last file written), for the fastest run;
* ``runs_s`` and ``report_s`` - in this process, after a warm-up:
  :func:`frictionlab.studies.reproduce.run` (every closed-loop run) and
  :func:`frictionlab.studies.reproduce.write_report` (report and figures), minimum over
  the repeats;
* each of the above with ``--workers 2`` (the local pool) as well as the
  default (the engine's choice, in-process for a job this small).

The machine's load average is printed before and after (other jobs on a
shared machine slow every figure down).  The last printed line is a JSON object.

Usage::

    .venv/bin/python benchmarks/reproduce.py [--repeats 3]
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
from pathlib import Path

TARGET_S = 20.0


def _cli() -> list[str]:
    exe = Path(sys.executable).with_name("frictionlab")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "frictionlab"]


def command_times(repeats: int, extra: list[str]) -> tuple[float, float, float]:
    """(min wall, median wall, command-reported seconds of the fastest) over ``repeats``."""
    walls, reported = [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            proc = subprocess.run([*_cli(), "reproduce", "--out", tmp, "--json",
                                   "--no-progress", *extra],
                                  capture_output=True, text=True, check=True)
            walls.append(time.perf_counter() - t0)
            reported.append(json.loads(proc.stdout)["seconds"])
    best = min(range(repeats), key=walls.__getitem__)
    return walls[best], statistics.median(walls), reported[best]


def inprocess_times(repeats: int, workers: int | None) -> tuple[float, float]:
    """(min of run(), min of write_report()) after a warm-up, in this process."""
    from frictionlab.studies.reproduce import run, write_report

    run(workers)  # warm-up: the numba cache, a pool's start-up
    runs, reports = [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            results = run(workers)
            t1 = time.perf_counter()
            write_report(results, tmp, t1 - t0)
            runs.append(t1 - t0)
            reports.append(time.perf_counter() - t1)
    return min(runs), min(reports)


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    load0 = os.getloadavg()
    print(f"load average before: {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f} "
          f"({os.cpu_count()} cores)")
    result: dict = {}
    for label, extra, workers in (("default", [], None), ("workers2", ["--workers", "2"], 2)):
        wall, wall_med, reported = command_times(args.repeats, extra)
        runs_s, report_s = inprocess_times(args.repeats, workers)
        print(f"{label}: frictionlab reproduce {' '.join(extra)}: wall {wall:.2f} s "
              f"(median {wall_med:.2f}) of which the command reports {reported:.2f} s; "
              f"in-process: runs {runs_s:.2f} s, report and figures {report_s:.2f} s "
              f"(target: wall < {TARGET_S:g} s)")
        suffix = "" if label == "default" else f"_{label}"
        result.update({f"wall_s{suffix}": round(wall, 2), f"seconds{suffix}": reported,
                       f"runs_s{suffix}": round(runs_s, 3),
                       f"report_s{suffix}": round(report_s, 3)})
    load1 = os.getloadavg()
    print(f"load average after: {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}")
    result["load_before"] = round(load0[0], 2)
    result["load_after"] = round(load1[0], 2)
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
