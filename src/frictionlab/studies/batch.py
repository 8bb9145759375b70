r"""Compiled batch evaluation: many closed-loop runs reduced to their features in one call.

The unit of work of sweeps and identification is one closed-loop run (Sec. 5)
reduced to its limit-cycle features (Table 1's columns).  Run one at a time
from Python, each costs the compiled simulation plus the Python around it
(building the trajectory, slicing the window, the feature calls).  Here a
whole batch of parameter sets - a sweep's chunk, one generation of the
identification's global search - is packed into arrays once and handed to one
compiled driver, which for every set runs the same compiled closed loop as
:func:`frictionlab.runs.simulate_config`
(:func:`~frictionlab.model.closedloop.run_loop`:
sensor model, controller step, plant tick) and the same compiled feature
extraction as :func:`frictionlab.model.limit_cycles.features`
(:func:`~frictionlab.model.limit_cycles.features_kernel`), with no Python per run.
The features are those of :func:`frictionlab.runs.run_features`, bit
for bit (noise included: :func:`frictionlab.model.sensor.measure`'s noise is a
function of the seed and the sample number, with no generator state to share
between threads).

The driver :func:`_batch_serial` runs the sets in turn with the GIL
released: the thread backend of :mod:`frictionlab.studies.sweep` runs one
batch per Python thread, each thread taking the next chunk of the sweep when
it is done with one; the Dask and process-pool workers run one batch at a time.

numba is imported on the first batch, as for every kernel
(:mod:`frictionlab.model._jit`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config import Config
from ..model._jit import jit, jit_nogil
from ..model.closedloop import NC, run_loop
from ..model.controller import NS, gains_record, gains_row, state_vector, state_view
from ..model.friction import KINDS, friction_row, friction_view, plant_record, resolve_drift
from ..model.limit_cycles import (
    FEATURES,
    KERNEL_VALUES,
    REL_PROMINENCE,
    SETTLE_TOL,
    SMOOTH,
    STATUS_CODES,
    features_kernel,
)
from ..model.sensor import SensorParams, sensor_record
from ..model.swingup import SWING_FIELDS, SwingUpRecord
from ..runs import make_controller, make_sensor, run_ticks

__all__ = ["Batch", "evaluate_rows", "prepare", "rows", "run"]

#: Status code of a set whose window is not positive (an error row).
_BAD_WINDOW = 3
_FEATURE_INDEX = [KERNEL_VALUES.index(name) for name in FEATURES]


#: Ticks recorded per call of the closed loop: the rows of a chunk stay in the
#: core's cache (a whole run's 18 columns, 0.9 MB for 30 s, did not), and only
#: the three columns the features read are kept.
CHUNK_TICKS = 256
#: Lengths of the swing-up supervisor's rows (run_loop's unused swing-up arguments).
_SUP_N = len(SwingUpRecord._fields)
_SWING_N = len(SWING_FIELDS)


@jit
def _one(i, x0, nt, pc, sub, rat, h, pp, fk, fp, gp, cp, s0, sens, fall, win,
         buf, sig, codes, vals, cycles):
    """Run set ``i`` and store its status code, feature values and cycle count.

    As :func:`frictionlab.runs.run_features`: the closed loop for
    ``nt[i]`` ticks (recorded into ``buf``, :data:`CHUNK_TICKS` rows at a time:
    the loop continued chunk by chunk is the single run bit for bit, as
    :func:`~frictionlab.runs.simulate_config` with ``progress``; the
    measured angle, u and the measured arm velocity copied into ``sig``), then the
    features of the measured angle over the window (``win[i]`` s, nan: the last
    half) by :func:`frictionlab.model.limit_cycles.trajectory_features`'s rules.
    """
    x = np.zeros(5)
    x[0] = x0[i]
    # the controller state is a record on a copy of row i (viewed below, where
    # the copy is used, so that numba keeps it alive: a record does not hold its
    # array); the plant's and the compensator's friction records view rows of
    # the caller's arrays, once
    s_row = s0[i].copy()
    plant_friction = friction_view(fp[i])
    comp = friction_view(cp[i])
    sp = sensor_record(sens[i])
    gains = gains_record(gp[i])
    n = nt[i]
    chunk = buf.shape[0]
    # run_loop's swing-up arguments, unused (no swing-up in a batch)
    sup_row = np.zeros(_SUP_N)
    wx = np.zeros(_SWING_N)
    phase = np.zeros(0)
    # np.int64 and np.bool_, not the constants 0, True, False: numba compiles a callee
    # for literal argument types (Literal[int](0), Literal[bool](True)) apart from the
    # int64 and bool of the Python callers (simulate, the periodic orbits, the swing-up):
    # run_loop, the longest compile of the package, would be compiled three times
    done, fell_code, mem, zero = np.int64(0), 0, 0.0, 0.0
    record, swing = np.bool_(True), np.bool_(False)
    while done < n and fell_code == 0:
        m = min(chunk, n - done)
        d, fell_code, mem, zero = run_loop(x, mem, m, pc[i], sub[i], rat[i], pp[i], fk[i],
                                           plant_friction, gains, comp, state_view(s_row), sp,
                                           done, zero, fall[i], buf, record, swing, sup_row,
                                           wx, phase)
        for k in range(d):
            sig[0, done + k] = buf[k, 0]
            sig[1, done + k] = buf[k, 3]
            sig[2, done + k] = buf[k, 5]
        done += d
    fell = fell_code == 1
    for j in range(vals.shape[1]):
        vals[i, j] = np.nan
    cycles[i] = 0
    if done < 3:
        codes[i] = 2 if fell else 1
        return
    hi = h[i]
    last = (done - 1) * hi  # the times are np.arange(done) * h
    w = win[i]
    if np.isnan(w):
        span = 0.5 * (last - 0.0)
    elif fell:
        span = w
    else:
        span = min(w, last)
    if not span > 0:
        codes[i] = _BAD_WINDOW
        return
    # only the window's samples (and at least 3) go to the features: the same
    # window, without the times and copies of the samples before it
    thr = last - span - 1e-12
    lo = done
    while lo > 0 and (lo - 1) * hi >= thr:
        lo -= 1
    lo = min(lo, done - 3)
    t = np.arange(lo, done) * hi
    code, fv, cyc = features_kernel(t, sig[0, lo:done], sig[1, lo:done], sig[2, lo:done], span,
                                     fell, sp.noise, REL_PROMINENCE, SETTLE_TOL,
                                     np.int64(SMOOTH))  # not a literal: as from Python
    codes[i] = code
    vals[i, :] = fv
    cycles[i] = cyc


@jit_nogil
def _batch_serial(x0, nt, pc, sub, rat, h, pp, fk, fp, gp, cp, s0, sens, fall, win,
                  codes, vals, cycles):
    """Every set of the batch in turn (in the calling thread, the GIL released)."""
    n = len(nt)
    longest = 1
    for i in range(n):
        longest = max(longest, nt[i])
    buf = np.empty((min(longest, CHUNK_TICKS), NC))
    sig = np.empty((3, longest))
    for i in range(n):
        _one(i, x0, nt, pc, sub, rat, h, pp, fk, fp, gp, cp, s0, sens, fall, win,
             buf, sig, codes, vals, cycles)


@dataclass
class Batch:
    """Parameter sets packed for the compiled drivers.

    ``points[k]`` is the point of set k; ``errors`` holds, by index into the
    original point list, the message of every point that could not be packed
    (invalid configuration or duration); ``index[k]`` is the original index
    of set k.
    """

    points: list[Mapping[str, Any]]
    index: list[int]
    errors: dict[int, str]
    arrays: tuple
    window: float | None
    codes: np.ndarray
    vals: np.ndarray
    cycles: np.ndarray
    n_points: int


def _pack(cfgs: Sequence[Config], durations: Sequence[int], window: float | None) -> tuple:
    n = len(cfgs)
    x0 = np.empty(n)
    nt = np.empty(n, dtype=np.int64)
    pc = np.empty(n, dtype=np.int64)
    sub = np.empty(n, dtype=np.int64)
    rat = np.empty(n, dtype=np.int64)
    h = np.empty(n)
    fk = np.empty(n, dtype=np.int64)
    fall = np.empty(n)
    win = np.full(n, np.nan if window is None else float(window))
    pp, fp, gp, cp, s0, sens = [], [], [], [], [], []
    # the controller, plant and sensor rows depend on these sections only; a
    # sweep's points share them (with_values keeps the sections it does not
    # change, the very objects), so they are packed once per run of equal ones
    last_key: tuple = ()
    for k, (cfg, ticks) in enumerate(zip(cfgs, durations, strict=True)):
        key = (cfg.design, cfg.plant, cfg.compensation_kind, cfg.compensation, cfg.rig,
               cfg.sim)
        if len(last_key) != len(key) or any(a is not b for a, b in zip(key, last_key, strict=True)):
            ctrl = make_controller(cfg)
            g, c = ctrl.record()
            shared = (gains_row(g),  # gains_record reads it back
                      friction_row(c),  # friction_view reads it back
                      state_vector(ctrl.init(cfg.sim.initial_angle)),  # state_view reads it
                      cfg.plant_row(),
                      np.array(make_sensor(cfg), dtype=float))  # sensor_record reads it back
            last_key = key
        gp.append(shared[0])
        cp.append(shared[1])
        s0.append(shared[2])
        pp.append(shared[3])
        sens.append(shared[4])
        fp.append(friction_row(resolve_drift(plant_record(cfg.friction_kind, cfg.friction),
                                             ticks * cfg.design.h)))
        x0[k] = cfg.sim.initial_angle
        nt[k] = ticks
        pc[k] = cfg.plant_model.code
        sub[k] = cfg.substeps
        rat[k] = cfg.pendulum_ratio
        h[k] = cfg.design.h
        fk[k] = KINDS.index(cfg.friction_kind)
        fall[k] = cfg.sim.fall_angle

    def stack(rows, width):
        return np.ascontiguousarray(np.array(rows, dtype=float).reshape(n, width))

    # plant rows of every width (a batch may mix plants), padded to the widest
    wide = max((len(r) for r in pp), default=0)
    pp = [np.pad(r, (0, wide - len(r))) for r in pp]
    return (x0, nt, pc, sub, rat, h, stack(pp, wide), fk, stack(fp, len(fp[0]) if n else 0),
            stack(gp, len(gp[0]) if n else 0), stack(cp, len(cp[0]) if n else 0),
            stack(s0, NS), stack(sens, len(SensorParams._fields)), fall, win)


def prepare(base: Config, points: Sequence[Mapping[str, Any]], duration: float | None,
            window: float | None) -> Batch:
    """Pack ``points`` (``{key: value}`` applied to ``base``) for :func:`run`.

    A point whose configuration is invalid, or whose duration is, becomes an
    error (the message a single run would raise).
    """
    cfgs, ticks, index, kept, errors = [], [], [], [], {}
    for i, p in enumerate(points):
        try:
            cfg = base.with_values(p)
            n = run_ticks(cfg, duration)
        except Exception as exc:
            errors[i] = f"{type(exc).__name__}: {exc}"
            continue
        cfgs.append(cfg)
        ticks.append(n)
        index.append(i)
        kept.append(p)
    n = len(cfgs)
    return Batch(kept, index, errors, _pack(cfgs, ticks, window) if n else (), window,
                 np.zeros(n, dtype=np.int64), np.full((n, len(KERNEL_VALUES)), np.nan),
                 np.zeros(n, dtype=np.int64), len(points))


def run(batch: Batch) -> Batch:
    """Run every set of ``batch`` in the calling thread, the GIL released (in place;
    returns it)."""
    if batch.index:
        _batch_serial(*batch.arrays, batch.codes, batch.vals, batch.cycles)
    return batch


def rows(batch: Batch, points: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Sweep rows of a run batch, in the order of ``points`` (the list it was prepared
    from): the point, the seven features (``None`` where undefined), ``status``,
    ``error``; a point that could not run is an ``error`` row."""
    out: list[dict[str, Any] | None] = [None] * batch.n_points
    for i, msg in batch.errors.items():
        row = dict(points[i])
        row.update(dict.fromkeys(FEATURES))
        row["status"] = "error"
        row["error"] = msg
        out[i] = row
    vals = batch.vals[:, _FEATURE_INDEX].tolist()
    for k, i in enumerate(batch.index):
        row = dict(points[i])
        code = int(batch.codes[k])
        if code == _BAD_WINDOW:
            row.update(dict.fromkeys(FEATURES))
            row["status"] = "error"
            row["error"] = f"ValueError: window must be > 0 s, got {batch.window}"
        else:
            row.update({name: (v if math.isfinite(v) else None)
                        for name, v in zip(FEATURES, vals[k], strict=True)})
            row["status"] = STATUS_CODES[code]
            row["error"] = None
        out[i] = row
    return out  # type: ignore[return-value]


def evaluate_rows(base: Config, points: Sequence[Mapping[str, Any]], duration: float | None,
                  window: float | None) -> list[dict[str, Any]]:
    """Rows of :func:`frictionlab.studies.sweep.evaluate` with the default reduction, in one batch.

    Parameters
    ----------
    base : Config
        Configuration every point modifies.
    points : sequence of mappings ``{key: value}``
    duration, window : float or None
        As for :func:`frictionlab.runs.run_features`.

    Returns
    -------
    list of dict
        One row per point, as :func:`frictionlab.studies.sweep.reduce_features` and
        the sweep engine make it.
    """
    return rows(run(prepare(base, points, duration, window)), points)
