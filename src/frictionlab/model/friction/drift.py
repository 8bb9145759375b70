"""The friction record written at run time: copies, the adaptive compensator's
levels, and the plant's drift of its levels over a run (``friction.drift``;
:mod:`frictionlab.model.friction`)."""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit, jit_inline
from .params import copy_friction, friction_view


@jit_inline
def copy_friction_into(p, out):
    """Copy every field of the friction record ``p`` into ``out``."""
    out.fs = p.fs
    out.fc = p.fc
    out.fv = p.fv
    out.vs = p.vs
    out.sigma0 = p.sigma0
    out.sigma1 = p.sigma1
    out.k = p.k
    out.band = p.band
    out.eps = p.eps
    out.fs_neg = p.fs_neg
    out.fc_neg = p.fc_neg
    out.fv_neg = p.fv_neg
    out.vd = p.vd
    out.drift = p.drift
    out.drift_start = p.drift_start
    out.drift_time = p.drift_time
    out.adapt_gain = p.adapt_gain
    out.adapt_bandwidth = p.adapt_bandwidth
    out.adapt_deadband = p.adapt_deadband
    out.adapt_innovation = p.adapt_innovation
    out.adapt_min = p.adapt_min
    out.adapt_max = p.adapt_max
    out.adapt_distance = p.adapt_distance


@jit
def with_levels(p, fc, fs, out):
    """Write ``p`` with the Coulomb and stiction levels (both directions)
    replaced by ``fc`` and ``fs`` into the record ``out`` (the adaptive
    compensator's estimates, :mod:`frictionlab.model.adaptive`); returns ``out``."""
    copy_friction_into(p, out)
    out.fc = fc
    out.fc_neg = fc
    out.fs = fs
    out.fs_neg = fs
    return out


@jit
def drift_factor(t, p):
    r"""Factor on the plant's friction levels at time ``t`` (``friction.drift``).

    :math:`1 + d\,\min(1, \max(0, (t - t_0)/T))` with d = ``drift``,
    :math:`t_0` = ``drift_start`` and T = ``drift_time`` (a NaN T must have
    been replaced by the run's duration; T = 0 is a step at :math:`t_0`).
    """
    d = p.drift
    if d == 0.0:
        return 1.0
    t0 = p.drift_start
    span = p.drift_time
    if t < t0:
        return 1.0
    if not span > 0.0:
        return 1.0 + d
    r = (t - t0) / span
    return 1.0 + d * min(r, 1.0)


@jit
def drifted_params(p, t, out):
    """Write ``p`` with its levels (F_S, F_C, F_v, both directions) scaled by
    :func:`drift_factor` at time ``t`` into the (scratch) record ``out``;
    returns ``out``."""
    c = drift_factor(t, p)
    copy_friction_into(p, out)
    if c != 1.0:
        out.fs = p.fs * c
        out.fc = p.fc * c
        out.fv = p.fv * c
        out.fs_neg = p.fs_neg * c
        out.fc_neg = p.fc_neg * c
        out.fv_neg = p.fv_neg * c
    return out


@jit
def drifted_rows(p, t, out):
    """:func:`drifted_params` on records stored as float rows (:func:`friction_row`):
    the form for a caller in Python at every tick (the emulated plant)."""
    drifted_params(friction_view(p), t, friction_view(out))


@jit
def is_drifting(p):
    """Whether ``p`` has a drift with a resolved drift time (:func:`resolve_drift`;
    an unresolved one, NaN, is ignored)."""
    return p.drift != 0.0 and not np.isnan(p.drift_time)


def without_drift(p: np.record) -> np.record:
    """A copy of ``p`` without drift (the plant at its starting levels)."""
    q = copy_friction(p)
    q["drift"] = 0.0
    return q


def resolve_drift(p: np.record, duration: float) -> np.record:
    """``p`` (a copy if changed) with an unset drift time (NaN: to the end of
    the run) set to the time from ``drift_start`` to ``duration``, the run's
    length in s."""
    # (items, not attributes: numpy reads a record's attribute in Python code)
    if math.isnan(p["drift_time"]):
        p = copy_friction(p)
        p["drift_time"] = max(float(duration) - p["drift_start"], 0.0)
    return p
