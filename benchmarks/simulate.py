r"""Simulator benchmark: compiled closed loop vs a plain scipy ``solve_ivp`` loop.

Measures, single-threaded and side by side in one process:

* ``classical_ms`` - a 30 s closed-loop run of
  :func:`frictionlab.model.simulation.simulate_config` with the fast design and the
  classical friction model eq. (17) at eq. (20)'s F_S = 2.3, F_C = 1.5, with
  the zero-velocity band 0.03 rad/s the thesis needed for stiction (Sec. 5.2);
* ``lugre_ms`` - the same with the LuGre plant friction at its defaults,
  eq. (21) (F_S 2.3, F_C 1.5, F_v 0.07, sigma0 100, sigma1 5, v_S 1) and the
  plant's observer gain k = 0 (plain eq. 18, the default);
* ``lugre_k1_ms`` - the same with eq. (21)'s k = 1 acting in the plant
  (eq. 19, e = -theta), and ``lugre_k1_cost`` = ``lugre_k1_ms / lugre_ms``;
* ``scipy_ms`` - the classical case with :func:`scipy_closed_loop` below: the
  same controller (:func:`frictionlab.model.controller.controller_step`, the code
  :meth:`Controller.step` runs), the same plant (:func:`frictionlab.model.plants.thesis.rhs`
  with the friction of :mod:`frictionlab.model.friction` evaluated inside the
  right-hand side), u held over each sample, ``solve_ivp`` (RK45, rtol 1e-6,
  scipy's default atol 1e-6) restarted every sample, timed over the full 30 s
  by default (``--scipy-duration`` shortens the timed span; the time is then
  scaled linearly to 30 s, and the output says so);
* ``speedup_vs_scipy`` - ``scipy_ms / classical_ms``;
* ``feature_error_vs_fine`` - the largest relative difference of the seven
  limit-cycle features (:data:`frictionlab.model.limit_cycles.FEATURES`) between a
  run with the default integration steps (``sim.substeps`` and
  ``sim.pendulum_steps``) and one with 20 times as many of both, over both
  friction models and both designs, LuGre with sigma0 = 1000 (the stiff
  bristle) and LuGre with k = 1 (eq. 19), as a fraction (0.005 = 0.5%).

It also prints the features of the scipy run next to the compiled run's (an
independent check of the compiled integrator over the whole 30 s), and
``sampled_angle_effect``: the largest relative feature difference when
eq. (19)'s error e = -theta uses the angle sampled at each tick and held
instead of the continuous angle (both with the scipy loop; LuGre eq. (21),
fast design with k = 1 and 2, slow design with k = 1), as a fraction.

Timings are the minimum of ``--repeats`` runs after a warm-up run (numba
compilation) - the least disturbed run on a shared machine; the medians are
printed alongside; BLAS/OpenMP/numba thread pools are pinned to one thread before
numpy is imported.  The last printed line is a JSON object.

Usage::

    .venv/bin/python benchmarks/simulate.py [--repeats 15] [--scipy-duration 30]
"""

from __future__ import annotations

import os

if __name__ == "__main__":  # single-threaded; set before numpy/numba load (not on import)
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                 "NUMBA_NUM_THREADS"):
        os.environ[_var] = "1"

import argparse
import json
import statistics
import time

import numpy as np
from scipy.integrate import solve_ivp

from frictionlab.config import Config, build_config
from frictionlab.model.controller import controller_step
from frictionlab.model.friction import classical_force, lugre_dz, lugre_force
from frictionlab.model.limit_cycles import FEATURES, features, trajectory_features
from frictionlab.model.plants.thesis import rhs
from frictionlab.runs import make_controller, simulate_config

DURATION = 30.0
#: Sec. 5.2: the band the thesis widened to 0.03 rad/s to see stiction.
CLASSICAL_SETS = ("friction.zero_velocity_band=0.03",)
FINE_FACTOR = 20
#: LuGre plants (design, k) on which the sampled angle in eq. (19) is compared.
SAMPLED_ANGLE_CASES = (("fast", 1.0), ("fast", 2.0), ("slow", 1.0))
RTOL = 1e-6


def classical_config(design: str = "fast", extra: tuple[str, ...] = ()) -> Config:
    """Classical friction eq. (17) with eq. (20)'s levels, band 0.03."""
    return build_config(design, "classical", sets=[*CLASSICAL_SETS, *extra])


def lugre_config(design: str = "fast", extra: tuple[str, ...] = ()) -> Config:
    """LuGre plant friction at its defaults (eq. 21)."""
    return build_config(design, "lugre", sets=list(extra))


#: The convergence cases: (name, configuration).
CONVERGENCE = (
    ("classical fast", classical_config("fast")),
    ("lugre fast", lugre_config("fast")),
    ("classical slow", classical_config("slow")),
    ("lugre slow", lugre_config("slow")),
    ("lugre fast sigma0 1000", lugre_config("fast", ("friction.sigma0=1000",))),
    ("lugre slow sigma0 1000", lugre_config("slow", ("friction.sigma0=1000",))),
    ("lugre fast k 1", lugre_config("fast", ("friction.observer_gain=1",))),
    ("lugre slow k 1", lugre_config("slow", ("friction.observer_gain=1",))),
)


