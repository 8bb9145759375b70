r"""Sweep benchmark: parameter sets per second, threads, Dask, process pool, serial.

The sweep: 1,000 parameter sets, a 40 x 25 grid of ``friction.coulomb``
(F_C 1.0 ... 2.0) and ``friction.stiction`` (F_S 2.1 ... 2.9) around eq.
(20)'s F_C = 1.5, F_S = 2.3, each a 30 s closed-loop run with the fast design
(eqs. 13-14) and the classical plant friction eq. (17) with the zero-velocity
band 0.03 rad/s of Sec. 5.2, reduced to its limit-cycle features by
:func:`frictionlab.studies.sweep.evaluate` - the code ``frictionlab sweep`` runs.

Figures (sets per second of wall time):

* ``sets_per_s`` - the default backend, the compiled batch evaluator
  (:mod:`frictionlab.studies.batch`) on threads, one per core, each taking the
  next chunk when done
  (``workers=None``);
* ``dask_sets_per_s`` - a Dask ``LocalCluster`` with one single-threaded
  worker process per core (``dask="local"``), each evaluating its chunks with
  the compiled batch on one thread;
* ``per_run_pool_sets_per_s`` - the previous default: a process pool of all
  cores running one Python-driven simulation and feature extraction per set
  (``reduce=reduce_features``, as a custom reduction runs);
* ``serial_sets_per_s`` - the compiled batch on one thread (``workers=1``),
  timed on the first ``--serial-points`` sets (default 200);
* ``ceiling_sets_per_s`` - cores / the CPU time of the simulation alone (one
  30 s run without recording or features, :func:`simulate_config` with
  ``record=False``): the rate if the cores did nothing but simulate;
  ``fraction_of_ceiling`` = ``sets_per_s`` / it;
* ``all_cores_ceiling_sets_per_s`` - the simulation alone measured with every
  core busy: one process per core, each simulating the same 100 sets at once
  (started together at a barrier; best of the passes).  Where the cores share
  caches, memory bandwidth or a host's physical core, a run costs more CPU
  with the other cores computing than alone, and this is the rate the cores
  can reach; ``fraction_of_all_cores_ceiling`` = ``sets_per_s`` / it;
* ``alternated_fraction_of_ceiling`` - the threaded sweep over the ceiling with
  the two timed in alternation, one ratio per round (the simulation alone of
  100 sets in this process, then the threaded sweep): the figures above are
  timed minutes apart, and this virtual machine's speed drifts by 10-30 %
  between minutes and processes.  On a busy machine the
  wall-clock rates fall with the share of the cores the benchmark gets, so
  the CPU times are compared too: ``batch_fraction_simulation`` is the
  simulation alone over the compiled batch on one thread (both timed in
  alternation on the same 100 sets), and ``threads_cpu_ms`` the CPU per set
  of the threaded sweep; ``cores / threads_cpu_ms`` is its rate with the
  cores free.

Besides wall-clock rates it prints the CPU time per set summed over all the
benchmark's processes (main, pool or Dask workers, forkserver, nannies): on a
machine shared with other jobs this shows the engine's own cost, and
``cores / cpu_per_set`` is the rate the backend would reach with the cores free.

The pool and the cluster are started and warmed up (compiled simulator loaded
in every worker) before the timed sweep, as they are in a session that runs
several sweeps (the engine keeps them); their start-up times are printed
separately.  Each timed figure is the best of ``--repeats`` sweeps (default
3; the least disturbed on a shared machine), the medians are printed too.
The backends run one after the other, so on a busy machine compare the
figures of one run of the benchmark.  It also checks that every backend
returns identical rows.  The last printed line is a JSON object.

Usage::

    .venv/bin/python benchmarks/sweep.py [--repeats 3] [--serial-points 200] [--workers N]
"""

from __future__ import annotations

import os

if __name__ == "__main__":  # single-threaded BLAS in every process (inherited by workers);
    # the default backend runs in this process's threads
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[_var] = "1"

import argparse
import json
import math
import statistics
import time

from _measure import cpu_seconds, load_average

from frictionlab.config import Config, build_config
from frictionlab.runs import simulate_config
from frictionlab.studies.sweep import evaluate, make_points, parse_vary, reduce_features, shutdown

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


def _rates(fn, n_sets: int, repeats: int) -> tuple[float, float, float, list]:
    """Best and median sets per second of ``fn()`` over ``repeats`` calls, CPU ms per set
    (all processes, median), and the last rows."""
    times, cpu, rows = [], [], None
    for _ in range(repeats):
        c0, t0 = cpu_seconds(), time.perf_counter()
        rows = fn()
        times.append(time.perf_counter() - t0)
        cpu.append(cpu_seconds() - c0)
    return (n_sets / min(times), n_sets / statistics.median(times),
            1e3 * statistics.median(cpu) / n_sets, rows)


