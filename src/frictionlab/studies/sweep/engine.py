"""The sweep's engine: a list of points to rows, chunk by chunk, on threads running
the compiled batch evaluator, in-process, on a local process pool or on Dask
(:func:`iter_evaluate`, :func:`evaluate`; the backends' choice in the package's
docstring)."""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import closing
from typing import Any

from ...config import Config
from .backends import check_dask_address, drop_pool, get_dask, get_pool, interrupts_deferred
from .work import Reduce, check_reduce, error_row, run_chunk

__all__ = ["DASK_BATCH_CHUNK", "MAX_CHUNK", "MIN_TAIL_CHUNK", "THREAD_CHUNK", "TINY_WORK",
           "auto_workers", "evaluate", "guided_chunks", "iter_evaluate"]

#: Largest number of points per task.
MAX_CHUNK = 50
#: Smallest task of the shrinking tail of a sweep (default chunking).
MIN_TAIL_CHUNK = 4
#: ``workers=None`` runs a sweep in-process when its serial work (points x ticks
#: x substeps) is below this (about half a second of simulation).
TINY_WORK = 5_000_000


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


def guided_chunks(n: int, workers: int, max_chunk: int = MAX_CHUNK) -> list[range]:
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

    from .. import batch  # start-up: loads with the first sweep, not the command line

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
        check_reduce(reduce)
    if workers is not None and (isinstance(workers, bool) or int(workers) != workers
                                or workers < 1):
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    if chunk_size is not None and (int(chunk_size) != chunk_size or chunk_size < 1):
        raise ValueError(f"chunk_size must be an integer >= 1, got {chunk_size!r}")
    if dask is not None:
        check_dask_address(dask)
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
                                  else guided_chunks(n, n_workers, THREAD_CHUNK))
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
        chunks = guided_chunks(n, n_workers)

    if backend == "serial":
        for idx in chunks:
            yield list(idx), run_chunk(base, [pts[i] for i in idx], duration, window,
                                        reduce)
        return

    if backend == "pool":
        from concurrent.futures import as_completed
        from concurrent.futures.process import BrokenProcessPool

        with interrupts_deferred():
            ex = get_pool(n_workers)
            futs = {ex.submit(run_chunk, base, [pts[i] for i in idx], duration, window,
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
                    drop_pool(n_workers, ex)
                msg = f"worker failed: {type(exc).__name__}: {exc}"
                yield list(idx), [error_row(pts[i], msg) for i in idx]
        finally:
            for fut in futs:
                fut.cancel()
        return

    from distributed import as_completed as dask_completed

    client = get_dask(dask, workers)
    dfuts = [client.submit(run_chunk, base, [pts[i] for i in idx], duration, window, reduce,
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
            yield list(idx), [error_row(pts[i], msg) for i in idx]
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
        As for :func:`frictionlab.runs.run_features` (defaults:
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