def scipy_closed_loop(cfg: Config, duration: float, rtol: float = RTOL,
                      angle: str = "continuous") -> dict:
    """The closed loop of ``cfg`` with ``solve_ivp`` restarted every sample.

    Supports the ``none``, ``classical`` and ``lugre`` plant friction models,
    without measurement noise or quantisation.  Classical friction eq. (17) is
    evaluated inside the right-hand side from the current arm velocity and the
    applied force ``k_u u`` (with ``cfg``'s zero-velocity band); LuGre adds the
    bristle deflection z as a 5th state with eq. (19)'s error e = -theta (the
    plain eq. (18) when the plant's observer gain k is 0): with ``angle =
    "continuous"`` (frictionlab's plant) the angle inside the right-hand side,
    with ``"sampled"`` the angle at the sample's start, held over the sample
    (what a discrete controller sees).

    Returns
    -------
    dict
        ``t``, ``theta_m``, ``u``, ``arm_dot_m`` (one entry per tick, the
        measurement taken and the control applied at that tick), ``status``
        (``"ok"`` or ``"fell"``) and ``ticks``.
    """
    kind = cfg.friction_kind
    if kind not in ("none", "classical", "lugre"):
        raise ValueError(f"scipy baseline supports friction none, classical, lugre; got {kind!r}")
    if angle not in ("continuous", "sampled"):
        raise ValueError(f"angle must be 'continuous' or 'sampled', got {angle!r}")
    if cfg.sim.noise > 0.0 or cfg.sim.quantization > 0.0:
        raise ValueError("scipy baseline runs without measurement noise and quantisation")
    ctrl = make_controller(cfg)
    gp, cp = ctrl.record()
    pp = cfg.plant
    fp = cfg.friction.record()
    h = cfg.design.h
    n = round(duration / h)
    ku = pp.input_gain

    if kind == "classical":
        def f(t, x, u, th_s):
            fr = classical_force(x[3], ku * u, fp)
            return rhs(t, x, (u, fr), pp)
    elif kind == "lugre":
        def f(t, x, u, th_s):
            dz = lugre_dz(x[3], x[4], -(x[0] if angle == "continuous" else th_s), fp)
            dx = rhs(t, x, (u, lugre_force(x[3], x[4], dz, fp)), pp)
            dx[4] = dz
            return dx
    else:
        def f(t, x, u, th_s):
            return rhs(t, x, u, pp)

    x = np.zeros(5 if kind == "lugre" else 4)
    x[0] = cfg.sim.initial_angle
    s = ctrl.init(cfg.sim.initial_angle)
    theta_m = np.empty(n)
    u_log = np.empty(n)
    armd_log = np.empty(n)
    status = "ok"
    k = 0
    while k < n:
        theta_m[k], armd_log[k] = x[0], x[3]
        u, _u_fb, _f_hat = controller_step(s, gp, cp, x[0], x[2], x[3])
        u_log[k] = u
        sol = solve_ivp(f, (k * h, (k + 1) * h), x, method="RK45", rtol=rtol, args=(u, x[0]))
        x = sol.y[:, -1]
        k += 1
        if not abs(x[0]) <= cfg.sim.fall_angle or not np.all(np.isfinite(x)):
            status = "fell"
            break
    return {"t": np.arange(k) * h, "theta_m": theta_m[:k], "u": u_log[:k],
            "arm_dot_m": armd_log[:k], "status": status, "ticks": k}


def _time_ms(fn, repeats: int, warmup=None) -> tuple[float, float]:
    """(min, median) wall time of ``fn`` in ms over ``repeats`` calls after a warm-up."""
    (warmup or fn)()  # warm-up: numba compilation / cache load
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * min(times), 1e3 * statistics.median(times)


def _rel_errors(coarse, fine) -> dict[str, float]:
    out = {}
    for name in FEATURES:
        a, b = getattr(coarse, name), getattr(fine, name)
        if a is None or b is None:
            out[name] = 0.0 if a is None and b is None else float("inf")
        else:
            out[name] = abs(a - b) / abs(b) if b != 0 else abs(a - b)
    return out


def convergence(base: Config, duration: float = DURATION
                ) -> tuple[dict[str, float], object, object]:
    """Relative feature differences between the default integration steps and
    20 times as many (arm substeps and pendulum steps)."""
    fine = base.with_values({"sim.substeps": base.substeps * FINE_FACTOR,
                             "sim.pendulum_steps": base.sim.pendulum_steps * FINE_FACTOR})
    fc = trajectory_features(simulate_config(base, duration))
    ff = trajectory_features(simulate_config(fine, duration))
    return _rel_errors(fc, ff), fc, ff


def _scipy_features(cfg: Config, duration: float, angle: str):
    r = scipy_closed_loop(cfg, duration, angle=angle)
    return features(r["t"], r["theta_m"], r["u"], r["arm_dot_m"])