def sim_vs_batch_ms(base: Config, points: list[dict], repeats: int) -> tuple[float, float]:
    """CPU ms per set of the simulation alone (no recording, no features) and of the
    compiled batch on one thread (configurations built, simulation, features, rows),
    measured in alternation on the same ``points`` (best of ``repeats`` passes each),
    so that a busy machine disturbs both alike."""
    cfgs = [base.with_values(p) for p in points]
    sim, bat = math.inf, math.inf
    for _ in range(repeats):
        t0 = time.process_time()
        for cfg in cfgs:
            simulate_config(cfg, DURATION, record=False)
        sim = min(sim, (time.process_time() - t0) / len(cfgs))
        t0 = time.process_time()
        evaluate(base, points, duration=DURATION, workers=1)
        bat = min(bat, (time.process_time() - t0) / len(cfgs))
    return 1e3 * sim, 1e3 * bat


def threads_vs_ceiling(base: Config, points: list[dict], sims: list[dict], cores: int,
                       rounds: int) -> list[float]:
    """The threaded sweep's rate over the ceiling, one ratio per round: each round
    times the simulation alone of ``sims`` in this process (CPU time; the ceiling is
    ``cores`` over it), then the threaded sweep of ``points`` (wall clock), so that
    the machine's speed, which drifts by 10-30 % between minutes and processes on a
    virtual machine, is the same for both figures of a ratio."""
    cfgs = [base.with_values(p) for p in sims]
    ratios = []
    for _ in range(rounds):
        t0 = time.process_time()
        for cfg in cfgs:
            simulate_config(cfg, DURATION, record=False)
        ceiling = cores * len(cfgs) / (time.process_time() - t0)
        t0 = time.perf_counter()
        evaluate(base, points, duration=DURATION, workers=cores)
        ratios.append(len(points) / (time.perf_counter() - t0) / ceiling)
    return ratios


def _sim_worker(base: Config, points: list[dict], barrier, repeats: int) -> list[tuple]:
    """In a process of its own: the simulation alone of every point, ``repeats`` times,
    each pass started at a barrier shared with the other workers; the monotonic start and
    end of each pass (the clock is the same in every process)."""
    cfgs = [base.with_values(p) for p in points]
    simulate_config(cfgs[0], DURATION, record=False)  # load the compiled code
    spans = []
    for _ in range(repeats):
        barrier.wait()
        t0 = time.monotonic()
        for cfg in cfgs:
            simulate_config(cfg, DURATION, record=False)
        spans.append((t0, time.monotonic()))
    return spans


