r"""Sweep benchmark: parameter sets per second, serial, process pool and Dask LocalCluster.

The sweep: 1,000 parameter sets, a 40 x 25 grid of ``friction.coulomb``
(F_C 1.0 ... 2.0) and ``friction.stiction`` (F_S 2.1 ... 2.9) around eq.
(20)'s F_C = 1.5, F_S = 2.3, each a 30 s closed-loop run with the fast design
(eqs. 13-14) and the classical plant friction eq. (17) with the zero-velocity
band 0.03 rad/s of Sec. 5.2, reduced to its limit-cycle features by
:func:`frictionlab.sweep.evaluate` - the code ``frictionlab sweep`` runs.

Figures (sets per second of wall time):

* ``pool_sets_per_s`` - the local process pool on all cores
  (``workers=None``, i.e. ``os.cpu_count()`` processes);
* ``dask_sets_per_s`` - a Dask ``LocalCluster`` with one single-threaded
  worker process per core (``dask="local"``);
* ``serial_sets_per_s`` - in-process (``workers=1``), timed on the first
  ``--serial-points`` sets (default 200) and reported as a rate; the rate of a
  serial sweep does not depend on its length, so it extrapolates to 1,000.

Besides wall-clock rates it prints the CPU time per set summed over all the
benchmark's processes (main, pool or Dask workers, forkserver, nannies): on a
machine shared with other jobs this shows the engine's own cost, and
``cores / cpu_per_set`` is the rate the backend would reach with the cores free.

The pool and the cluster are started and warmed up (compiled simulator loaded
in every worker) before the timed sweep, as they are in a session that runs
several sweeps (identification, tuning; the engine keeps them); their start-up
times are printed separately.  Each timed figure is the best of ``--repeats``
sweeps (default 3; the least disturbed on a shared machine), the medians are
printed too.  The benchmark also checks that the three backends return
identical rows.  The last printed line is a JSON object.

Usage::

    .venv/bin/python benchmarks/sweep.py [--repeats 3] [--serial-points 200]
"""

from __future__ import annotations

import os

if __name__ == "__main__":  # single-threaded numerics in every process (inherited by workers)
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                 "NUMBA_NUM_THREADS"):
        os.environ[_var] = "1"

import argparse
import json
import statistics
import time

import psutil

from frictionlab.config import Config, build_config
from frictionlab.sweep import evaluate, make_points, parse_vary, shutdown

DURATION = 30.0
N_SETS = 1000
VARY = ("friction.coulomb=1.0:2.0:40", "friction.stiction=2.1:2.9:25")
#: Sec. 5.2: the band the thesis widened to 0.03 rad/s to see stiction.
CLASSICAL_SETS = ("friction.zero_velocity_band=0.03",)


def sweep_points(base: Config) -> list[dict]:
    """The 1,000 parameter sets (40 x 25 grid of F_C and F_S)."""
    points = make_points(base, [parse_vary(v) for v in VARY], "grid")
    assert len(points) == N_SETS
    return points


def _cpu_seconds() -> float:
    """CPU time (user + system) of this process and all its live descendants."""
    me = psutil.Process()
    total = 0.0
    for p in [me, *me.children(recursive=True)]:
        try:
            t = p.cpu_times()
        except psutil.NoSuchProcess:
            continue
        total += t.user + t.system
    return total


def _rates(fn, n_sets: int, repeats: int) -> tuple[float, float, float, list]:
    """Best and median sets per second of ``fn()`` over ``repeats`` calls, CPU ms per set
    (all processes, median), and the last rows."""
    times, cpu, rows = [], [], None
    for _ in range(repeats):
        c0, t0 = _cpu_seconds(), time.perf_counter()
        rows = fn()
        times.append(time.perf_counter() - t0)
        cpu.append(_cpu_seconds() - c0)
    return (n_sets / min(times), n_sets / statistics.median(times),
            1e3 * statistics.median(cpu) / n_sets, rows)


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3, help="timed sweeps per backend (best)")
    ap.add_argument("--serial-points", type=int, default=200,
                    help="sets timed in-process for the serial rate")
    ap.add_argument("--workers", type=int, default=None,
                    help="processes / Dask workers (default: all cores)")
    args = ap.parse_args(argv)

    cores = args.workers or os.cpu_count() or 1
    base = build_config("fast", "classical", sets=list(CLASSICAL_SETS))
    points = sweep_points(base)
    print(f"{N_SETS} sets x {DURATION:g} s, fast design, classical friction, {cores} workers "
          f"(os.cpu_count() = {os.cpu_count()})")

    def run(**kw):
        return evaluate(base, points, duration=DURATION, **kw)

    sub = points[:args.serial_points]
    evaluate(base, sub[:2], duration=DURATION, workers=1)  # load the compiled code
    serial, serial_med, serial_cpu, serial_rows = _rates(
        lambda: evaluate(base, sub, duration=DURATION, workers=1), len(sub), args.repeats)
    print(f"serial: {serial:.1f} sets/s (median {serial_med:.1f}), timed on {len(sub)} sets "
          f"({1e3 / serial:.2f} ms per set; CPU {serial_cpu:.2f} ms per set)")

    t0 = time.perf_counter()
    evaluate(base, points[:4 * cores], duration=DURATION, workers=cores, chunk_size=1)
    print(f"pool start-up and warm-up: {time.perf_counter() - t0:.2f} s")
    pool, pool_med, pool_cpu, pool_rows = _rates(lambda: run(workers=cores), N_SETS,
                                                 args.repeats)
    print(f"pool: {pool:.1f} sets/s (median {pool_med:.1f}); CPU {pool_cpu:.2f} ms per set, "
          f"i.e. {cores * 1e3 / pool_cpu:.0f} sets/s if {cores} cores were free")
    shutdown()

    t0 = time.perf_counter()
    evaluate(base, points[:4 * cores], duration=DURATION, dask="local", workers=cores,
             chunk_size=1)
    print(f"dask LocalCluster start-up and warm-up: {time.perf_counter() - t0:.2f} s")
    dask, dask_med, dask_cpu, dask_rows = _rates(lambda: run(dask="local", workers=cores),
                                                 N_SETS, args.repeats)
    print(f"dask: {dask:.1f} sets/s (median {dask_med:.1f}); {dask / pool:.2f} x the pool; "
          f"CPU {dask_cpu:.2f} ms per set, i.e. {cores * 1e3 / dask_cpu:.0f} sets/s if "
          f"{cores} cores were free")
    shutdown()

    identical = pool_rows == dask_rows and pool_rows[:len(sub)] == serial_rows
    statuses = {s: sum(r["status"] == s for r in pool_rows)
                for s in sorted({r["status"] for r in pool_rows})}
    print(f"rows identical across backends: {identical}; statuses: {statuses}")
    result = {"pool_sets_per_s": round(pool, 1), "dask_sets_per_s": round(dask, 1),
              "serial_sets_per_s": round(serial, 1)}
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
