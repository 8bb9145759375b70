r"""Friction from the simple experiments of Appendix E: their analyses.

* :func:`analyse_stiction` - E.1, stiction and Coulomb friction per direction
  from a staircase of constant u and sliding runs below the breakaway level;
* :func:`analyse_stribeck` - E.2, the Stribeck curve from steady velocity
  control (:func:`stribeck_model`, eq. 18's steady state).

Friction levels are in the plant's units (m/s^2 of arm-tip acceleration, like
u).  At rest or at constant speed the friction balances the force the plant
receives, :math:`k_u u` (eq. 5), so the analyses multiply the logged u by the
*assumed* control scaling ``input_gain`` (``plant.input_gain``, 1 by
default), as App. E.1 divided its DAC readings by :math:`|k_u|`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...io.notes import Note
from ...model.friction import stribeck_magnitude
from .logsignals import (
    ARM_LENGTH,
    IdentificationError,
    constant_runs,
    line_fit,
    log_signal,
    log_time,
    noise_level,
    ordered,
    quantum,
)

__all__ = ["analyse_stiction", "analyse_stribeck", "fit_stribeck", "steady_points",
           "stribeck_model"]


def analyse_stiction(log: Any, *, input_gain: float = 1.0, arm_length: float = ARM_LENGTH,
                     v_detect: float | None = None, v_slide: float | None = None) -> dict:
    r"""Stiction and Coulomb friction per direction (App. E.1).

    Stiction (per direction d): the first sample where the arm speed d
    :math:`\dot\Omega` exceeds ``v_detect`` while d u > 0 marks the breakaway;
    the stiction is the largest d u applied before it, less half the
    staircase step (the true level lies within the last step).  The step is
    the median increment between the staircase's levels.  When the arm
    breaks away at the staircase's first level L, the log bounds the
    stiction only from above: it lies in (0, L] (u was 0 before the
    staircase).  The estimate is then L/2 and a warning says so.

    Coulomb (per direction): every run of constant u with d u > 0 below the
    breakaway level during which the arm slides in direction d faster than
    ``v_slide`` gives the acceleration a by a straight-line fit of the
    measured arm velocity; eq. (5) :math:`L_1 a = k_u u - F_C` then gives
    :math:`F_C = k_u u - L_1 a`, averaged over the runs (weighted by their
    length).  Decelerating and accelerating runs both count: the Coulomb
    level is where the fitted acceleration crosses zero, which is the
    thesis's "smallest u that keeps the arm moving".

    Returns
    -------
    dict
        ``stiction``, ``coulomb`` (means of both directions) and
        ``stiction_positive``, ``stiction_negative``, ``coulomb_positive``,
        ``coulomb_negative``, ``breakaway_time_positive/negative``,
        ``segments`` (per sliding run: direction, u, acceleration, friction),
        ``warnings``.
    """
    t = log_time(log)
    u = log_signal(log, "u")
    v = log_signal(log, "arm_dot_m")
    sig = noise_level(v)
    v_detect = max(0.1, 6.0 * sig) if v_detect is None else v_detect
    v_slide = max(0.2, 6.0 * sig) if v_slide is None else v_slide
    out: dict[str, Any] = {}
    segments = []
    warnings = []
    for d, name in ((1.0, "positive"), (-1.0, "negative")):
        drive = d * u > 0
        moving = d * v > v_detect
        hits = np.flatnonzero(drive & moving)
        if len(hits) == 0:
            raise IdentificationError(f"no breakaway in the {name} direction: the arm never "
                                      f"moved faster than {v_detect:g} rad/s under d*u > 0")
        k = int(hits[0])
        # the staircase leading to the breakaway: same-sign u before k
        j = k
        while j > 0 and drive[j - 1]:
            j -= 1
        stair = d * u[j:k + 1]
        levels = np.unique(stair)
        level = float(stair.max())
        if len(levels) > 1:
            step = float(np.median(np.diff(levels)))
        else:
            # breakaway at the first level: u rose from 0 to it in one step
            step = level
            warnings.append(Note(
                f"the arm broke away at the first level of the {name} staircase "
                f"(u = {d * level:g}): the stiction is only known to be at most "
                f"{input_gain * level:.4g}; reported as half of that.  Repeat with a "
                "smaller staircase step", "step"))
        stiction = input_gain * (level - 0.5 * step)
        out[f"stiction_{name}"] = stiction
        out[f"breakaway_time_{name}"] = float(t[k])
        # Coulomb: constant-u runs below the breakaway level with sliding (the
        # staircase's levels below it leave the arm at rest)
        est, wts = [], []
        for a, b in constant_runs(u):
            uu = float(u[a])
            if not 0 < d * uu < level:
                continue
            idx = np.arange(a + 1, b)  # the first sample may hold the push
            idx = idx[d * v[idx] > v_slide]
            if len(idx) < 8:
                continue
            acc, _, _ = line_fit(t[idx], v[idx])
            f = d * (input_gain * uu - arm_length * acc)
            est.append(f)
            wts.append(len(idx))
            segments.append({"direction": name, "u": uu, "acceleration": acc,
                             "friction": f, "t0": float(t[idx[0]]), "t1": float(t[idx[-1]])})
        if not est:
            raise IdentificationError(f"no sliding run below the breakaway level in the "
                                      f"{name} direction: cannot estimate Coulomb friction")
        out[f"coulomb_{name}"] = float(np.average(est, weights=wts))
    out["stiction"] = 0.5 * (out["stiction_positive"] + out["stiction_negative"])
    out["coulomb"] = 0.5 * (out["coulomb_positive"] + out["coulomb_negative"])
    out["segments"] = segments
    out["warnings"] = warnings
    return ordered(out, ("stiction", "coulomb", "stiction_positive", "stiction_negative",
                          "coulomb_positive", "coulomb_negative"))



def stribeck_model(v: np.ndarray, coulomb: float, stiction: float, viscous: float,
                   stribeck_velocity: float) -> np.ndarray:
    r"""Steady-state friction magnitude at speed :math:`|v|` (the curve of eq. 18):
    :math:`F_C + (F_S - F_C)e^{-(v/v_S)^2} + F_v|v|`."""
    a = np.abs(np.asarray(v, dtype=float))
    return stribeck_magnitude(a, coulomb, stiction, stribeck_velocity) + viscous * a


def steady_points(t, u, v, chunk: float, v_min: float) -> np.ndarray:
    """(mean v, mean u, samples) of every steady chunk of the log.

    A chunk is steady when neither signal moves over it by more than its
    measurement noise allows: the peak-to-peak range of the arm velocity
    stays below 2 % of its level plus 8 noise standard deviations, that of u
    below 5 % plus 8 (the noise levels come from second differences of the
    whole log, which a few reference steps do not disturb).  This rejects
    the chunks holding a reference step and the transient after it.
    """
    h = float(np.median(np.diff(t)))
    n = max(8, round(chunk / h))
    # noise, and the converters' resolution (a quantised signal at rest has no second
    # differences but its steps; under a P loop u moves in steps of gain x quantum)
    tol_v = 8.0 * noise_level(v) + 2.0 * quantum(v) + 1e-9
    tol_u = 8.0 * noise_level(u) + 2.0 * quantum(u) + 1e-9
    pts = []
    for a in range(0, len(t) - n + 1, n):
        s = slice(a, a + n)
        vv, uu = v[s], u[s]
        vm, um = float(vv.mean()), float(uu.mean())
        if abs(vm) < v_min or np.mean(np.sign(vv) != np.sign(vm)) > 0.05:
            continue
        if np.ptp(vv) > 0.02 * abs(vm) + tol_v:
            continue
        if np.ptp(uu) > 0.05 * abs(um) + tol_u:
            continue
        pts.append((vm, um, n))
    return np.array(pts).reshape(-1, 3)


def fit_stribeck(v: np.ndarray, f: np.ndarray) -> tuple[dict, list[str]]:
    """Least-squares fit of :func:`stribeck_model` to (|v|, |F|) points."""
    a, fa = np.abs(v), np.abs(f)
    order = np.argsort(a)
    a, fa = a[order], fa[order]
    hi = a >= np.median(a)
    fv0 = max(0.0, np.polyfit(a[hi], fa[hi], 1)[0]) if hi.sum() >= 2 else 0.0
    fc0 = max(1e-3, float(np.min(fa - fv0 * a)))
    fs0 = max(fc0, float(fa[0] - fv0 * a[0]))
    vs0 = max(0.1, float(a[0]))

    def res(p):
        return stribeck_model(a, *p) - fa

    lo = [0.0, 0.0, 0.0, 1e-3]
    hi_b = [np.inf, np.inf, np.inf, np.inf]
    x0 = np.clip([fc0, fs0 * 1.05 + 1e-3, fv0, vs0], np.array(lo) + 1e-9, None)
    from scipy.optimize import least_squares  # heavy import, only when used

    sol = least_squares(res, x0, bounds=(lo, hi_b), x_scale="jac")
    fc, fs, fv, vs = (float(x) for x in sol.x)
    warnings = []
    if a.min() > 3.0 * vs or fs - fc < 0.01 * fc:
        # no Stribeck rise within the measured speeds: F_S and v_S are not
        # determined; fit the Coulomb + viscous line alone
        fv, fc = (float(x) for x in np.polyfit(a, fa, 1))
        fv = max(fv, 0.0)
        warnings.append(f"no Stribeck rise above the Coulomb level at the measured speeds "
                        f"(lowest {a.min():.2g} rad/s): stiction and stribeck_velocity are "
                        "not identifiable from this curve (App. E.2 had the same "
                        "limitation); fitted Coulomb + viscous only")
        return {"coulomb": fc, "viscous": fv, "stribeck_velocity": None,
                "stiction": None}, warnings
    if a.min() > 2.0 * vs:
        warnings.append(f"no steady point below {a.min():.2g} rad/s, about twice the "
                        f"fitted Stribeck velocity {vs:.2g}: stiction and stribeck_velocity "
                        "are extrapolated (App. E.2 had the same limitation)")
    return {"coulomb": fc, "viscous": fv, "stribeck_velocity": vs, "stiction": fs}, warnings


def analyse_stribeck(log: Any, *, input_gain: float = 1.0, chunk: float = 0.25,
                     v_min: float = 0.05) -> dict:
    r"""Stribeck curve from steady velocity-control runs (App. E.2).

    The log is cut into chunks of ``chunk`` s; a chunk is steady when
    neither the measured arm velocity nor u moves over it by more than a few
    percent plus their measurement noise (see :func:`steady_points`).
    At constant velocity eq. (5) gives friction = :math:`k_u u`; the steady
    points (both directions, as magnitudes) are fitted with
    :func:`stribeck_model` by least squares.  Per-direction fits are added
    when each direction has at least 4 steady velocities.

    Returns
    -------
    dict
        ``coulomb``, ``viscous``, ``stribeck_velocity``, ``stiction`` (the
        curve's level at zero speed), per-direction ``*_positive``/
        ``*_negative``, ``points`` ([v, friction] per steady chunk) and
        ``warnings``.
    """
    t = log_time(log)
    u = log_signal(log, "u")
    v = log_signal(log, "arm_dot_m")
    pts = steady_points(t, u, v, chunk, v_min)
    if len(pts) < 4:
        raise IdentificationError(f"only {len(pts)} steady chunk(s) of constant arm velocity "
                                  "in the log; the Stribeck fit needs at least 4")
    vv, ff = pts[:, 0], input_gain * pts[:, 1]
    est, warnings = fit_stribeck(vv, ff)
    out: dict[str, Any] = dict(est)
    for d, name in ((1.0, "positive"), (-1.0, "negative")):
        sel = d * vv > 0
        speeds = np.unique(np.round(np.abs(vv[sel]), 1))
        if len(speeds) >= 4:
            e, _ = fit_stribeck(vv[sel], ff[sel])
            for k, val in e.items():
                out[f"{k}_{name}"] = val
    out["points"] = [[float(a), float(b)] for a, b in zip(vv, ff, strict=True)]
    out["warnings"] = warnings
    return ordered(out, ("coulomb", "viscous", "stribeck_velocity", "stiction"))