def all_cores_ceiling(base: Config, points: list[dict], cores: int, repeats: int) -> float:
    """Sets per second of wall time when ``cores`` processes do nothing but the
    simulation alone, all at once (best of ``repeats`` passes): the ceiling measured
    with every core busy, where :func:`sim_vs_batch_ms`'s one process has the machine's
    caches and memory bandwidth to itself."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    ctx = mp.get_context("spawn")
    with ctx.Manager() as manager:
        barrier = manager.Barrier(cores)
        with ProcessPoolExecutor(cores, mp_context=ctx) as ex:
            futs = [ex.submit(_sim_worker, base, points, barrier, repeats)
                    for _ in range(cores)]
            spans = [f.result() for f in futs]
    best = min(max(s[r][1] for s in spans) - min(s[r][0] for s in spans)
               for r in range(repeats))
    return cores * len(points) / best


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3, help="timed sweeps per backend (best)")
    ap.add_argument("--serial-points", type=int, default=200,
                    help="sets timed in-process for the serial rate")
    ap.add_argument("--workers", type=int, default=None,
                    help="threads / processes / Dask workers (default: all cores)")
    args = ap.parse_args(argv)

    cores = args.workers or os.cpu_count() or 1
    base = build_config("fast", "classical", sets=list(CLASSICAL_SETS))
    points = sweep_points(base)
    print(f"{N_SETS} sets x {DURATION:g} s, fast design, classical friction, {cores} workers "
          f"(os.cpu_count() = {os.cpu_count()}; load average "
          f"{load_average()})")

    def run(**kw):
        return evaluate(base, points, duration=DURATION, **kw)

    sub = points[:args.serial_points]
    evaluate(base, sub[:2], duration=DURATION, workers=1)  # load the compiled code
    evaluate(base, sub[:4 * cores], duration=DURATION, workers=cores)
    sim_ms, batch_ms = sim_vs_batch_ms(base, sub[:100], 2 * args.repeats)
    ceiling = cores * 1e3 / sim_ms
    print(f"simulation alone: {sim_ms:.2f} ms CPU per set (ceiling {ceiling:.0f} sets/s on "
          f"{cores} cores); the compiled batch on one thread, alternated with it: "
          f"{batch_ms:.2f} ms ({100 * sim_ms / batch_ms:.0f} % simulation)")
    busy_ceiling = all_cores_ceiling(base, sub[:100], cores, 2 * args.repeats)
    print(f"simulation alone on all {cores} cores at once ({cores} processes): "
          f"{busy_ceiling:.0f} sets/s ({100 * busy_ceiling / ceiling:.0f} % of "
          f"{cores} x one process's rate)")
    serial, serial_med, serial_cpu, serial_rows = _rates(
        lambda: evaluate(base, sub, duration=DURATION, workers=1), len(sub), args.repeats)
    print(f"serial (compiled batch, one thread): {serial:.1f} sets/s (median "
          f"{serial_med:.1f}), timed on {len(sub)} sets; CPU {serial_cpu:.2f} ms per set")

    threads, threads_med, threads_cpu, threads_rows = _rates(lambda: run(workers=cores),
                                                             N_SETS, args.repeats)
    print(f"threads (default): {threads:.1f} sets/s (median {threads_med:.1f}), "
          f"{100 * threads / ceiling:.0f} % of the ceiling, {100 * threads / busy_ceiling:.0f} % "
          f"of the all-cores ceiling; CPU {threads_cpu:.2f} ms per set, "
          f"i.e. {cores * 1e3 / threads_cpu:.0f} sets/s if {cores} cores were free")
    print(f"threads vs one thread, CPU per set: {threads_cpu:.2f} / {serial_cpu:.2f} ms "
          f"(x{threads_cpu / serial_cpu:.2f})")
    ratios = threads_vs_ceiling(base, points, sub[:100], cores, 2 * args.repeats)
    print(f"threads / ceiling, the two timed in alternation ({len(ratios)} rounds): median "
          f"{100 * statistics.median(ratios):.0f} %, best {100 * max(ratios):.0f} %, worst "
          f"{100 * min(ratios):.0f} %")

    t0 = time.perf_counter()
    evaluate(base, points[:4 * cores], duration=DURATION, dask="local", workers=cores,
             chunk_size=1)
    print(f"dask LocalCluster start-up and warm-up: {time.perf_counter() - t0:.2f} s")
    dask, dask_med, dask_cpu, dask_rows = _rates(lambda: run(dask="local", workers=cores),
                                                 N_SETS, args.repeats)
    print(f"dask: {dask:.1f} sets/s (median {dask_med:.1f}); {dask / threads:.2f} x the "
          f"threads; CPU {dask_cpu:.2f} ms per set, i.e. {cores * 1e3 / dask_cpu:.0f} sets/s "
          f"if {cores} cores were free")
    shutdown()

    t0 = time.perf_counter()
    evaluate(base, points[:4 * cores], duration=DURATION, workers=cores, chunk_size=1,
             reduce=reduce_features)
    print(f"per-run process pool start-up and warm-up: {time.perf_counter() - t0:.2f} s")
    pool, pool_med, pool_cpu, pool_rows = _rates(
        lambda: run(workers=cores, reduce=reduce_features), N_SETS, args.repeats)
    print(f"per-run process pool (previous default): {pool:.1f} sets/s (median "
          f"{pool_med:.1f}); CPU {pool_cpu:.2f} ms per set")
    shutdown()

    identical = (threads_rows == dask_rows == pool_rows
                 and threads_rows[:len(sub)] == serial_rows)
    statuses = {s: sum(r["status"] == s for r in threads_rows)
                for s in sorted({r["status"] for r in threads_rows})}
    print(f"rows identical across backends: {identical}; statuses: {statuses}")
    result = {"sets_per_s": round(threads, 1), "dask_sets_per_s": round(dask, 1),
              "dask_vs_threads": round(dask / threads, 3),
              "per_run_pool_sets_per_s": round(pool, 1),
              "serial_sets_per_s": round(serial, 1), "sim_only_ms": round(sim_ms, 3),
              "batch_one_thread_ms": round(batch_ms, 3),
              "batch_fraction_simulation": round(sim_ms / batch_ms, 3),
              "threads_cpu_ms": round(threads_cpu, 3),
              "ceiling_sets_per_s": round(ceiling, 1),
              "fraction_of_ceiling": round(threads / ceiling, 3),
              "all_cores_ceiling_sets_per_s": round(busy_ceiling, 1),
              "fraction_of_all_cores_ceiling": round(threads / busy_ceiling, 3),
              "alternated_fraction_of_ceiling": [round(r, 3) for r in ratios],
              "identical": identical}
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
