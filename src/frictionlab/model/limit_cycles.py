r"""Limit-cycle features of the measured pendulum angle (Table 1's columns).

For each positive half-cycle of the measured angle (from an upward zero
crossing to the next downward one):

* ``peak1`` - the first local maximum,
* ``peak2`` - the last local maximum,
* ``valley`` - the minimum between them.

A half-cycle with a single maximum contributes ``peak1`` only (its
``peak2``/``valley`` are missing).  Each feature is averaged over the
half-cycles inside the analysis window; a feature no half-cycle has is
reported as ``None``.  ``period`` is the mean spacing of upward zero crossings
(linearly interpolated); ``max_u`` and ``max_arm_velocity`` are the maxima of
``|u|`` and ``|measured arm velocity|``; ``peak_to_peak`` is max - min of the
measured angle.  The same figures for the negative half-cycles (of
``-theta``) are returned as ``neg_peak1``/``neg_peak2``/``neg_valley``, a
symmetry check.

Local maxima are found with a prominence threshold (the definitions of
:func:`scipy.signal.find_peaks`, compiled) (by default 2% of the half-cycle's height, at least
3 noise standard deviations), so that measurement noise and quantisation
steps do not count as peaks.  Zero crossings use a small hysteresis for the
same reason.  With a known measurement-noise level (``noise > 0``) the angle
is first smoothed by a 9-sample centred moving average (45 ms at h = 5 ms),
which also removes the upward bias noise gives a raw maximum.

``status`` is ``"fell"`` when the run fell; ``"settled"`` when the angle's
peak-to-peak over the window is below ``settle_tol``, or when the window holds
no cycle (fewer than two upward crossings) and the peak-to-peak is below 10
noise standard deviations (the wander measurement noise drives through a loop
whose limit cycle compensation has removed); else ``"limit_cycle"``, with
``period`` ``None`` when the window holds fewer than two upward crossings (a
window shorter than the slow design's 3.3 s cycle, say).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ._jit import jit

__all__ = ["FEATURES", "LimitCycleFeatures", "features", "trajectory_features"]

#: Feature names of ``simulate --json`` (docs/cli.md), in Table 1's order plus peak_to_peak.
FEATURES = ("peak1", "peak2", "valley", "period", "max_u", "max_arm_velocity", "peak_to_peak")


@dataclass(frozen=True)
class LimitCycleFeatures:
    """Limit-cycle features (SI units; ``None`` where undefined)."""

    status: str
    peak1: float | None
    peak2: float | None
    valley: float | None
    period: float | None
    max_u: float | None
    max_arm_velocity: float | None
    peak_to_peak: float | None
    neg_peak1: float | None = None
    neg_peak2: float | None = None
    neg_valley: float | None = None
    cycles: int = 0

    def as_dict(self) -> dict:
        return asdict(self)

    def interface_dict(self) -> dict:
        """The ``features`` object of ``frictionlab simulate --json``."""
        return {k: getattr(self, k) for k in FEATURES}


def _mean(values: np.ndarray) -> float | None:
    """Mean of the finite entries (the half-cycles that have the feature), or None."""
    v = values[np.isfinite(values)]
    return float(v.sum() / len(v)) if len(v) else None


@jit
def _crossings_kernel(t, y, hyst):
    n = len(y)
    up_t = np.empty(n)
    up_i = np.empty(n, dtype=np.int64)
    dn_t = np.empty(n)
    dn_i = np.empty(n, dtype=np.int64)
    nu = 0
    nd = 0
    state = 0  # -1 below, +1 above
    last_change = -1
    for i in range(1, n):
        if (y[i - 1] < 0.0) != (y[i] < 0.0):
            last_change = i
        if y[i] > hyst and state <= 0:
            if state < 0 and last_change > 0:
                j = last_change
                up_t[nu] = t[j - 1] + (t[j] - t[j - 1]) * (-y[j - 1]) / (y[j] - y[j - 1])
                up_i[nu] = j
                nu += 1
            state = 1
        elif y[i] < -hyst and state >= 0:
            if state > 0 and last_change > 0:
                j = last_change
                dn_t[nd] = t[j - 1] + (t[j] - t[j - 1]) * (-y[j - 1]) / (y[j] - y[j - 1])
                dn_i[nd] = j
                nd += 1
            state = -1
    return up_t[:nu], up_i[:nu], dn_t[:nd], dn_i[:nd]


def _crossings(t: np.ndarray, y: np.ndarray, hyst: float):
    """Interpolated times and sample indices of upward / downward zero crossings.

    A crossing counts once the signal has moved from beyond ``-hyst`` to beyond
    ``+hyst`` (Schmitt trigger); its time is the last sign change in between.
    """
    return _crossings_kernel(np.ascontiguousarray(t, dtype=float),
                             np.ascontiguousarray(y, dtype=float), float(hyst))


@jit
def _segment_peaks(seg, min_prominence):
    """Indices of local maxima of ``seg`` with prominence >= ``min_prominence``.

    Same definitions as :func:`scipy.signal.find_peaks` (plateaus give their
    middle sample; prominence = height above the higher of the two bases), with
    the segment padded by zeros so that maxima at its edges count.
    """
    n = len(seg)
    y = np.zeros(n + 2)
    y[1:n + 1] = seg
    peaks = np.empty(n, dtype=np.int64)
    npk = 0
    i = 1
    while i < n + 1:
        if y[i - 1] < y[i]:
            j = i + 1
            while j < n + 1 and y[j] == y[i]:
                j += 1
            if y[j] < y[i]:
                p = (i + j - 1) // 2
                hp = y[p]
                k = p - 1
                left_min = hp
                while k >= 0 and y[k] <= hp:
                    if y[k] < left_min:
                        left_min = y[k]
                    k -= 1
                k = p + 1
                right_min = hp
                while k <= n + 1 and y[k] <= hp:
                    if y[k] < right_min:
                        right_min = y[k]
                    k += 1
                if hp - max(left_min, right_min) >= min_prominence:
                    peaks[npk] = p - 1
                    npk += 1
            i = j
        else:
            i += 1
    return peaks[:npk]


@jit
def _half_cycle_kernel(y, starts, ends, noise, rel_prominence):
    m = len(starts)
    p1 = np.full(m, np.nan)
    p2 = np.full(m, np.nan)
    va = np.full(m, np.nan)
    for c in range(m):
        a, b = starts[c], ends[c]
        if b - a < 3:
            continue
        seg = y[a:b]
        height = seg.max()
        prom = max(rel_prominence * height, 3.0 * noise, 1e-12)
        idx = _segment_peaks(seg, prom)
        if len(idx) == 0:
            continue
        p1[c] = seg[idx[0]]
        if len(idx) >= 2:
            p2[c] = seg[idx[-1]]
            va[c] = seg[idx[0]:idx[-1] + 1].min()
    return p1, p2, va


def _half_cycles(starts: np.ndarray, ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pair each crossing in ``starts`` with the first crossing in ``ends`` after it
    (both sorted sample indices); starts with no later end are dropped."""
    j = np.searchsorted(ends, starts, side="right")
    ok = j < len(ends)
    return starts[ok], ends[j[ok]]