def _fmt(feat) -> str:
    return ", ".join(f"{k}={getattr(feat, k):.5g}" if getattr(feat, k) is not None
                     else f"{k}=None" for k in FEATURES)


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=15, help="timed repeats per case (min)")
    ap.add_argument("--scipy-duration", type=float, default=DURATION,
                    help="simulated seconds of the timed scipy run (scaled to 30 s)")
    ap.add_argument("--scipy-repeats", type=int, default=3,
                    help="timed repeats of the scipy run (min)")
    args = ap.parse_args(argv)

    ccfg, lcfg = classical_config(), lugre_config()
    classical_ms, classical_med = _time_ms(lambda: simulate_config(ccfg, DURATION), args.repeats)
    lugre_ms, lugre_med = _time_ms(lambda: simulate_config(lcfg, DURATION), args.repeats)
    kcfg = lugre_config("fast", ("friction.observer_gain=1",))
    k1_ms, k1_med = _time_ms(lambda: simulate_config(kcfg, DURATION), args.repeats)
    print(f"compiled, {DURATION:g} s run, substeps {ccfg.substeps} (classical) / "
          f"{lcfg.substeps} (lugre), pendulum steps {ccfg.sim.pendulum_steps}, min (median) of "
          f"{args.repeats}: classical {classical_ms:.3f} ({classical_med:.3f}) ms, "
          f"lugre {lugre_ms:.3f} ({lugre_med:.3f}) ms, lugre k = 1 {k1_ms:.3f} "
          f"({k1_med:.3f}) ms: x{k1_ms / lugre_ms:.3f}")

    span = min(args.scipy_duration, DURATION)
    ref: dict = {}

    def run_scipy():
        ref.update(scipy_closed_loop(ccfg, span))

    scipy_span_ms, scipy_span_med = _time_ms(run_scipy, args.scipy_repeats,
                                             warmup=lambda: scipy_closed_loop(ccfg, 0.1))
    scipy_ms = scipy_span_ms * DURATION / span
    scipy_med = scipy_span_med * DURATION / span
    speedup = scipy_ms / classical_ms
    what = ("" if span == DURATION else
            f" (timed over {span:g} s: {scipy_span_ms:.1f} ms, scaled linearly)")
    print(f"scipy solve_ivp (RK45, rtol {RTOL:g}, restarted every sample), classical, "
          f"{DURATION:g} s run, min (median) of {args.scipy_repeats}: {scipy_ms:.0f} "
          f"({scipy_med:.0f}) ms{what}; speedup_vs_scipy {speedup:.0f}x "
          f"(medians: {scipy_med / classical_med:.0f}x)")
    # cross-check: the two integrators' limit cycles over the same span
    sf = features(ref["t"], ref["theta_m"], ref["u"], ref["arm_dot_m"])
    cf = trajectory_features(simulate_config(ccfg, span))
    ce = _rel_errors(cf, sf)
    print(f"classical, {span:g} s, scipy features: {_fmt(sf)}")
    print(f"classical, {span:g} s, compiled vs scipy: max relative feature difference "
          f"{100 * max(ce.values()):.2f}% ({max(ce, key=ce.get)})")

    worst = 0.0
    for name, cfg in CONVERGENCE:
        err, fc, ff = convergence(cfg)
        arg = max(err, key=err.get)
        worst = max(worst, err[arg])
        print(f"{name}: features (substeps {cfg.substeps}): {_fmt(fc)}")
        print(f"{name}: features (substeps {cfg.substeps * FINE_FACTOR}): {_fmt(ff)}")
        print(f"{name}: max relative feature error vs {FINE_FACTOR}x steps "
              f"{100 * err[arg]:.3f}% ({arg}); per feature: "
              + ", ".join(f"{k} {100 * v:.3f}%" for k, v in err.items()))

    # which angle eq. (19)'s e = -theta uses: the continuous one (frictionlab) or
    # the sampled one held over the sample, both in the scipy loop
    sampled = 0.0
    for design, k in SAMPLED_ANGLE_CASES:
        cfg = lugre_config(design, (f"friction.observer_gain={k}",))
        fcont, fsamp = (_scipy_features(cfg, DURATION, angle)
                        for angle in ("continuous", "sampled"))
        err = _rel_errors(fsamp, fcont)
        arg = max(err, key=err.get)
        sampled = max(sampled, err[arg])
        print(f"lugre {design} k {k:g}, scipy, sampled vs continuous angle in eq. (19): max "
              f"relative feature difference {100 * err[arg]:.3f}% ({arg}); per feature: "
              + ", ".join(f"{n} {100 * v:.3f}%" for n, v in err.items()))

    result = {
        "classical_ms": round(classical_ms, 4),
        "lugre_ms": round(lugre_ms, 4),
        "lugre_k1_ms": round(k1_ms, 4),
        "lugre_k1_cost": round(k1_ms / lugre_ms, 3),
        "scipy_ms": round(scipy_ms, 1),
        "speedup_vs_scipy": round(speedup, 1),
        "feature_error_vs_fine": float(f"{worst:.3g}"),
        "sampled_angle_effect": float(f"{sampled:.3g}"),
    }
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
