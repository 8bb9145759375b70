r"""The process and the rig's scalings from the simple experiments of Appendices A
and B: their analyses.

* :func:`analyse_free_oscillation` - A.1-A.2, natural frequency and damping of
  the hanging pendulum (eqs. 22-25);
* :func:`analyse_control_scaling` - B.4, the control scaling :math:`k_u`
  (eq. 26);
* :func:`analyse_velocity_scale` - B.3, scale and bias of the arm-velocity
  channel;
* :func:`analyse_angle_scales` - B.1, B.2, the angle channels from a lap by
  hand.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ...model.rig import RigScaling
from .logsignals import (
    ARM_LENGTH,
    IdentificationError,
    constant_runs,
    line_fit,
    log_signal,
    log_time,
    noise_level,
)

__all__ = ["analyse_angle_scales", "analyse_control_scaling", "analyse_free_oscillation",
           "analyse_velocity_scale", "consecutive_peaks", "parabolic_peak", "unwrap_raw"]


def parabolic_peak(y: np.ndarray, i: int) -> tuple[float, float]:
    """Sub-sample offset and height of a maximum at sample i (parabola through 3 points)."""
    if i <= 0 or i >= len(y) - 1:
        return 0.0, float(y[i])
    a, b, c = y[i - 1], y[i], y[i + 1]
    den = a - 2 * b + c
    if den >= 0:
        return 0.0, float(b)
    off = 0.5 * (a - c) / den
    return float(off), float(b - 0.25 * (a - c) * off)



def consecutive_peaks(pk_t: np.ndarray, pk_y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The longest run of peaks one period apart: spacings at most 1.5 times their
    median.  A lone peak of the noise after the swing has died away (or a missing
    one) would otherwise stretch the mean spacing of eq. (24)."""
    if len(pk_t) < 3:
        return pk_t, pk_y
    ok = np.diff(pk_t) <= 1.5 * float(np.median(np.diff(pk_t)))
    best, start = (0, 0), 0
    for i, good in enumerate(ok.tolist()):
        if not good:
            start = i + 1
        elif i + 1 - start > best[1] - best[0]:
            best = (start, i + 1)
    return pk_t[best[0]:best[1] + 1], pk_y[best[0]:best[1] + 1]


