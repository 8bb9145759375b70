r"""Limit-cycle features of the measured pendulum angle (Table 1's columns).

For each positive half-cycle of the measured angle (from an upward zero
crossing to the next downward one), as the thesis reads its plots (Table 1):

* ``peak1`` - the first local maximum,
* ``peak2`` - the last local maximum; with a single maximum, the *shoulder*
  after it, if the angle has one (below),
* ``valley`` - the minimum between the two maxima (none for a shoulder).

A maximum counts however shallow its dip, as long as it stands above the
measurement noise: its prominence (:func:`scipy.signal.find_peaks`'s
definition, compiled: the height above the higher of its two bases) must be
at least 3 noise standard deviations and :data:`REL_PROMINENCE` (10^-6) of
the half-cycle's height.  That floor is what a noise-free run needs: the
simulator's angle has no secondary maximum below 10^-3 of the height in any
run of the thesis's tables, and rounding is at 10^-16.

A *shoulder* is a local minimum of the slope's magnitude between the first
peak and the fall, with no valley: the angle keeps falling but slows down and
steepens again (the second peak of a double top whose dip has filled in).
With the slope taken as the difference of consecutive samples, it is a local
maximum of ``-|slope|`` after the maximum whose prominence is at least 3
standard deviations of a difference's noise and :data:`REL_PROMINENCE` of the
steepest descent; the highest one gives ``peak2`` (the angle where the
descent is least steep) and ``valley`` stays missing.

A half-cycle with neither contributes ``peak1`` only.  Each feature is
averaged over the half-cycles inside the analysis window that have it; a
feature no half-cycle has is reported as ``None``.  ``period`` is the mean
spacing of upward zero crossings (linearly interpolated); ``max_u`` and
``max_arm_velocity`` are the maxima of ``|u|`` and ``|measured arm
velocity|``; ``peak_to_peak`` is max - min of the measured angle.  The same
figures for the negative half-cycles (of ``-theta``) are returned as
``neg_peak1``/``neg_peak2``/``neg_valley``, a symmetry check.

Zero crossings use a small hysteresis so that noise and quantisation steps do
not count as crossings.  With a known measurement-noise level (``noise > 0``)
the angle is first smoothed by a 9-sample centred moving average (45 ms at
h = 5 ms), which also removes the upward bias noise gives a raw maximum; a
shoulder's slope prominence must then exceed 3 times
:math:`\sqrt2\,\sigma/3`, the noise of the difference of two 9-sample means
(the difference of consecutive averaged samples is less noisy,
:math:`\sqrt2\,\sigma/9`, but a fall holds dozens of them and the largest
of their wiggles passes 3 of those).

This is the one definition: ``simulate``, ``features`` (run logs), sweeps,
fits, ``reproduce``, ``predict`` and the console all reduce a run through
:func:`features_kernel` (the batch evaluator calls it compiled, the others
through :func:`features`).

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

__all__ = ["FEATURES", "LimitCycleFeatures", "comparable", "features", "trajectory_features"]

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


def crossings(t: np.ndarray, y: np.ndarray, hyst: float):
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
def _shoulder(seg, p, min_prominence):
    """The shoulder after the maximum at ``p`` of ``seg``: ``(index, value)`` or ``(-1, nan)``.

    A shoulder is a local minimum of the slope's magnitude on the way down
    from the maximum (the descent slows, then steepens again) that is not a
    valley: the angle keeps falling through it.  The slope is the first
    difference ``d[j] = seg[j + 1] - seg[j]``; a shoulder is a local maximum of
    ``-|d|`` after ``p`` whose prominence (:func:`scipy.signal.find_peaks`'s
    definition, the segment's ends not counting as peaks) is at least
    ``min_prominence`` (rad per sample).  Its value is the highest angle (the
    mean of a difference's two samples) over the stretch that follows it
    while the slope's magnitude stays within ``min_prominence`` of its
    minimum: under noise, a dip too shallow to count is such a flat stretch,
    from its bottom over its second top, and the shoulder is that top.  Of
    several shoulders, the highest; its index is where its stretch starts.
    """
    n = len(seg) - p - 1  # differences after the maximum
    if n < 3:
        return -1, np.nan
    w = np.empty(n)
    for j in range(n):
        w[j] = -abs(seg[p + j + 1] - seg[p + j])
    best = -1
    best_value = -np.inf
    i = 1
    while i < n - 1:
        if w[i - 1] < w[i]:
            k = i + 1
            while k < n and w[k] == w[i]:
                k += 1
            if k < n and w[k] < w[i]:
                c = (i + k - 1) // 2
                hc = w[c]
                left_min = hc
                q = c - 1
                while q >= 0 and w[q] <= hc:
                    left_min = min(left_min, w[q])
                    q -= 1
                right_min = hc
                q = c + 1
                while q < n and w[q] <= hc:
                    right_min = min(right_min, w[q])
                    q += 1
                if hc - max(left_min, right_min) >= min_prominence:
                    # the flat stretch that follows, within the prominence of the
                    # least steep slope: its highest point is the shoulder's
                    value = seg[p + c] + seg[p + c + 1]
                    q = c + 1
                    while q < n and w[q] >= hc - min_prominence:
                        value = max(value, seg[p + q] + seg[p + q + 1])
                        q += 1
                    if value > best_value:
                        best, best_value = c, value
            i = k
        else:
            i += 1
    if best < 0:
        return -1, np.nan
    return p + best, 0.5 * best_value


@jit
def _half_cycle_kernel(y, starts, ends, noise, rel_prominence, slope_noise):
    """peak1, peak2 and valley of each half-cycle ``y[starts[c]:ends[c]]`` (nan: none).

    A maximum counts when its prominence is at least ``rel_prominence`` times
    the half-cycle's height and 3 noise standard deviations (``noise``); with
    a single maximum, a shoulder after it (:func:`_shoulder`, its slope
    prominence at least ``rel_prominence`` times the steepest descent and 3
    ``slope_noise``) is ``peak2``, with no valley.
    """
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
        else:
            steepest = 0.0
            for j in range(idx[0], len(seg) - 1):
                steepest = max(steepest, seg[j] - seg[j + 1])
            slope_prom = max(rel_prominence * steepest, 3.0 * slope_noise, 1e-15)
            _, value = _shoulder(seg, idx[0], slope_prom)
            p2[c] = value
    return p1, p2, va


@jit
def _half_cycles(starts, ends):
    """Pair each crossing in ``starts`` with the first crossing in ``ends`` after it
    (both sorted sample indices); starts with no later end are dropped."""
    a = np.empty(len(starts), dtype=np.int64)
    b = np.empty(len(starts), dtype=np.int64)
    m = 0
    j = 0
    for s in starts:
        while j < len(ends) and ends[j] <= s:
            j += 1
        if j == len(ends):
            break
        a[m] = s
        b[m] = ends[j]
        m += 1
    return a[:m], b[:m]


@jit
def _block_sum(a, lo, n):
    """numpy's pairwise summation of ``a[lo:lo + n]`` for n <= 128 (eight accumulators)."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - (n % 8):
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@jit
def _pairwise_sum(a):
    """``a.sum()`` in numpy's pairwise order, bit for bit (halves of whole blocks
    of 8 down to 128 entries, :func:`_block_sum`); without recursion, which
    numba's on-disk cache does not handle."""
    n = len(a)
    if n <= 128:
        return _block_sum(a, 0, n)
    # post-order walk of numpy's split tree: tasks (lo, n, combine?), partial sums
    t_lo = np.empty(256, dtype=np.int64)
    t_n = np.empty(256, dtype=np.int64)
    t_c = np.empty(256, dtype=np.int64)
    vals = np.empty(128)
    nt = 1
    nv = 0
    t_lo[0], t_n[0], t_c[0] = 0, n, 0
    while nt > 0:
        nt -= 1
        lo, m, c = t_lo[nt], t_n[nt], t_c[nt]
        if c == 1:
            nv -= 1
            vals[nv - 1] = vals[nv - 1] + vals[nv]
        elif m <= 128:
            vals[nv] = _block_sum(a, lo, m)
            nv += 1
        else:
            m2 = m // 2
            m2 -= m2 % 8
            t_lo[nt], t_n[nt], t_c[nt] = 0, 0, 1
            t_lo[nt + 1], t_n[nt + 1], t_c[nt + 1] = lo + m2, m - m2, 0
            t_lo[nt + 2], t_n[nt + 2], t_c[nt + 2] = lo, m2, 0
            nt += 3
    return vals[0]


@jit
def _finite_mean(values):
    """Mean of the finite entries (the half-cycles that have the feature), or nan."""
    v = values[np.isfinite(values)]
    if len(v) == 0:
        return np.nan
    return _pairwise_sum(v) / len(v)


@jit
def _abs_max(a):
    """``max |a|`` (nan if any entry is nan, as numpy's max)."""
    m = -np.inf
    for x in a:
        if np.isnan(x):
            return np.nan
        ax = abs(x)
        if ax > m:
            m = ax
    return m


@jit
def _moving_average(y, size):
    """Centred ``size``-sample moving average, the ends extended with the end values
    (``scipy.ndimage.uniform_filter1d(y, size, mode="nearest")`` up to rounding)."""
    n = len(y)
    s1 = size // 2
    out = np.empty(n)
    for i in range(n):
        acc = 0.0
        for k in range(i - s1, i - s1 + size):
            acc += y[min(max(k, 0), n - 1)]
        out[i] = acc / size
    return out


#: Default smallest prominence of a maximum, relative to its half-cycle's height (and
#: of a shoulder, relative to the steepest descent after the maximum): the floor
#: of a noise-free run, far above the simulator's rounding and far below any dip
#: it produces (docs/cli.md, "Features").  Measured noise raises it.
REL_PROMINENCE = 1e-6
#: Default peak-to-peak (rad) below which the loop counts as settled.
SETTLE_TOL = 2e-3
#: Default moving-average length (samples) for noisy measurements.
SMOOTH = 9

#: Status codes of :func:`features_kernel`.
ST_LIMIT_CYCLE, ST_SETTLED, ST_FELL = 0, 1, 2
STATUS_CODES = ("limit_cycle", "settled", "fell")
#: Value order of :func:`features_kernel`'s result (nan = None).
KERNEL_VALUES = ("peak1", "peak2", "valley", "period", "max_u", "max_arm_velocity",
                 "peak_to_peak", "neg_peak1", "neg_peak2", "neg_valley")


@jit
def features_kernel(t, y, u, v, span, fell, noise, rel_prominence, settle_tol, smooth):
    """The features of :func:`features`, compiled (also run by the batch evaluator).

    ``u`` and ``v`` of length 0 stand for "not given".  Returns ``(status code,
    values, cycles)`` with ``values`` in :data:`KERNEL_VALUES` order, nan where
    undefined.
    """
    vals = np.full(10, np.nan)
    empty_code = ST_FELL if fell else ST_SETTLED
    n = len(t)
    if n < 3:
        return empty_code, vals, 0
    # the window: the samples with t >= t[-1] - span; for increasing t (every
    # run's) a tail of the arrays, taken as views (no copies)
    thr = t[n - 1] - span - 1e-12
    j = n
    while j > 0 and t[j - 1] >= thr:
        j -= 1
    tail = True
    for i in range(j):
        if t[i] >= thr:
            tail = False
            break
    if tail:
        tw = t[j:]
        yw = y[j:]
        uw = u[j:] if len(u) > 0 else u
        vw = v[j:] if len(v) > 0 else v
    else:
        m = t >= thr
        tw = t[m]
        yw = y[m]
        uw = u[m] if len(u) > 0 else u
        vw = v[m] if len(v) > 0 else v
    finite = True
    for x in yw:
        if not np.isfinite(x):
            finite = False
            break
    if not finite:
        keep = np.isfinite(yw)
        tw = tw[keep]
        yw = yw[keep]
        if len(yw) < 3:
            return empty_code, vals, 0
    # the noise of one sample-to-sample difference of the angle searched
    slope_noise = math.sqrt(2.0) * noise
    if noise > 0.0 and len(yw) >= smooth:
        # noisy measurements: a short centred moving average (default 9 samples,
        # 45 ms at h = 5 ms, far shorter than any limit cycle) before peak search;
        # a difference of the average is (y[i + smooth] - y[i]) / smooth, of noise
        # sqrt(2) noise / smooth; a fall holds dozens of them, and the largest of so
        # many independent wiggles would pass 3 of those: the shoulder has to stand
        # out from sqrt(2) noise / sqrt(smooth) (the noise of a difference of
        # means of smooth samples each)
        yw = _moving_average(yw, smooth)
        slope_noise = math.sqrt(2.0) * noise / math.sqrt(smooth)
    ptp = yw.max() - yw.min()
    if len(u) > 0:
        vals[4] = _abs_max(uw)
    if len(v) > 0:
        vals[5] = _abs_max(vw)
    vals[6] = ptp
    hyst = max(0.02 * 0.5 * ptp, 3.0 * noise)
    up_t, up_i, _dn_t, dn_i = _crossings_kernel(tw, yw, hyst)
    nup = len(up_t)
    if fell:
        # a falling run has no cycle shape: only the extremes are meaningful
        return ST_FELL, vals, 0
    if nup >= 2:
        d = np.empty(nup - 1)
        for i in range(nup - 1):
            d[i] = up_t[i + 1] - up_t[i]
        vals[3] = _pairwise_sum(d) / (nup - 1)
    # positive half-cycles: an upward crossing followed by the next downward one
    a, b = _half_cycles(up_i, dn_i)
    p1, p2, va = _half_cycle_kernel(yw, a, b, noise, rel_prominence, slope_noise)
    a, b = _half_cycles(dn_i, up_i)
    n1, n2, nv = _half_cycle_kernel(-yw, a, b, noise, rel_prominence, slope_noise)
    vals[0] = _finite_mean(p1)
    vals[1] = _finite_mean(p2)
    vals[2] = _finite_mean(va)
    vals[7] = _finite_mean(n1)
    vals[8] = _finite_mean(n2)
    vals[9] = _finite_mean(nv)
    cycles = 0
    for x in p1:
        if np.isfinite(x):
            cycles += 1
    if ptp < settle_tol or (nup < 2 and ptp < 10.0 * noise):
        # at rest, or no cycle and no more motion than the noise drives
        return ST_SETTLED, vals, cycles
    return ST_LIMIT_CYCLE, vals, cycles


def _from_kernel(code: int, vals: np.ndarray, cycles: int) -> LimitCycleFeatures:
    """:class:`LimitCycleFeatures` from :func:`features_kernel`'s result."""
    f = [None if math.isnan(x) else float(x) for x in vals]
    return LimitCycleFeatures(STATUS_CODES[code], *f[:7], *f[7:], int(cycles))


def features(
    t,
    theta,
    u=None,
    arm_velocity=None,
    *,
    window: float | None = None,
    fell: bool = False,
    noise: float = 0.0,
    rel_prominence: float = REL_PROMINENCE,
    settle_tol: float = SETTLE_TOL,
    smooth: int = SMOOTH,
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
    t = np.ascontiguousarray(t, dtype=float)
    y = np.ascontiguousarray(theta, dtype=float)
    if t.shape != y.shape or t.ndim != 1:
        raise ValueError("t and theta must be 1-D arrays of equal length")
    n = len(t)
    if n < 3:
        return LimitCycleFeatures("fell" if fell else "settled", *([None] * 7))
    span = window if window is not None else 0.5 * (t[-1] - t[0])
    if not span > 0:
        raise ValueError(f"window must be > 0 s, got {window}")
    none = np.empty(0)
    us, vs = (none if a is None else np.ascontiguousarray(a, dtype=float)
              for a in (u, arm_velocity))
    for name, a in (("u", us), ("arm_velocity", vs)):
        if a is not none and a.shape != t.shape:
            raise ValueError(f"{name} must have the length of t ({n}), got {a.shape}")
    return _from_kernel(*features_kernel(t, y, us, vs, float(span), bool(fell), float(noise),
                                          float(rel_prominence), float(settle_tol),
                                          int(smooth)))


def trajectory_features(traj, window: float | None = None) -> LimitCycleFeatures:
    """:func:`features` of a :class:`frictionlab.model.simulation.Trajectory`."""
    noise = traj.noise
    if len(traj) < 3:
        return LimitCycleFeatures("fell" if traj.status == "fell" else "settled", *([None] * 7))
    if window is not None and traj.config is not None and traj.status != "fell":
        window = min(window, traj.t[-1])
    return features(
        traj.t, traj["theta_m"], traj["u"], traj["arm_dot_m"], window=window,
        fell=traj.status == "fell", noise=noise,
    )


def comparable(values, name: str) -> float | None:
    """Feature ``name`` of ``values`` (a mapping of feature names) as compared with
    a measured one: a missing ``valley`` is the ``peak2`` (a shoulder), a missing
    ``peak2`` or ``valley`` the ``peak1`` (a single maximum): each the limit of a
    dip that has just filled in.  ``None`` where even that is missing."""

    def get(n):
        v = values.get(n)
        return None if v is None or not math.isfinite(float(v)) else float(v)

    v = get(name)
    if v is None and name == "valley":
        v = get("peak2")
    if v is None and name in ("peak2", "valley"):
        v = get("peak1")
    return v


def _isnan(x) -> bool:
    return x is None or (isinstance(x, float) and math.isnan(x))
