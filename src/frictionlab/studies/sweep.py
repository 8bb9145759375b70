r"""Parameter sweeps: many closed-loop runs, each reduced to its limit-cycle features.

Sections 5.2-5.3 of the thesis vary one friction parameter at a time (Tables
2-3: F_C, then F_S, for the fast design and the classical model; Appendix F:
the seven LuGre parameters around the defaults of eq. (21)) and note the
limit cycle's peaks, period, max(u) and max arm velocity for each setting.
This module does that for any parameter keys, on one core, all local cores,
or a Dask cluster.  It is the engine only: the command line (``frictionlab
sweep``, its table and plot) is :mod:`frictionlab.cli.sweep`, which imports
this module, never the reverse.

Engine
------
:func:`evaluate` maps a list of points (``{key: value}`` dicts applied to a
base :class:`~frictionlab.config.Config`) to result rows, in order.  The unit
of work is one closed-loop run reduced to a row: by default
:func:`reduce_features` (:func:`frictionlab.model.simulation.run_features`); a
caller that needs more of each run than its features (compensation tuning:
the control chatter) passes its own ``reduce``, which runs in the workers
beside the simulation so that only the row travels back.  Points are shipped
in chunks (by default at most 50 points and a quarter of a worker's share,
shrinking towards the end so the workers finish together) so that the
compiled simulator, not task scheduling, dominates.  A point whose
configuration is invalid or whose simulation (or reduction) raises becomes a
row with status ``"error"`` and an ``error`` message; a worker that dies
turns its chunk into such rows.  A sweep never crashes because of one point.

Backends (chosen by :func:`evaluate`'s ``workers``, ``dask`` and ``reduce``):

* threads, the default for the default reduction (features): ``workers``
  threads in this process (``None``: one per core), each taking the next
  chunk of points (at most :data:`THREAD_CHUNK`, shrinking towards the end)
  and running it through the compiled batch evaluator
  :mod:`frictionlab.studies.batch` with the GIL released: simulation and
  feature extraction compiled, no Python per run and no process start-up;
* in-process, for a custom ``reduce`` (``workers=1``, or ``workers=None``
  for a sweep of under about half a second of serial work);
* a local process pool, for a custom ``reduce`` (``workers=N``; ``None``:
  all cores).  Workers fork
  from a ``forkserver`` that has imported the package and loaded the
  numba-compiled simulator (from its on-disk cache) once; the pool is kept for
  the life of the process so repeated calls (identification, tuning) pay the
  start-up once.  :func:`shutdown` closes it (also at exit);
* Dask distributed: ``dask="local"`` starts a ``LocalCluster`` (one
  single-threaded worker process per core, or ``workers``; settings in
  :func:`_local_dask_config`), ``dask="tcp://HOST:PORT"`` connects to a
  running scheduler whose workers have ``frictionlab`` installed.  Clients
  are kept like the pool.  Each worker evaluates its chunk with the compiled
  batch evaluator on one thread (or with ``reduce``).

Output files
------------
:class:`SweepFile` writes rows as chunks complete (CSV, flushed and fsynced per
chunk), reads them back for ``--resume``, and at the end rewrites the file in
sweep order (atomically).  Columns: the varied keys, the seven features of
:data:`frictionlab.model.limit_cycles.FEATURES`, ``status``, ``error`` (a
``reduce``'s extra columns are not written, except the swing-up sweep's
``caught`` and ``catch_time``).  A
``.parquet`` output is written at the end from all rows; while the sweep runs
the rows go to the crash-safe CSV journal ``FILE.parquet.partial.csv``.
A sidecar ``FILE.meta.json`` records the base configuration, duration and
window, so that ``--resume`` refuses to mix results of different set-ups.
"""

from __future__ import annotations

import atexit
import csv
import io
import json
import math
import os
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import closing, contextmanager
from pathlib import Path
from typing import Any

from ..config import Config, ConfigError, ConfigValueError, UnknownKeyError, valid_keys
from ..model.limit_cycles import FEATURES

__all__ = [
    "MODES",
    "STATUSES",
    "OutputMismatch",
    "SweepFile",
    "auto_workers",
    "evaluate",
    "iter_evaluate",
    "make_points",
    "parse_vary",
    "reduce_features",
    "shutdown",
    "validate_points",
]

#: Sweep modes: Cartesian product of the value lists, or one key at a time.
MODES = ("grid", "oat")
#: Row statuses: the three of ``frictionlab simulate`` plus ``error``.
STATUSES = ("limit_cycle", "settled", "fell", "not_caught", "error")
#: The extra columns of a swing-up sweep (:func:`reduce_swingup`).
SWINGUP_COLUMNS = ("caught", "catch_time")

#: Largest number of points per task.
MAX_CHUNK = 50
#: Smallest task of the shrinking tail of a sweep (default chunking).
MIN_TAIL_CHUNK = 4
#: ``workers=None`` runs a sweep in-process when its serial work (points x ticks
#: x substeps) is below this (about half a second of simulation).
TINY_WORK = 5_000_000
#: Most parameter sets in one sweep (and values of one key): the points and
#: their rows are held in memory (about 1 kB a set), so a typing slip such as
#: ``1:2:100000000`` is refused at once instead of exhausting memory; a larger
#: study is several sweeps.
MAX_POINTS = 100_000


