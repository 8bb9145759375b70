r"""Compensation benchmark: cost of the compensators and of ``compensate tune``.

Measures:

* ``run_ms`` - a 30 s closed-loop run (fast design, LuGre plant at eq. 21,
  noise 0.002) per compensator (``none``, ``coulomb``, ``classical``,
  ``lugre``): what the compensator adds to the compiled loop (minimum of
  ``--repeats`` runs after a warm-up);
* ``api_step_us`` - one :meth:`frictionlab.compensation.Compensator.step`
  call from Python (LuGre; the per-tick cost of the public API outside the
  compiled loop), mean over 20000 calls;
* ``tune_s`` - ``frictionlab.compensation.tune`` over the default LuGre grid
  (64 points, 30 s runs) in-process (``workers=1``) and on the sweep engine's
  process pool with ``--workers`` processes (default 2).

The last printed line is a JSON object.

Usage::

    .venv/bin/python benchmarks/compensation.py [--repeats 10] [--workers 2]
"""

from __future__ import annotations

import argparse
import json
import time

from frictionlab.compensation import make_compensator, tune
from frictionlab.config import build_config
from frictionlab.simulation import simulate_config


def best_of(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    run_ms = {}
    for kind in ("none", "coulomb", "classical", "lugre"):
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
    print(json.dumps({"run_ms": run_ms, "api_step_us": api_us, "tune_s": tune_s}))


if __name__ == "__main__":
    main()