def features(
    t,
    theta,
    u=None,
    arm_velocity=None,
    *,
    window: float | None = None,
    fell: bool = False,
    noise: float = 0.0,
    rel_prominence: float = 0.02,
    settle_tol: float = 2e-3,
    smooth: int = 9,
) -> LimitCycleFeatures:
    """Limit-cycle features of a measured pendulum angle.

    Parameters
    ----------
    t, theta : array_like
        Time (s) and measured pendulum angle (rad).
    u, arm_velocity : array_like, optional
        Control signal and measured arm velocity, for ``max_u`` and
        ``max_arm_velocity``.
    window : float, optional
        Analyse only the last ``window`` seconds (default: the last half).
    fell : bool
        The run fell (status ``"fell"``; features are still computed on what
        there is).
    noise : float
        Measurement-noise standard deviation (rad).  When positive, the angle
        is smoothed with a ``smooth``-sample centred moving average first, and
        the peak prominence and crossing hysteresis are kept above 3 noise
        standard deviations.
    rel_prominence : float
        Minimum peak prominence relative to the half-cycle's height.
    settle_tol : float
        Peak-to-peak (rad) below which the loop counts as settled.
    smooth : int
        Moving-average length (samples) used when ``noise > 0``.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(theta, dtype=float)
    if t.shape != y.shape or t.ndim != 1:
        raise ValueError("t and theta must be 1-D arrays of equal length")
    n = len(t)
    empty = LimitCycleFeatures("fell" if fell else "settled", *([None] * 7))
    if n < 3:
        return empty
    span = window if window is not None else 0.5 * (t[-1] - t[0])
    if not span > 0:
        raise ValueError(f"window must be > 0 s, got {window}")
    m = t >= t[-1] - span - 1e-12
    tw, yw = t[m], y[m]
    finite = np.isfinite(yw)
    if not finite.all():
        tw, yw = tw[finite], yw[finite]
        if len(yw) < 3:
            return empty
    if noise > 0.0 and len(yw) >= smooth:
        # noisy measurements: a short centred moving average (default 9 samples,
        # 45 ms at h = 5 ms, far shorter than any limit cycle) before peak search
        from scipy.ndimage import uniform_filter1d  # heavy import, only when used

        yw = uniform_filter1d(yw, size=smooth, mode="nearest")
    ptp = float(yw.max() - yw.min())
    max_u = float(np.max(np.abs(np.asarray(u, dtype=float)[m]))) if u is not None else None
    max_v = (float(np.max(np.abs(np.asarray(arm_velocity, dtype=float)[m])))
             if arm_velocity is not None else None)
    hyst = max(0.02 * 0.5 * ptp, 3.0 * noise)
    up_t, up_i, _dn_t, dn_i = _crossings(tw, yw, hyst)
    period = float(np.mean(np.diff(up_t))) if len(up_t) >= 2 else None
    # positive half-cycles: an upward crossing followed by the next downward one
    yw = np.ascontiguousarray(yw, dtype=float)
    p1, p2, va = _half_cycle_kernel(yw, *_half_cycles(up_i, dn_i), float(noise),
                                    float(rel_prominence))
    n1, n2, nv = _half_cycle_kernel(-yw, *_half_cycles(dn_i, up_i), float(noise),
                                    float(rel_prominence))
    if fell:
        # a falling run has no cycle shape: only the extremes are meaningful
        p1 = p2 = va = n1 = n2 = nv = np.empty(0)
        period = None
        status = "fell"
    elif ptp < settle_tol or (len(up_t) < 2 and ptp < 10.0 * noise):
        # at rest, or no cycle and no more motion than the noise drives
        status = "settled"
    else:
        status = "limit_cycle"
    return LimitCycleFeatures(
        status, _mean(p1), _mean(p2), _mean(va), period, max_u, max_v, ptp,
        _mean(n1), _mean(n2), _mean(nv), int(np.isfinite(p1).sum()),
    )


def trajectory_features(traj, window: float | None = None) -> LimitCycleFeatures:
    """:func:`features` of a :class:`frictionlab.simulation.Trajectory`."""
    cfg = traj.config
    noise = cfg.sim.noise if cfg is not None else 0.0
    if len(traj) < 3:
        return LimitCycleFeatures("fell" if traj.status == "fell" else "settled", *([None] * 7))
    if window is not None and cfg is not None and traj.status != "fell":
        window = min(window, traj.t[-1])
    return features(
        traj.t, traj["theta_m"], traj["u"], traj["arm_dot_m"], window=window,
        fell=traj.status == "fell", noise=noise,
    )


def _isnan(x) -> bool:
    return x is None or (isinstance(x, float) and math.isnan(x))
