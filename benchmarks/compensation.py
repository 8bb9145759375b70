r"""Compensation benchmark: cost of the compensators and of ``compensate tune``.

Measures:

* ``run_ms`` - a 30 s closed-loop run (fast design, LuGre plant at eq. 21,
  noise 0.002) per compensator (``none``, ``coulomb``, ``classical``,
  ``lugre``): what the compensator adds to the compiled loop (minimum of
  ``--repeats`` runs after a warm-up);
* ``api_step_us`` - one :meth:`frictionlab.studies.compensation.Compensator.step`
  call from Python (LuGre; the per-tick cost of the public API outside the
  compiled loop), mean over 20000 calls;
* ``tune_s`` - ``frictionlab.studies.compensation.tune`` over the default LuGre grid
  (64 points, 30 s runs) in-process (``workers=1``) and on the sweep engine's
  process pool with ``--workers`` processes (default 2);
* ``adaptive`` - the acceptance figures of the adaptive compensator
  (``--compensation adaptive``) on the LuGre plant of eq. (21) with noise
  0.002, measured by the peak-to-peak of the measured pendulum angle over the
  last 10 s (``frictionlab simulate``'s features), each the mean over
  ``--seeds`` noise seeds, for the compensators' default observer gain k = 7
  and for plain eq. (18) compensation (k = 0):

  - ``drift``: plant levels falling 40 % over 60 s (``friction.drift=-0.4``);
    the fixed LuGre compensator set to the plant's start values (F_S 2.3,
    F_C 1.5, F_v 0.07) against the adaptive one started there, and their ratio
    (target <= 0.5);
  - ``floor``: the same loop without drift, the compensator knowing the
    plant's levels exactly, at the start levels and at the end levels (0.6 x):
    what noise alone leaves;
  - ``no_drift``: fixed and adaptive without drift, and their ratio (target
    <= 1.5);
  - ``off35``: compensation Coulomb level 1.0 on a plant with 1.55 (35 % off),
    30 s: the estimate F_C at 5, 10, 20 and 30 s and the peak-to-peak over
    15-20 s and 20-30 s, beside the fixed compensator started as far off and
    the adaptive one started at 1.55;
  - ``robustness``: fixed LuGre and adaptive (compensator defaults, k = 7 and
    k = 0) on other plants and conditions, 40 s runs, seed 0: the status and
    the peak-to-peak over the last 10 s.

The last printed line is a JSON object.

Usage::

    .venv/bin/python benchmarks/compensation.py [--repeats 10] [--workers 2]
        [--part all|cost|adaptive] [--seeds 3]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from frictionlab.config import build_config
from frictionlab.model.limit_cycles import trajectory_features
from frictionlab.runs import simulate_config
from frictionlab.studies.compensation import make_compensator, tune

NOISE = 0.002
#: The plant's start levels (eq. 21) as compensator settings.
START = ["compensation.stiction=2.3", "compensation.coulomb=1.5", "compensation.viscous=0.07"]
#: The plant's levels at the end of a -0.4 drift, for plant and compensator.
END_LEVELS = {"stiction": 1.38, "coulomb": 0.9, "viscous": 0.042}


def best_of(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def ptp(comp: str, sets: list[str], duration: float, seed: int, window=(-10.0, None)):
    """Peak-to-peak of the measured angle over ``window`` (s; negative: from the end)."""
    cfg = build_config("fast", "lugre", comp,
                       sets=[f"sim.noise={NOISE}", f"sim.seed={seed}", *sets])
    tr = simulate_config(cfg, duration)
    assert tr.status == "ok", (comp, sets, seed)
    t0, t1 = window
    t0 = duration + t0 if t0 < 0 else t0
    t1 = duration if t1 is None else t1
    m = (tr.t >= t0 - 1e-9) & (tr.t < t1 - 1e-9)
    sub = type(tr)(tr.k[m], tr.h, tr.data[m], tr.status, tr.config)
    f = trajectory_features(sub, t1 - t0)
    return f.interface_dict()["peak_to_peak"], tr


def adaptive_figures(seeds: int) -> dict:
    """The adaptive compensator's acceptance figures (see the module docstring)."""
    out = {}
    seeds_ = range(seeds)

    def mean(comp, sets, duration=60.0, window=(-10.0, None)):
        vals = [ptp(comp, sets, duration, s, window)[0] for s in seeds_]
        return round(float(np.mean(vals)), 5), [round(v, 5) for v in vals]

    end_plant = [f"friction.{k}={v}" for k, v in END_LEVELS.items()]
    end_comp = [f"compensation.{k}={v}" for k, v in END_LEVELS.items()]
    for k in (7, 0):
        kk = [f"compensation.observer_gain={k}"]
        res = {}
        drift = ["friction.drift=-0.4", *START, *kk]
        fixed, fixed_all = mean("lugre", drift)
        adapt, adapt_all = mean("adaptive", drift)
        res["drift"] = {"fixed": fixed, "adaptive": adapt, "ratio": round(adapt / fixed, 3),
                        "fixed_per_seed": fixed_all, "adaptive_per_seed": adapt_all}
        floor_start, _ = mean("lugre", [*START, *kk])
        floor_end, _ = mean("lugre", [*end_plant, *end_comp, *kk])
        res["floor"] = {"start_levels": floor_start, "end_levels": floor_end}
        nd_adapt, _ = mean("adaptive", [*START, *kk])
        res["no_drift"] = {"fixed": floor_start, "adaptive": nd_adapt,
                           "ratio": round(nd_adapt / floor_start, 3)}
        off = ["friction.coulomb=1.55", "compensation.coulomb=1.0", *kk]
        right = ["friction.coulomb=1.55", "compensation.coulomb=1.55", *kk]
        est = []
        for s in seeds_:
            _, tr = ptp("adaptive", off, 30.0, s)
            est.append([float(tr["coulomb_hat"][round(t / tr.h) - 1]) for t in (5, 10, 20, 30)])
        res["off35"] = {
            "coulomb_hat_at_5_10_20_30s": [round(float(v), 3) for v in np.mean(est, axis=0)],
            "adaptive_15_20": mean("adaptive", off, 30.0, (15.0, 20.0))[0],
            "adaptive_20_30": mean("adaptive", off, 30.0, (20.0, 30.0))[0],
            "fixed_20_30": mean("lugre", off, 30.0, (20.0, 30.0))[0],
            "adaptive_started_right_20_30": mean("adaptive", right, 30.0, (20.0, 30.0))[0],
        }
        out[f"k{k}"] = res
        d, f, n, o = res["drift"], res["floor"], res["no_drift"], res["off35"]
        print(f"k = {k}: drift -0.4 over 60 s, p2p last 10 s: fixed {d['fixed']:.4f}, adaptive "
              f"{d['adaptive']:.4f} (ratio {d['ratio']:.2f}, target <= 0.5); noise floor "
              f"(exact levels, no drift) {f['start_levels']:.4f} at the start levels, "
              f"{f['end_levels']:.4f} at the end levels")
        print(f"k = {k}: no drift: fixed {n['fixed']:.4f}, adaptive {n['adaptive']:.4f} "
              f"(ratio {n['ratio']:.2f}, target <= 1.5)")
        print(f"k = {k}: 35 % off (F_C 1.0 on 1.55): F_C estimate at 5/10/20/30 s "
              f"{o['coulomb_hat_at_5_10_20_30s']}; p2p 15-20 s {o['adaptive_15_20']:.4f}, "
              f"20-30 s {o['adaptive_20_30']:.4f} (fixed {o['fixed_20_30']:.4f}, adaptive "
              f"started at 1.55 {o['adaptive_started_right_20_30']:.4f})", flush=True)
    out["robustness"] = robustness()
    return out


