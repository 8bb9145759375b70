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
:func:`reduce_features` (:func:`frictionlab.runs.run_features`); a
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
  :func:`~.backends.local_dask_config`), ``dask="tcp://HOST:PORT"`` connects to a
  running scheduler whose workers have ``frictionlab`` installed.  Clients
  are kept like the pool.  Each worker evaluates its chunk with the compiled
  batch evaluator on one thread (or with ``reduce``).

Modules
-------
:mod:`.points` (the varied keys, the parameter sets), :mod:`.work` (the unit of
work: a point to a row), :mod:`.backends` (the process pool and Dask clients),
:mod:`.engine` (:func:`evaluate`, :func:`iter_evaluate`), :mod:`.files` (the
output files).  Every public name is importable from ``frictionlab.studies.sweep``.

Output files
------------
:class:`SweepFile` writes rows as chunks complete (CSV, flushed and fsynced per
chunk), reads them back for ``--resume``, and at the end rewrites the file in
sweep order (atomically).  Columns: the varied keys, the seven features of
:data:`frictionlab.model.limit_cycles.FEATURES`, ``status``, ``error`` (a
``reduce``'s extra columns are not written, except the swing-up sweep's
``caught`` and ``swing_up_time``).  A
``.parquet`` output is written at the end from all rows; while the sweep runs
the rows go to the crash-safe CSV journal ``FILE.parquet.partial.csv``.
A sidecar ``FILE.meta.json`` records the base configuration, duration and
window, so that ``--resume`` refuses to mix results of different set-ups.
"""

from __future__ import annotations

from .backends import DASK_FORMS, check_dask_address, get_dask, shutdown
from .engine import (
    DASK_BATCH_CHUNK,
    MAX_CHUNK,
    MIN_TAIL_CHUNK,
    THREAD_CHUNK,
    TINY_WORK,
    auto_workers,
    evaluate,
    guided_chunks,
    iter_evaluate,
)
from .files import OutputMismatch, SweepFile, columns
from .points import (
    MAX_POINTS,
    MODES,
    VARY_FORMS,
    make_points,
    parse_vary,
    point_ident,
    validate_points,
)
from .work import STATUSES, SWINGUP_COLUMNS, Reduce, reduce_features, reduce_swingup

__all__ = [
    "DASK_BATCH_CHUNK",
    "DASK_FORMS",
    "MAX_CHUNK",
    "MAX_POINTS",
    "MIN_TAIL_CHUNK",
    "MODES",
    "STATUSES",
    "SWINGUP_COLUMNS",
    "THREAD_CHUNK",
    "TINY_WORK",
    "VARY_FORMS",
    "OutputMismatch",
    "Reduce",
    "SweepFile",
    "auto_workers",
    "check_dask_address",
    "columns",
    "evaluate",
    "get_dask",
    "guided_chunks",
    "iter_evaluate",
    "make_points",
    "parse_vary",
    "point_ident",
    "reduce_features",
    "reduce_swingup",
    "shutdown",
    "validate_points",
]