# ---------------------------------------------------------------------------
# sweep specification
# ---------------------------------------------------------------------------


#: What a varied key's values may be (the ``allowed`` of a refused one).
VARY_FORMS = "KEY=V1,V2,... or KEY=START:STOP:N"


def _vary_error(value: Any, message: str) -> ConfigValueError:
    """A refused varied key: field ``vary`` (the command line's ``--vary``)."""
    return ConfigValueError("vary", value, VARY_FORMS, message)


def _number(key: str, text: str) -> float:
    t = text.strip()
    if not t:
        raise _vary_error(key, f"{key}: empty value in the list")
    try:
        v = float(t)
    except ValueError:
        raise _vary_error(key, f"{key}: {t!r} is not a number") from None
    if not math.isfinite(v):
        raise _vary_error(key, f"{key}: {t!r} is not a finite number")
    return v


def _tidy(v: float) -> float:
    """Round a computed grid value to 12 significant digits (1.7, not 1.7000000000000002)."""
    return float(f"{v:.12g}")


def parse_vary(text: str, plant: str = "thesis") -> tuple[str, list[float]]:
    """Parse ``KEY=V1,V2,...`` or ``KEY=START:STOP:N`` (N evenly spaced values),
    KEY a key of the plant ``plant`` (a ``--plant`` name).

    ``START:STOP:N`` includes both ends (``N = 1`` gives ``START``); its
    values are rounded to 12 significant digits.

    Raises
    ------
    ConfigError
        Unknown key, empty list, non-numeric value, bad N (at most
        :data:`MAX_POINTS`), duplicate value.
    """
    if "=" not in text:
        raise _vary_error(text, f"expected {VARY_FORMS}, got {text!r}")
    key, spec = (s.strip() for s in text.split("=", 1))
    if key not in valid_keys(plant):
        raise UnknownKeyError(key, field="vary", plant=plant)
    if not spec:
        raise _vary_error(key, f"{key}: empty list of values")
    if ":" in spec:
        parts = spec.split(":")
        if len(parts) != 3:
            raise _vary_error(key, f"{key}: a range is START:STOP:N, got {spec!r}")
        start, stop = _number(key, parts[0]), _number(key, parts[1])
        try:
            n = int(parts[2].strip())
        except ValueError:
            raise _vary_error(key, f"{key}: N in START:STOP:N must be an integer >= 1, "
                                   f"got {parts[2]!r}") from None
        if n < 1:
            raise _vary_error(key, f"{key}: N in START:STOP:N must be >= 1, got {n}")
        if n > MAX_POINTS:
            raise _vary_error(key, f"{key}: N in START:STOP:N must be <= {MAX_POINTS}, "
                              f"got {n}")
        if n == 1:
            values = [start]
        else:
            values = [_tidy(start + (stop - start) * i / (n - 1)) for i in range(n)]
    else:
        values = [_number(key, t) for t in spec.split(",")]
    seen = set()
    for v in values:
        if v in seen:
            raise _vary_error(key, f"{key}: value {v:g} appears twice")
        seen.add(v)
    return key, values


def _as_key_type(base: Config, key: str, value: Any) -> Any:
    """Integer-valued keys (``sim.seed``, ``sim.substeps``) keep integer values."""
    if isinstance(value, float) and value.is_integer():
        current = base.get(key)
        if isinstance(current, int) and not isinstance(current, bool):
            return int(value)
    return value


def make_points(base: Config, varies: Sequence[tuple[str, Sequence[float]]],
                mode: str = "grid") -> list[dict[str, Any]]:
    """The parameter sets of a sweep.

    Parameters
    ----------
    base : Config
        The configuration every point modifies.
    varies : sequence of (key, values)
        As returned by :func:`parse_vary`, in the order given.
    mode : {"grid", "oat"}
        ``grid``: the Cartesian product (the last key varies fastest).
        ``oat``: one key at a time, the others at their base values, as in
        the thesis's Tables 2-3 and Appendix F; a point that occurs for two
        keys (both at their base values) is run once.

    Returns
    -------
    list of dict
        Each point gives a value for every varied key.
    """
    if mode not in MODES:
        raise ConfigValueError("mode", mode, ", ".join(MODES),
                               f"must be one of {', '.join(MODES)}; got {mode!r}")
    if not varies:
        raise _vary_error(None, "a sweep needs at least one varied key (KEY=VALUES)")
    keys = [k for k, _ in varies]
    for k in keys:
        if keys.count(k) > 1:
            raise _vary_error(k, f"{k} given more than once")
    for k, values in varies:
        if not values:
            raise _vary_error(k, f"{k}: empty list of values")
    sizes = [len(values) for _, values in varies]
    total = math.prod(sizes) if mode == "grid" else sum(sizes)
    if total > MAX_POINTS:
        raise ConfigError(f"the sweep has {total} parameter sets ({' x '.join(map(str, sizes))}"
                          f"{'' if mode == 'grid' else ', one key at a time'}); at most "
                          f"{MAX_POINTS} fit in one sweep: split it into several")
    if mode == "grid":
        points: list[dict[str, Any]] = [{}]
        for k, values in varies:
            points = [{**p, k: _as_key_type(base, k, v)} for p in points for v in values]
        return points
    base_vals = {k: base.get(k) for k in keys}
    out, seen = [], set()
    for k, values in varies:
        for v in values:
            p = {**base_vals, k: _as_key_type(base, k, v)}
            ident = _ident(p, keys)
            if ident not in seen:
                seen.add(ident)
                out.append(p)
    return out


