"""The workers a sweep runs on, kept for the life of the process: a local process
pool forked from a warm ``forkserver``, and Dask clients (a ``LocalCluster`` or a
running scheduler); :func:`shutdown` closes them (also at exit)."""

from __future__ import annotations

import atexit
import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from ...config import ConfigValueError, build_config
from ...runs import run_features

__all__ = ["DASK_FORMS", "check_dask_address", "drop_pool", "get_dask", "get_pool",
           "interrupts_deferred", "local_dask_config", "pool_worker_init", "shutdown",
           "warm_up"]


def warm_up() -> None:
    """Load the compiled simulator and batch evaluator once (from numba's on-disk cache)."""
    from ..batch import evaluate_rows  # start-up: not with the command line

    run_features(build_config(), 2.0)
    evaluate_rows(build_config(), [{}], 2.0, None)


#: Set only in the environment of the forkserver this module starts: importing
#: the module there (a preload) also loads the compiled simulator, so that pool
#: workers fork with it in memory instead of each loading (or compiling) it.
_FORKSERVER_WARM_ENV = "FRICTIONLAB_SWEEP_FORKSERVER_WARM"


def _exit_with(parent) -> None:
    parent.join()  # returns when the parent's end of the pipe closes
    os._exit(1)


def pool_worker_init() -> None:
    """Pool worker start-up: warm the simulator, and exit when the sweep's process dies.

    A worker whose parent disappears without shutting the pool down (e.g. it
    was killed with SIGKILL) exits at once instead of lingering.
    """
    import multiprocessing

    warm_up()
    parent = multiprocessing.parent_process()
    if parent is not None:
        threading.Thread(target=_exit_with, args=(parent,), daemon=True).start()



# ---------------------------------------------------------------------------
# backends
# ---------------------------------------------------------------------------

_lock = threading.Lock()
_pools: dict[int, Any] = {}
_dask: dict[tuple, tuple[Any, Any]] = {}


def get_pool(workers: int):
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with _lock:
        ex = _pools.get(workers)
        if ex is None:
            from multiprocessing import forkserver

            ctx = multiprocessing.get_context("forkserver")
            # the forkserver imports and warms the simulator once; workers fork from it
            ctx.set_forkserver_preload(["frictionlab.studies.sweep.backends"])
            os.environ[_FORKSERVER_WARM_ENV] = "1"
            try:
                forkserver.ensure_running()
            finally:
                del os.environ[_FORKSERVER_WARM_ENV]
            ex = ProcessPoolExecutor(workers, mp_context=ctx, initializer=pool_worker_init)
            _pools[workers] = ex
        return ex


@contextmanager
def interrupts_deferred() -> Iterator[None]:
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


def drop_pool(workers: int, ex) -> None:
    with _lock:
        if _pools.get(workers) is ex:
            del _pools[workers]
    ex.shutdown(wait=False, cancel_futures=True)


def local_dask_config() -> dict[str, Any]:
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


def get_dask(address: str, workers: int | None):
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
            with dask.config.set(local_dask_config()):
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
            client.run(warm_up)
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
        warm_up()
    except Exception:  # the workers then warm up themselves
        pass


#: What a Dask address may be (the ``allowed`` of a refused one, field ``dask``).
DASK_FORMS = "'local' or tcp://HOST:PORT"


def check_dask_address(dask: str) -> None:
    if dask != "local" and not (dask.startswith("tcp://") and ":" in dask[len("tcp://"):]):
        raise ConfigValueError("dask", dask, DASK_FORMS, f"must be {DASK_FORMS}, got {dask!r}")