#: (design, plant friction, extra keys) of the robustness rows.
ROBUSTNESS_CASES = [
    ("fast", "classical", []), ("fast", "coulomb", []), ("slow", "lugre", []),
    ("fast", "lugre", ["sim.noise=0.01"]), ("fast", "lugre", ["sim.quantization=1"]),
    ("slow", "classical", ["friction.drift=-0.4"]), ("fast", "lugre", ["friction.drift=0.5"]),
    ("fast", "lugre", ["friction.drift=-0.4", "friction.drift_time=0",
                       "friction.drift_start=20"]),
]


def robustness() -> list[dict]:
    """Fixed LuGre against adaptive on other plants and conditions (no fall allowed)."""
    rows = []
    for design, friction, extra in ROBUSTNESS_CASES:
        row = {"design": design, "friction": friction, "set": extra}
        for k in (7, 0):
            for comp in ("lugre", "adaptive"):
                cfg = build_config(design, friction, comp,
                                   sets=[f"sim.noise={NOISE}", f"compensation.observer_gain={k}",
                                         *extra])
                tr = simulate_config(cfg, 40.0)
                p = trajectory_features(tr, 10.0).interface_dict()["peak_to_peak"]
                row[f"{comp}_k{k}"] = ("fell" if tr.status == "fell"
                                       else None if p is None else round(p, 4))
        rows.append(row)
        print(f"{design} {friction} {' '.join(extra)}: " + ", ".join(
            f"{k} {v}" for k, v in row.items() if k.endswith(("k7", "k0"))), flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--part", choices=("all", "cost", "adaptive"), default="all")
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args()
    result = {}
    if args.part in ("all", "adaptive"):
        result["adaptive"] = adaptive_figures(args.seeds)
    if args.part == "adaptive":
        print(json.dumps(result))
        return
    run_ms = {}
    for kind in ("none", "coulomb", "classical", "lugre", "adaptive"):
        cfg = build_config("fast", "lugre", kind, sets=["sim.noise=0.002"])
        run_ms[kind] = round(1e3 * best_of(lambda c=cfg: simulate_config(c, 30.0),
                                           args.repeats), 3)
        print(f"30 s closed-loop run, compensator {kind:9s}: {run_ms[kind]:.2f} ms")
    c = make_compensator("lugre")
    s = c.init()
    n = 20000
    t0 = time.perf_counter()
    for k in range(n):
        _, s = c.step(s, 0.5 if k % 200 < 100 else -0.5, e=0.001)
    api_us = round(1e6 * (time.perf_counter() - t0) / n, 2)
    print(f"Compensator.step (LuGre, Python API): {api_us:.2f} us per call")
    cfg = build_config("fast", "lugre", "lugre", sets=["sim.noise=0.002"])
    tune_s = {}
    for w in (1, args.workers):
        t0 = time.perf_counter()
        res = tune(cfg, duration=30.0, workers=w)
        tune_s[f"workers_{w}"] = round(time.perf_counter() - t0, 2)
        print(f"tune, default LuGre grid ({res.evaluated} points), workers={w}: "
              f"{tune_s[f'workers_{w}']:.1f} s; best {res.best}, reduction "
              f"{res.reduction:.1f}x")
    result.update({"run_ms": run_ms, "api_step_us": api_us, "tune_s": tune_s})
    print(json.dumps(result))


if __name__ == "__main__":
    main()