def validate_points(base: Config, points: Sequence[Mapping[str, Any]]) -> None:
    """Build every point's configuration; raise :class:`ConfigError` at the first bad one."""
    for p in points:
        try:
            base.with_values(p)
        except ValueError as exc:
            raise ConfigError(f"sweep point {_describe(p)}: {exc}") from None


def _describe(p: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={v!r}" for k, v in p.items())


def _ident(p: Mapping[str, Any], keys: Sequence[str]) -> tuple:
    """Identity of a point for resume: its varied values as floats (None kept)."""
    return tuple(None if p.get(k) is None else float(p[k]) for k in keys)


# ---------------------------------------------------------------------------
# the unit of work (runs in workers)
# ---------------------------------------------------------------------------


def _clean(v: Any) -> float | None:
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def _error_row(point: Mapping[str, Any], message: str) -> dict[str, Any]:
    row: dict[str, Any] = dict(point)
    row.update({name: None for name in FEATURES})
    row["status"] = "error"
    row["error"] = message
    return row


#: A reduction: ``reduce(cfg, duration, window) -> {"status": ..., feature: ..., ...}``.
Reduce = Callable[[Config, float | None, float | None], Mapping[str, Any]]


def reduce_features(cfg: Config, duration: float | None,
                    window: float | None) -> dict[str, Any]:
    """The default reduction of a run: its status and limit-cycle features.

    Parameters
    ----------
    cfg : Config
        The point's configuration.
    duration, window : float or None
        As for :func:`frictionlab.model.simulation.run_features`.

    Returns
    -------
    dict
        The seven features of :data:`~frictionlab.model.limit_cycles.FEATURES`
        (``None`` where undefined) and ``status`` (``limit_cycle``,
        ``settled`` or ``fell``).
    """
    from ..runs import run_features

    feats = run_features(cfg, duration, window)
    out: dict[str, Any] = {name: getattr(feats, name) for name in FEATURES}
    out["status"] = feats.status
    return out


def reduce_swingup(cfg: Config, duration: float | None,
                   window: float | None) -> dict[str, Any]:
    """The reduction of a swing-up run (``sweep --swing-up``).

    Returns the features and status of
    :func:`frictionlab.studies.swingup_sim.swingup_outcome` (``not_caught`` when it
    never reached the balancing phase) and ``caught`` (1 when it did, else 0)
    and ``catch_time`` (s, the catch that led to balancing; ``None`` if none).
    """
    from .swingup_sim import simulate_swingup, swingup_outcome

    res = simulate_swingup(cfg, duration)
    status, feats = swingup_outcome(res, window)
    out: dict[str, Any] = {name: getattr(feats, name) for name in FEATURES}
    out["status"] = status
    out["caught"] = int(res.balanced)
    out["catch_time"] = res.swing_up_time
    return out


def _row(point: Mapping[str, Any], result: Any) -> dict[str, Any]:
    """A point's row from its reduction: the point, the features, status, error, extras."""
    if not isinstance(result, Mapping):
        raise TypeError(f"reduce returned {type(result).__name__}, not a mapping")
    missing = [k for k in ("status", *FEATURES) if k not in result]
    if missing:
        raise ValueError(f"reduce returned no {', '.join(missing)}")
    if result["status"] not in STATUSES[:-1]:
        raise ValueError(f"reduce returned status {result['status']!r}; expected one of "
                         f"{', '.join(STATUSES[:-1])}")
    row: dict[str, Any] = dict(point)
    row.update({name: _clean(result[name]) for name in FEATURES})
    row["status"] = result["status"]
    row["error"] = None
    for k, v in result.items():
        if k in FEATURES or k == "status":
            continue
        if k in row:
            raise ValueError(f"reduce returned a column {k!r}, which the row has already")
        row[k] = v
    return row


def _run_chunk(base: Config, points: Sequence[Mapping[str, Any]], duration: float | None,
               window: float | None, reduce: Reduce | None = None) -> list[dict[str, Any]]:
    """Evaluate a chunk of points (executed in a worker process, or in-process).

    Each point's configuration is run and reduced by ``reduce`` (default:
    :func:`reduce_features`'s rows, computed by the compiled batch evaluator
    :func:`frictionlab.studies.batch.evaluate_rows` on one thread); a point whose
    configuration is invalid, or whose run or reduction raises, is an error row.
    """
    if reduce is None:
        # the default reduction, every point in one compiled batch (no Python per run)
        from .batch import evaluate_rows

        return evaluate_rows(base, points, duration, window)
    rows = []
    for p in points:
        try:
            rows.append(_row(p, reduce(base.with_values(p), duration, window)))
        except Exception as exc:
            rows.append(_error_row(p, f"{type(exc).__name__}: {exc}"))
    return rows


def _check_reduce(reduce: Any) -> None:
    """A ``reduce`` must reach the workers by reference: a picklable top-level function."""
    import pickle

    if not callable(reduce):
        raise TypeError(f"reduce must be a function, got {type(reduce).__name__}")
    try:
        pickle.dumps(reduce)
    except Exception as exc:
        raise TypeError(f"reduce must be a picklable top-level function (it runs in worker "
                        f"processes); {reduce!r} is not: {exc}") from None


def _warm_up() -> None:
    """Load the compiled simulator and batch evaluator once (from numba's on-disk cache)."""
    from ..config import build_config
    from ..runs import run_features
    from .batch import evaluate_rows

    run_features(build_config(), 2.0)
    evaluate_rows(build_config(), [{}], 2.0, None)


#: Set only in the environment of the forkserver this module starts: importing
#: the module there (a preload) also loads the compiled simulator, so that pool
#: workers fork with it in memory instead of each loading (or compiling) it.
_FORKSERVER_WARM_ENV = "FRICTIONLAB_SWEEP_FORKSERVER_WARM"


def _exit_with(parent) -> None:
    parent.join()  # returns when the parent's end of the pipe closes
    os._exit(1)


def _pool_worker_init() -> None:
    """Pool worker start-up: warm the simulator, and exit when the sweep's process dies.

    A worker whose parent disappears without shutting the pool down (e.g. it
    was killed with SIGKILL) exits at once instead of lingering.
    """
    import multiprocessing

    _warm_up()
    parent = multiprocessing.parent_process()
    if parent is not None:
        threading.Thread(target=_exit_with, args=(parent,), daemon=True).start()


# ---------------------------------------------------------------------------
# backends
# ---------------------------------------------------------------------------

_lock = threading.Lock()
_pools: dict[int, Any] = {}
_dask: dict[tuple, tuple[Any, Any]] = {}


def _get_pool(workers: int):
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with _lock:
        ex = _pools.get(workers)
        if ex is None:
            from multiprocessing import forkserver

            ctx = multiprocessing.get_context("forkserver")
            # the forkserver imports and warms the simulator once; workers fork from it
            ctx.set_forkserver_preload(["frictionlab.studies.sweep"])
            os.environ[_FORKSERVER_WARM_ENV] = "1"
            try:
                forkserver.ensure_running()
            finally:
                del os.environ[_FORKSERVER_WARM_ENV]
            ex = ProcessPoolExecutor(workers, mp_context=ctx, initializer=_pool_worker_init)
            _pools[workers] = ex
        return ex


@contextmanager
def _interrupts_deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM while a process pool starts and takes its tasks.

    A worker that forks from the forkserver unpickles its pool's queues
    after its parent has moved on; a parent interrupted in that window (in
    the middle of ``submit``, before the pool's manager thread exists)
    exits without waiting for the worker and unlinks the queues' semaphores,
    and the worker prints a ``SemLock`` traceback.  Held here, the signal is
    delivered once the pool is complete, so that :func:`shutdown` at exit
    waits for the workers.  Outside the main thread (where handlers cannot
    be set) this does nothing.
    """
    import signal

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []
    previous = {s: signal.signal(s, lambda signum, frame: held.append(signum))
                for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        if held:
            handler = previous[held[0]]
            if callable(handler):
                handler(held[0], None)
            elif handler == signal.SIG_DFL:
                os.kill(os.getpid(), held[0])


def _drop_pool(workers: int, ex) -> None:
    with _lock:
        if _pools.get(workers) is ex:
            del _pools[workers]
    ex.shutdown(wait=False, cancel_futures=True)


def _local_dask_config() -> dict[str, Any]:
    """Dask settings for the workers of a ``LocalCluster`` started by a sweep.

    * No ``MALLOC_TRIM_THRESHOLD_`` (Dask's default sets it): fixing a malloc
      threshold turns off glibc's adaptive mmap threshold, so every run's
      trajectory buffer (about 0.8 MB for 30 s) is mmapped and page-faulted
      afresh - measured at about 20% of a 30 s run's CPU time.
    * No statistical profiler (a thread sampling every 10 ms contends for the
      GIL with the task, which holds it during the compiled simulation).
    * No work stealing: the tasks are equal chunks, and the scheduler (in this
      process) would re-balance them every 100 ms on the cores the workers need.
    * Event-loop health ticks every 1 s instead of 20 ms and system monitoring
      every 2 s instead of 0.5 s: with the scheduler and the nannies in this
      process, the defaults cost about 7% of a core while the cluster is idle
      (2% with these).
    """
    import dask

    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}) or {})
    environ.pop("MALLOC_TRIM_THRESHOLD_", None)
    return {"distributed.nanny.pre-spawn-environ": environ,
            "distributed.worker.profile.enabled": False,
            "distributed.scheduler.work-stealing": False,
            "distributed.admin.tick.interval": "1s",
            "distributed.admin.system-monitor.interval": "2s"}


def _get_dask(address: str, workers: int | None):
    """A cached ``distributed.Client`` for ``"local"`` or ``"tcp://HOST:PORT"``."""
    import logging

    import dask
    from distributed import Client, LocalCluster

    n = workers or os.cpu_count() or 1
    key = ("local", n) if address == "local" else (address,)
    with _lock:
        hit = _dask.get(key)
        if hit is not None and hit[0].status == "running":
            return hit[0]
        if address == "local":
            with dask.config.set(_local_dask_config()):
                # no dashboard; the scheduler's own HTTP server (health routes) on a
                # port the kernel picks, not the default 8787 that another cluster on
                # the machine may hold
                cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                       dashboard_address=None, host="127.0.0.1",
                                       silence_logs=logging.ERROR,
                                       scheduler_kwargs={"dashboard": False,
                                                         "dashboard_address": "127.0.0.1:0"})
            try:
                client = Client(cluster, timeout="60s")
            except BaseException:
                cluster.close()
                raise
        else:
            cluster = None
            try:
                client = Client(address, timeout="30s")
            except OSError as exc:
                raise ConfigValueError("dask", address, DASK_FORMS,
                                       f"{address}: cannot connect to the scheduler "
                                       f"({exc})") from None
        try:
            client.run(_warm_up)
        except BaseException:
            client.close()
            if cluster is not None:
                cluster.close()
            raise
        _dask[key] = (client, cluster)
        return client


def shutdown() -> None:
    """Close the cached process pools and Dask clients/clusters (also run at exit)."""
    with _lock:
        pools, clients = list(_pools.values()), list(_dask.values())
        _pools.clear()
        _dask.clear()
    for ex in pools:
        ex.shutdown(wait=True, cancel_futures=True)
    for client, cluster in clients:
        try:
            client.close(timeout=10)
        finally:
            if cluster is not None:
                cluster.close(timeout=10)


atexit.register(shutdown)

if os.environ.pop(_FORKSERVER_WARM_ENV, None) == "1":  # this is the pool's forkserver
    try:
        _warm_up()
    except Exception:  # the workers then warm up themselves
        pass


#: What a Dask address may be (the ``allowed`` of a refused one, field ``dask``).
DASK_FORMS = "'local' or tcp://HOST:PORT"


def _check_dask_address(dask: str) -> None:
    if dask != "local" and not (dask.startswith("tcp://") and ":" in dask[len("tcp://"):]):
        raise ConfigValueError("dask", dask, DASK_FORMS, f"must be {DASK_FORMS}, got {dask!r}")


def _serial_work(base: Config, n_points: int, duration: float | None) -> float:
    d = base.sim.duration if duration is None else duration
    return n_points * (d / base.design.h) * base.substeps


def auto_workers(base: Config, n_points: int, duration: float | None = None) -> int:
    """Local processes for ``n_points`` runs of ``base`` when none are requested.

    All cores, unless the serial work (points x ticks x substeps) is below
    :data:`TINY_WORK` (about half a second), which is not worth a process
    pool's start-up, or there is one core: then 1 (in-process).  A caller
    that evaluates many small batches (identification: one batch per
    generation) passes its whole job's points, because the pool is started
    once per process and kept.

    Parameters
    ----------
    base : Config
        Configuration of the runs (its sampling period and substeps).
    n_points : int
        Number of runs.
    duration : float, optional
        Simulated seconds per run (default ``base.sim.duration``).

    Returns
    -------
    int
        The number of workers to pass as ``workers``.
    """
    cpus = os.cpu_count() or 1
    if cpus == 1 or _serial_work(base, n_points, duration) < TINY_WORK:
        return 1
    return cpus


def _chunks(n: int, size: int) -> list[range]:
    return [range(i, min(i + size, n)) for i in range(0, n, size)]


def _guided_chunks(n: int, workers: int, max_chunk: int = MAX_CHUNK) -> list[range]:
    """Chunks of at most ``max_chunk`` and ``ceil(n / (4 workers))`` points,
    shrinking towards the end of the sweep (to ``remaining / (2 workers)``, not
    below :data:`MIN_TAIL_CHUNK`) so that the workers finish together."""
    size = max(1, min(max_chunk, math.ceil(n / (4 * workers))))
    out, i = [], 0
    while i < n:
        rest = n - i
        m = min(size, max(MIN_TAIL_CHUNK, math.ceil(rest / (2 * workers))), rest)
        out.append(range(i, i + m))
        i += m
    return out


#: Largest Dask chunk of the default reduction (one compiled batch per chunk).
DASK_BATCH_CHUNK = 250
#: Largest chunk of the thread backend (one compiled batch; the rows are written
#: and progress reported per chunk).
THREAD_CHUNK = 32


def _thread_chunks(base: Config, pts: list[dict[str, Any]], duration: float | None,
                   window: float | None, threads: int,
                   chunks: list[range]) -> Iterator[tuple[list[int], list[dict[str, Any]]]]:
    """The thread backend: ``threads`` threads, each taking the next chunk as soon as
    it is done with one and running it as one compiled batch, the GIL released.

    Each thread also packs its chunk and makes its rows (Python, about 5 % of the
    work), so no thread waits for another, and the cores compute while the caller
    takes the rows.  With the chunks shrinking towards the end, the threads finish
    together.  (Dealing every batch's sets to numba's threads in fixed turns, as
    before, left the cores about 88 % busy: each batch ended when its slower thread
    did; measured in docs/performance.md.)  Chunks are yielded as they complete;
    closing the generator early cancels those not yet started and waits for the
    running ones.
    """
    from concurrent.futures import ThreadPoolExecutor, as_completed

    from . import batch

    def one(idx: range) -> list[dict[str, Any]]:
        sub = [pts[i] for i in idx]
        return batch.rows(batch.run(batch.prepare(base, sub, duration, window)), sub)

    # more threads than cores would only take turns on them
    threads = min(threads, len(chunks), os.cpu_count() or 1)
    ex = ThreadPoolExecutor(threads, thread_name_prefix="frictionlab-batch")
    try:
        futs = {ex.submit(one, idx): idx for idx in chunks}
        for fut in as_completed(futs):
            yield list(futs[fut]), fut.result()
    finally:
        ex.shutdown(wait=True, cancel_futures=True)


def iter_evaluate(
    base: Config,
    points: Sequence[Mapping[str, Any]],
    *,
    duration: float | None = None,
    window: float | None = None,
    workers: int | None = None,
    dask: str | None = None,
    chunk_size: int | None = None,
    reduce: Reduce | None = None,
) -> Iterator[tuple[list[int], list[dict[str, Any]]]]:
    """Evaluate ``points`` chunk by chunk, yielding ``(indices, rows)`` as chunks complete.

    Arguments as :func:`evaluate`.  Chunks arrive in completion order; closing
    the generator early cancels the chunks not yet started.
    """
    n = len(points)
    if reduce is not None:
        _check_reduce(reduce)
    if workers is not None and (isinstance(workers, bool) or int(workers) != workers
                                or workers < 1):
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    if chunk_size is not None and (int(chunk_size) != chunk_size or chunk_size < 1):
        raise ValueError(f"chunk_size must be an integer >= 1, got {chunk_size!r}")
    if dask is not None:
        _check_dask_address(dask)
    if n == 0:
        return
    pts = [dict(p) for p in points]
    if dask is not None:
        backend, n_workers = "dask", workers or os.cpu_count() or 1
    elif reduce is None:
        backend, n_workers = "threads", workers or os.cpu_count() or 1
    else:
        n_workers = workers or auto_workers(base, n, duration)
        backend = "serial" if n_workers == 1 else "pool"
    if backend == "threads":
        yield from _thread_chunks(base, pts, duration, window, n_workers,
                                  _chunks(n, chunk_size) if chunk_size
                                  else _guided_chunks(n, n_workers, THREAD_CHUNK))
        return
    if chunk_size:
        chunks = _chunks(n, chunk_size)
    elif backend == "dask" and reduce is None:
        # a Dask task costs milliseconds of scheduling (in this process and the
        # workers); a chunk of the compiled batch runs 1-2 ms a point, so equal
        # chunks, two per worker (measured on 1,000 30 s sets, 2 workers: 4 tasks
        # cost 1.1-1.6 ms of CPU per set where the 20 of a shrinking tail cost
        # 1.5-1.8 ms, at the same or less wall time)
        chunks = _chunks(n, min(DASK_BATCH_CHUNK, math.ceil(n / (2 * n_workers))))
    else:
        chunks = _guided_chunks(n, n_workers)

    if backend == "serial":
        for idx in chunks:
            yield list(idx), _run_chunk(base, [pts[i] for i in idx], duration, window,
                                        reduce)
        return

    if backend == "pool":
        from concurrent.futures import as_completed
        from concurrent.futures.process import BrokenProcessPool

        with _interrupts_deferred():
            ex = _get_pool(n_workers)
            futs = {ex.submit(_run_chunk, base, [pts[i] for i in idx], duration, window,
                              reduce): idx
                    for idx in chunks}
        try:
            for fut in as_completed(futs):
                idx = futs[fut]
                exc = fut.exception()
                if exc is None:
                    yield list(idx), fut.result()
                    continue
                if isinstance(exc, BrokenProcessPool):
                    _drop_pool(n_workers, ex)
                msg = f"worker failed: {type(exc).__name__}: {exc}"
                yield list(idx), [_error_row(pts[i], msg) for i in idx]
        finally:
            for fut in futs:
                fut.cancel()
        return

    from distributed import as_completed as dask_completed

    client = _get_dask(dask, workers)
    dfuts = [client.submit(_run_chunk, base, [pts[i] for i in idx], duration, window, reduce,
                           pure=False) for idx in chunks]
    index = {f.key: idx for f, idx in zip(dfuts, chunks, strict=True)}
    try:
        for fut in dask_completed(dfuts):
            idx = index[fut.key]
            if fut.status == "finished":
                yield list(idx), fut.result()
                continue
            try:
                exc = fut.exception(timeout=30)
            except Exception as e:
                exc = e
            msg = f"worker failed: {type(exc).__name__}: {exc}"
            yield list(idx), [_error_row(pts[i], msg) for i in idx]
    finally:
        pending = [f for f in dfuts if not f.done()]
        if pending:
            client.cancel(pending)


def evaluate(
    base: Config,
    points: Sequence[Mapping[str, float]],
    *,
    duration: float | None = None,
    window: float | None = None,
    workers: int | None = None,
    dask: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    chunk_size: int | None = None,
    reduce: Reduce | None = None,
) -> list[dict]:
    """Run the closed loop for every point and reduce each run to a row.

    Parameters
    ----------
    base : Config
        Configuration every point modifies.
    points : sequence of mappings ``{key: value}``
        Parameter sets, applied with :meth:`Config.with_values`.
    duration, window : float, optional
        As for :func:`frictionlab.model.simulation.run_features` (defaults:
        ``sim.duration``; the last half of the run).
    workers : int, optional
        Default reduction: ``N`` threads in this process (``None``: one per
        core).  With ``reduce``: ``1``
        in-process, ``N`` a local pool of N processes, ``None`` all cores
        except that a sweep of under about half a second of serial work runs
        in-process.  With ``dask="local"``: N Dask workers.
    dask : {"local", "tcp://HOST:PORT"}, optional
        Run on Dask distributed instead of the local pool.
    progress : callable, optional
        Called as ``progress(done, total)`` (points) after every chunk.
    chunk_size : int, optional
        Points per task (default: at most 50 and a quarter of a worker's
        share, shrinking towards the end of the sweep; on Dask with the
        default reduction half a worker's share, at most
        :data:`DASK_BATCH_CHUNK`; the thread backend: at most
        :data:`THREAD_CHUNK`, shrinking towards the end).
    reduce : callable, optional
        ``reduce(cfg, duration, window) -> dict`` runs and reduces one point
        (``cfg`` is the point's configuration) in place of
        :func:`reduce_features`, in the workers.  It returns ``status``
        (``limit_cycle``, ``settled`` or ``fell``) and the seven features,
        plus any extra columns, which follow ``error`` in the row.  It must be
        a picklable top-level function (the pool and Dask ship it by
        reference); an exception it raises makes the point an error row.

    Returns
    -------
    list of dict
        One row per point, in the order of ``points``: the point's keys and
        values, the seven features of :data:`~frictionlab.model.limit_cycles.FEATURES`
        (``None`` where undefined), ``status``
        (``limit_cycle``/``settled``/``fell``/``error``), ``error`` (a
        message, or ``None``) and the extra columns of ``reduce`` (absent
        from an error row).

    Raises
    ------
    TypeError
        ``reduce`` is not a picklable function (before any run).
    ValueError
        Bad ``workers`` or ``chunk_size``.
    ConfigError
        Bad ``dask`` address, or a scheduler that cannot be reached.
    """
    n = len(points)
    rows: list[dict | None] = [None] * n
    done = 0
    with closing(iter_evaluate(base, points, duration=duration, window=window,
                               workers=workers, dask=dask, chunk_size=chunk_size,
                               reduce=reduce)) as chunks:
        for idx, chunk_rows in chunks:
            for i, row in zip(idx, chunk_rows, strict=True):
                rows[i] = row
            done += len(idx)
            if progress is not None:
                progress(done, n)
    return rows  # type: ignore[return-value]


# ---------------------------------------------------------------------------
# output files
# ---------------------------------------------------------------------------


def columns(keys: Sequence[str], extra: Sequence[str] = ()) -> list[str]:
    """CSV columns: the varied keys, the features, ``status``, ``error``, then ``extra``
    (:data:`SWINGUP_COLUMNS` for a swing-up sweep)."""
    return [*keys, *FEATURES, "status", "error", *extra]


class OutputMismatch(ConfigError):
    """An existing output that this sweep cannot continue: its columns or the set-up
    that produced it (its ``.meta.json``) are not this sweep's.  Write another file
    or overwrite it (the command line names its options).

    Attributes
    ----------
    path : str
        The output.
    field : str
        What differs: ``"columns"``, or the set-up's field or key.
    """

    def __init__(self, path: str, field: str, message: str):
        self.path, self.field = path, field
        super().__init__(message)


def _header_mismatch(path: str, found: Sequence[str], cols: Sequence[str]) -> OutputMismatch:
    """The error for an output whose columns are not this sweep's."""
    why = ""
    if sorted(found) == sorted(cols):
        why = (" (the same columns in another order: the file was written by an earlier "
               "frictionlab, status before the features)")
    return OutputMismatch(path, "columns", f"{path} has columns {','.join(found)}; this sweep "
                                           f"writes {','.join(cols)}{why}")


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return repr(v)
    return str(v)


def _parse_cell(col: str, text: str) -> Any:
    if col in ("status", "error"):
        return text if text != "" else None
    if text == "":
        return None
    v = float(text)
    return int(v) if v.is_integer() and "." not in text and "e" not in text.lower() else v


def _parse_csv(text: str, path: str, cols: list[str]) -> list[dict[str, Any]]:
    reader = csv.reader(io.StringIO(text))
    header = next(reader, None)
    if header is None:
        return []
    if header != cols:
        raise _header_mismatch(path, header, cols)
    rows = []
    for line_no, rec in enumerate(reader, start=2):
        if not rec:
            continue
        if len(rec) != len(cols):
            raise ConfigError(f"{path}:{line_no}: expected {len(cols)} fields, got {len(rec)}")
        try:
            rows.append({c: _parse_cell(c, t) for c, t in zip(cols, rec, strict=True)})
        except ValueError:
            raise ConfigError(f"{path}:{line_no}: not a number in a numeric column") from None
    return rows


class SweepFile:
    """The output of a sweep: incremental crash-safe CSV, resume, final rewrite.

    Parameters
    ----------
    path : str
        ``FILE.csv`` or ``FILE.parquet``.
    keys : sequence of str
        The varied keys (the leading columns).
    meta : dict
        What produced the rows (base configuration, duration, window); stored
        in ``FILE.meta.json`` and compared on resume.
    extra : sequence of str
        Columns after ``error`` (:data:`SWINGUP_COLUMNS`).
    """

    def __init__(self, path: str, keys: Sequence[str], meta: dict, extra: Sequence[str] = ()):
        if not path.endswith((".csv", ".parquet")):
            raise ConfigValueError("path", path, ".csv or .parquet",
                                   f"{path}: the extension must be .csv or .parquet")
        self.path = path
        self.keys = list(keys)
        self.cols = columns(keys, extra)
        self.meta = meta
        self.parquet = path.endswith(".parquet")
        self.journal = path + ".partial.csv" if self.parquet else path
        self.meta_path = path + ".meta.json"
        self._fh: io.TextIOBase | None = None

    def _files(self) -> list[str]:
        return [p for p in dict.fromkeys((self.path, self.journal, self.meta_path))
                if os.path.exists(p)]

    def exists(self) -> bool:
        return bool([p for p in self._files() if p != self.meta_path])

    def remove(self) -> None:
        for p in self._files():
            os.remove(p)

    def load(self) -> list[dict[str, Any]]:
        """Rows already present (for ``--resume``), after checking the set-up matches."""
        if not self.exists():
            return []
        self._check_meta()
        rows: list[dict[str, Any]] = []
        if self.parquet and os.path.exists(self.path):
            rows.extend(self._read_parquet())
        if os.path.exists(self.journal):
            rows.extend(self._read_journal())
        return rows

    def _check_meta(self) -> None:
        if not os.path.exists(self.meta_path):
            return
        try:
            with open(self.meta_path, encoding="utf-8") as fh:
                old = json.load(fh)
        except (OSError, ValueError, RecursionError) as exc:
            raise ConfigError(f"cannot read {self.meta_path}: {exc}") from None
        if not isinstance(old, dict):
            raise ConfigError(f"{self.meta_path} is not a sweep's description (a JSON object)")
        for field in ("keys", "duration", "window"):
            if old.get(field) != self.meta.get(field):
                raise OutputMismatch(
                    self.path, field, f"{self.path} was produced with {field} = "
                    f"{old.get(field)!r}, this sweep has {self.meta.get(field)!r}")
        # compared as stored: a tuple value (design.gains) reads back as a list
        ob, nb = old.get("base"), json.loads(json.dumps(self.meta.get("base", {})))
        ob = ob if isinstance(ob, dict) else {}
        for k in sorted(set(ob) | set(nb)):
            if k in self.keys:
                continue
            if ob.get(k) != nb.get(k):
                raise OutputMismatch(
                    self.path, k, f"{self.path} was produced with {k} = {ob.get(k)!r}, "
                    f"this sweep has {nb.get(k)!r}")

    def _read_journal(self) -> list[dict[str, Any]]:
        with open(self.journal, "rb") as fh:
            data = fh.read()
        end = data.rfind(b"\n") + 1
        if end < len(data):
            # a line cut short by a kill: drop it (its chunk is run again)
            with open(self.journal, "r+b") as fh:
                fh.truncate(end)
            data = data[:end]
        return _parse_csv(data.decode("utf-8"), self.journal, self.cols)

    def _read_parquet(self) -> list[dict[str, Any]]:
        import pyarrow.parquet as pq

        try:
            table = pq.read_table(self.path)
        except Exception as exc:
            raise ConfigError(f"cannot read {self.path}: {exc}") from None
        if table.column_names != self.cols:
            raise _header_mismatch(self.path, table.column_names, self.cols)
        return table.to_pylist()

    def open(self) -> None:
        """Start appending (writing the header and the sidecar when new)."""
        Path(self.path).parent.mkdir(parents=True, exist_ok=True)
        with open(self.meta_path, "w", encoding="utf-8") as fh:
            json.dump(self.meta, fh, indent=1)
        new = not os.path.exists(self.journal) or os.path.getsize(self.journal) == 0
        self._fh = open(self.journal, "a", encoding="utf-8", newline="")
        if new:
            self._write_lines([self.cols])

    def _write_lines(self, records: list[list[Any]]) -> None:
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        for rec in records:
            w.writerow(rec)
        assert self._fh is not None
        self._fh.write(buf.getvalue())
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def append(self, rows: Sequence[Mapping[str, Any]]) -> None:
        """Append rows and make them durable (flush + fsync)."""
        self._write_lines([[_fmt(r.get(c)) for c in self.cols] for r in rows])

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def finish(self, rows: Sequence[Mapping[str, Any]]) -> None:
        """Replace the output with ``rows`` (sweep order), atomically."""
        self.close()
        tmp = self.path + ".tmp"
        if self.parquet:
            _write_parquet(tmp, rows, self.keys, self.cols)
        else:
            with open(tmp, "w", encoding="utf-8", newline="") as fh:
                w = csv.writer(fh, lineterminator="\n")
                w.writerow(self.cols)
                for r in rows:
                    w.writerow([_fmt(r.get(c)) for c in self.cols])
                fh.flush()
                os.fsync(fh.fileno())
        os.replace(tmp, self.path)
        if self.parquet and os.path.exists(self.journal):
            os.remove(self.journal)


def _write_parquet(path: str, rows: Sequence[Mapping[str, Any]], keys: Sequence[str],
                   cols: Sequence[str]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    fields = []
    for c in cols:
        if c in ("status", "error"):
            t = pa.string()
        elif c in keys and all(isinstance(r.get(c), int) or r.get(c) is None for r in rows):
            t = pa.int64()
        else:
            t = pa.float64()
        fields.append(pa.field(c, t))
    schema = pa.schema(fields)
    table = pa.Table.from_pylist([{c: r.get(c) for c in cols} for r in rows], schema=schema)
    pq.write_table(table, path)