def analyse_free_oscillation(log: Any, *, max_amplitude: float = 0.15,
                             min_amplitude: float | None = None) -> dict:
    r"""Natural frequency and damping from damped free oscillations (App. A.1-A.2).

    1. The rest angle :math:`\theta_0` is the median of the measured angle.
    2. Peaks of :math:`\theta - \theta_0` between ``min_amplitude`` (default
       3 noise standard deviations, at least 0.005 rad) and
       ``max_amplitude`` (the thesis discarded peaks above 0.15 rad as
       nonlinear) are located with sub-sample (parabolic) precision; the
       longest run of them one period apart is used (:func:`consecutive_peaks`:
       a lone peak of the noise after the swing has died away is not a period).
    3. Eq. (24): :math:`\omega_d = 2\pi/T` with T the mean peak spacing;
       eq. (25): the log of the peak heights is fitted by a straight line of
       slope :math:`-\zeta\omega_0`; then
       :math:`\omega_0 = \sqrt{\omega_d^2 + (\zeta\omega_0)^2}` (eq. 23).
    4. Refinement: eq. (22) (:math:`\theta_0 + A e^{-\sigma t}\cos(\omega_d t +
       \phi)`) is fitted by least squares to the samples between the first
       and the last used peak, which uses every sample rather than the
       peaks alone.

    Returns
    -------
    dict
        ``omega0``, ``zeta`` (refined), ``omega0_peaks``, ``zeta_peaks``
        (steps 1-3, the thesis's method), ``period``, ``rest_angle``,
        ``peaks`` ([t, height] of the used peaks), ``warnings`` (e.g. peak
        heights that grow instead of decaying: zeta is then 0).
    """
    t = log_time(log)
    y = log_signal(log, "theta_m")
    ok = np.isfinite(y)
    t, y = t[ok], y[ok]
    sig = noise_level(y)
    min_amp = max(0.005, 3.0 * sig) if min_amplitude is None else min_amplitude
    theta0 = float(np.median(y))
    d = y - theta0
    ys = d
    if sig > 0:
        from scipy.ndimage import uniform_filter1d

        ys = uniform_filter1d(d, size=5, mode="nearest")
    from scipy.signal import find_peaks  # heavy import, only when used

    h = float(np.median(np.diff(t)))
    idx, _ = find_peaks(ys, prominence=max(min_amp, 6.0 * sig), distance=max(1, int(0.1 / h)))
    pk_t, pk_y = [], []
    for i in idx:
        off, hy = parabolic_peak(ys, int(i))
        if min_amp <= hy <= max_amplitude:
            pk_t.append(t[i] + off * h)
            pk_y.append(hy)
    if len(pk_t) < 3:
        raise IdentificationError(
            f"only {len(pk_t)} oscillation peak(s) between {min_amp:.3g} and "
            f"{max_amplitude:g} rad; need at least 3 (is the pendulum swinging freely?)")
    pk_t, pk_y = consecutive_peaks(np.array(pk_t), np.array(pk_y))
    if len(pk_t) < 3:
        raise IdentificationError(
            f"only {len(pk_t)} consecutive oscillation peak(s) between {min_amp:.3g} and "
            f"{max_amplitude:g} rad; need at least 3 (is the pendulum swinging freely?)")
    period = float(np.mean(np.diff(pk_t)))
    wd = 2.0 * math.pi / period
    slope, _, _ = line_fit(pk_t, np.log(pk_y))
    warnings = []
    if slope > 0:
        warnings.append(
            f"the oscillation grows (peak heights rise by {100 * math.expm1(slope * period):.2g} "
            "% per period), so it is not a free decay (is the arm held, and nothing driving "
            "the pendulum?): zeta is reported as 0")
    sigma = max(0.0, -slope)
    w0_pk = math.hypot(wd, sigma)
    out = {"omega0_peaks": w0_pk, "zeta_peaks": sigma / w0_pk}
    # refinement on the samples spanning the used peaks
    m = (t >= pk_t[0] - 0.5 * period) & (t <= pk_t[-1] + 0.5 * period)
    tt, yy = t[m] - pk_t[0], y[m]

    def model(p):
        c0, amp, s, w, ph = p
        return c0 + amp * np.exp(-s * tt) * np.cos(w * tt + ph)

    p0 = [theta0, pk_y[0], sigma, wd, 0.0]
    from scipy.optimize import least_squares

    sol = least_squares(lambda p: model(p) - yy, p0, x_scale="jac")
    c0, _amp, s, w, _ = sol.x
    w, s = abs(float(w)), float(s)
    if sol.success and abs(w - wd) < 0.1 * wd and s >= 0:
        w0 = math.hypot(w, s)
        out = {"omega0": w0, "zeta": s / w0, **out, "rest_angle": float(c0)}
    else:
        out = {"omega0": w0_pk, "zeta": sigma / w0_pk, **out, "rest_angle": theta0}
    out["period"] = 2.0 * math.pi / (out["omega0"] * math.sqrt(max(0.0, 1 - out["zeta"] ** 2)))
    out["peaks"] = [[float(a), float(b)] for a, b in zip(pk_t, pk_y, strict=True)]
    out["warnings"] = warnings
    return out



def analyse_control_scaling(log: Any, *, coulomb: float = 1.5, arm_length: float = ARM_LENGTH,
                            v_range: tuple[float, float] = (0.1, 3.0),
                            nominal_u_scale: float | None = None) -> dict:
    r"""Control scaling :math:`k_u` from constant-u accelerations (App. B.4, eq. 26).

    For each run of constant nonzero u, the measured arm velocity in
    ``v_range`` (the thesis fitted :math:`\dot\Omega\in[0, 3]` rad/s; the
    lower limit keeps the in-band breakaway out) in the direction of u is
    fitted with a straight line: slope :math:`\ddot\Omega`.  With the known
    Coulomb friction :math:`F_C` (``friction.coulomb``) eq. (26) in this
    package's units, :math:`L_1\ddot\Omega = k_u u - F_C\,\mathrm{sgn}\,\dot\Omega`,
    gives :math:`k_u = (L_1\ddot\Omega + F_C)/|u|` per level; the estimate
    is their least-squares combination.  A regression of
    :math:`L_1\ddot\Omega` on u with free intercept gives :math:`k_u` and
    :math:`F_C` without the prior (``input_gain_free``, ``coulomb_free``).

    Returns
    -------
    dict
        ``input_gain`` (the plant's :math:`k_u`), ``u_scale`` (the DAC
        scaling that would make it 1: the nominal App. B value -0.022
        divided by ``input_gain``), ``levels`` (u, acceleration, k_u per
        run), ``input_gain_free``, ``coulomb_free``.
    """
    t = log_time(log)
    u = log_signal(log, "u")
    v = log_signal(log, "arm_dot_m")
    rows = []
    for a, b in constant_runs(u):
        uu = float(u[a])
        if uu == 0:
            continue
        d = math.copysign(1.0, uu)
        idx = np.arange(a, b)
        sel = idx[(d * v[idx] >= v_range[0]) & (d * v[idx] <= v_range[1])]
        if len(sel) < 6:
            continue
        acc, _, _ = line_fit(t[sel], v[sel])
        acc = d * acc
        rows.append({"u": uu, "acceleration": acc,
                     "input_gain": (arm_length * acc + coulomb) / abs(uu)})
    if not rows:
        raise IdentificationError(
            f"no run of constant u with the arm speeding through {v_range[0]:g}.."
            f"{v_range[1]:g} rad/s in its direction: nothing to fit")
    uu = np.array([abs(r["u"]) for r in rows])
    la = np.array([arm_length * r["acceleration"] for r in rows])
    k = float(np.sum(uu * (la + coulomb)) / np.sum(uu * uu))
    nominal = RigScaling().u_scale if nominal_u_scale is None else nominal_u_scale
    out: dict[str, Any] = {"input_gain": k, "u_scale": nominal / k, "levels": rows}
    if len(np.unique(uu)) >= 2:
        slope, icpt = np.polyfit(uu, la, 1)
        out["input_gain_free"] = float(slope)
        out["coulomb_free"] = float(-icpt)
    return out



def analyse_velocity_scale(log: Any, *, chunk: float = 0.25, v_min: float = 0.5) -> dict:
    r"""Scale and bias of the arm-velocity channel (App. B.3).

    The arm angle :math:`\Omega` (``arm_m``, whose scale ``rig.arm_scale`` is
    known from App. B.2) gives the true arm velocity; the raw velocity
    channel ``v`` is compared with it at several steady speeds.  The log is
    cut into chunks of ``chunk`` s of time (ticks the loop missed leave gaps;
    a chunk counts if it holds at least half its samples); in each the
    velocity is the slope of a straight line fitted to :math:`\Omega(t)` and the raw reading is the
    mean of ``v``.  A chunk counts when the arm moves faster than ``v_min``
    rad/s, the raw reading is steady (its range below 3 % of its level plus
    8 noise standard deviations) and the line fits (residual below 2 % of
    the distance travelled plus the angle's noise).  A straight line through
    the (raw, velocity) points of both directions, velocity =
    :math:`s(v + b)`, gives the scale s (``velocity_scale``) and bias b
    (``velocity_bias``) in the convention of ``rig.velocity_scale`` and
    ``rig.velocity_bias``.

    Returns
    -------
    dict
        ``velocity_scale``, ``velocity_bias``, ``points`` ([raw v, velocity]
        per chunk), ``residual_rms`` (rad/s), ``warnings``.
    """
    t = log_time(log)
    arm = log_signal(log, "arm_m")
    v = log_signal(log, "v")
    ok = np.isfinite(t) & np.isfinite(arm) & np.isfinite(v)
    t, arm, v = t[ok], arm[ok], v[ok]
    if len(t) < 16:
        raise IdentificationError("the log is too short for the velocity-scale analysis")
    h = float(np.median(np.diff(t)))
    n = max(8, round(chunk / h))
    sig_v, sig_a = noise_level(v), noise_level(arm)
    pts = []
    # chunks of time, not of samples: ticks a stalled host made the loop miss leave gaps
    # in the log; the line is fitted to the samples' own times, so a chunk with gaps
    # counts when at least half its samples are there
    edges = np.searchsorted(t, np.arange(t[0], t[-1] + h, n * h) - 0.5 * h)
    for a, b in itertools.pairwise(edges):
        if b - a < max(8, n // 2):
            continue
        tt, aa, vv = t[a:b], arm[a:b], v[a:b]
        vel, icpt, _ = line_fit(tt, aa)
        vm = float(vv.mean())
        if abs(vel) < v_min:
            continue
        if np.ptp(vv) > 0.03 * abs(vm) + 8.0 * sig_v + 1e-9:
            continue
        res = aa - (vel * tt + icpt)
        if float(np.sqrt(np.mean(res * res))) > 0.02 * abs(vel) * (tt[-1] - tt[0]) + 3 * sig_a:
            continue
        pts.append((vm, vel))
    if len(pts) < 4:
        raise IdentificationError(f"only {len(pts)} steady chunk(s) of arm motion faster "
                                  f"than {v_min:g} rad/s; the velocity-scale fit needs at "
                                  "least 4")
    p = np.array(pts)
    warnings = []
    if not (p[:, 1].min() < 0 < p[:, 1].max()):
        warnings.append("steady motion in one direction only: the bias is extrapolated")
    slope, icpt = np.polyfit(p[:, 0], p[:, 1], 1)
    res = p[:, 1] - (slope * p[:, 0] + icpt)
    return {"velocity_scale": float(slope), "velocity_bias": float(icpt / slope),
            "residual_rms": float(np.sqrt(np.mean(res * res))),
            "points": [[float(a), float(b)] for a, b in p], "warnings": warnings}



def unwrap_raw(r: np.ndarray) -> np.ndarray:
    """Undo the +-1 wrap-around of a raw angle channel (jumps of more than 1)."""
    d = np.diff(r)
    steps = np.where(d > 1.0, -2.0, np.where(d < -1.0, 2.0, 0.0))
    return r + np.concatenate([[0.0], np.cumsum(steps)])


def analyse_angle_scales(log: Any, marks: Mapping[str, float]) -> dict:
    r"""Scale and bias of the pendulum angle and scale of the arm angle (App. B.1, B.2).

    The log is the guided ``angle-scales`` run: the pendulum hanging at rest
    (``pendulum_before_*`` marks), one lap by hand, hanging at rest again
    (``pendulum_after_*``), then the arm turned exactly one lap and held
    (``arm_after_*``).  The raw channels are unwrapped (a jump of more than 1
    is the converter's wrap-around, 2 units); a lap is :math:`2\pi` rad, so

    * ``theta_scale`` = :math:`2\pi/|\Delta y|`,
    * ``theta_bias``: the hanging pendulum is at :math:`	heta = \pi`, so
      :math:`b = \pi/s_	heta - y_{hang}`, wrapped into [-1, 1) (the
      convention of ``rig.theta_bias``: :math:`	heta = s_	heta(y + b)`),
    * ``arm_scale`` = :math:`2\pi/|\Delta x|` (x before the arm's lap: its
      rest during ``pendulum_after``).

    Returns
    -------
    dict
        ``theta_scale``, ``theta_bias``, ``arm_scale``, ``pendulum_lap_raw``,
        ``arm_lap_raw``, ``warnings``.
    """
    t = log_time(log)
    y = unwrap_raw(log_signal(log, "y"))
    x = unwrap_raw(log_signal(log, "x"))
    need = ("pendulum_before_start", "pendulum_before_end", "pendulum_after_start",
            "pendulum_after_end", "arm_after_start", "arm_after_end")
    missing = [k for k in need if k not in marks]
    if missing:
        raise IdentificationError(f"the run has no {missing[0]!r} mark (is it a complete "
                                  "angle-scales run? its sidecar holds the marks)")

    def mean(sig, a, b):
        sel = (t >= marks[a]) & (t <= marks[b])
        if not sel.any():
            raise IdentificationError(f"no samples between the marks {a} and {b}")
        return float(sig[sel].mean())

    y0 = mean(y, "pendulum_before_start", "pendulum_before_end")
    y1 = mean(y, "pendulum_after_start", "pendulum_after_end")
    x0 = mean(x, "pendulum_after_start", "pendulum_after_end")
    x1 = mean(x, "arm_after_start", "arm_after_end")
    span_y, span_x = y1 - y0, x1 - x0
    if abs(span_y) < 0.5 or abs(span_x) < 1e-3:
        raise IdentificationError("no lap in the log (the readings before and after hardly "
                                  "differ)")
    ts = 2.0 * math.pi / abs(span_y)
    y_hang = (y0 + 1.0) % 2.0 - 1.0
    tb = (math.pi / ts - y_hang + 1.0) % 2.0 - 1.0
    return {"theta_scale": ts, "theta_bias": tb, "arm_scale": 2.0 * math.pi / abs(span_x),
            "pendulum_lap_raw": span_y, "arm_lap_raw": span_x, "warnings": []}

