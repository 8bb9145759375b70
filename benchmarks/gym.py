r"""Gymnasium environment benchmark: does the native vector ``frictionlab/Furuta-v0`` pay?

Measures, single-threaded, environment steps per second of:

* ``env_steps_per_s`` - :class:`frictionlab.gym.FurutaEnv` stepped directly
  (classical friction, noise 0.002 and quantisation on, random actions drawn
  beforehand);
* ``made_env_steps_per_s`` - the same through :func:`gymnasium.make` (time
  limit, order enforcing and passive checker wrappers), auto-reset by hand;
* ``sync_vector_steps_per_s_N`` - :class:`gymnasium.vector.SyncVectorEnv` of N
  copies, for each N of ``--envs`` (env-steps per second summed over the copies);
* ``native_vector_steps_per_s_N`` - :class:`frictionlab.gym.FurutaVectorEnv`
  (``gymnasium.make_vec``) of N copies: all plants in one compiled loop;
* ``vector_speedup_N`` - native over sync;
* ``plant_tick_steps_per_s`` - the plant alone: the largest N plants advanced by
  :func:`frictionlab.model.simulation.plant_tick` in one compiled loop, the upper
  bound of any batched environment;
* ``kernel_fraction`` - the plant's share of one direct env step
  (``env_steps_per_s / plant_tick_steps_per_s``).

Timings are the best of ``--repeats`` after a warm-up.  The last printed line
is a JSON object.

Usage::

    .venv/bin/python benchmarks/gym.py [--steps 20000] [--envs 16,64] [--repeats 5]
"""

from __future__ import annotations

import os

if __name__ == "__main__":
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                 "NUMBA_NUM_THREADS"):
        os.environ[_var] = "1"

import argparse
import json
import time

import gymnasium
import numpy as np

import frictionlab.gym as fgym
from frictionlab.config import build_config
from frictionlab.model._jit import jit
from frictionlab.model.friction import KINDS
from frictionlab.model.simulation import plant_tick

SETS = ["sim.noise=0.002", "sim.quantization=1"]


def _best(fn, repeats: int) -> float:
    fn()  # warm-up (compilation, caches)
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def env_rate(steps: int, repeats: int) -> float:
    """Steps per second of the environment class itself (reset when it terminates)."""
    return _env_rate(fgym.FurutaEnv(sets=SETS), steps, repeats, reset_on_truncation=False)


def made_env_rate(steps: int, repeats: int) -> float:
    """Steps per second through ``gymnasium.make`` (its wrappers; reset when an
    episode ends)."""
    return _env_rate(gymnasium.make(fgym.ENV_ID, sets=SETS), steps, repeats,
                     reset_on_truncation=True)


def _env_rate(env, steps: int, repeats: int, *, reset_on_truncation: bool) -> float:
    """Steps per second of one environment over random actions."""
    rng = np.random.default_rng(0)
    actions = rng.uniform(-2.0, 2.0, size=(steps, 1))

    def run():
        env.reset(seed=0)
        for a in actions:
            _, _, term, trunc, _ = env.step(a)
            if term or (trunc and reset_on_truncation):
                env.reset()

    return steps / _best(run, repeats)


def vector_rate(steps: int, n: int, repeats: int) -> float:
    """Steps per second of ``n`` environments in gymnasium's SyncVectorEnv."""
    venv = gymnasium.vector.SyncVectorEnv(
        [lambda: gymnasium.make(fgym.ENV_ID, sets=SETS) for _ in range(n)])
    return _vec_rate(venv, steps, n, repeats)


def native_vector_rate(steps: int, n: int, repeats: int) -> float:
    """Steps per second of the environment's own vectorised form (``make_vec``)."""
    return _vec_rate(gymnasium.make_vec(fgym.ENV_ID, num_envs=n, sets=SETS), steps, n, repeats)


def _vec_rate(venv, steps: int, n: int, repeats: int) -> float:
    """Steps per second of a vector environment of ``n`` copies over random actions."""
    rng = np.random.default_rng(0)
    batches = max(1, steps // n)
    actions = rng.uniform(-2.0, 2.0, size=(batches, n, 1))

    def run():
        venv.reset(seed=0)
        for a in actions:
            venv.step(a)

    return batches * n / _best(run, repeats)


@jit
def _batched(xs, us, mems, substeps, ratio, h, pp, fkind, fp, n_steps):
    for _ in range(n_steps):
        for i in range(xs.shape[0]):
            _f, mems[i] = plant_tick(xs[i], us[i], mems[i], substeps, ratio, h, pp, fkind, fp)


def plant_rate(steps: int, n: int, repeats: int) -> float:
    cfg = build_config(sets=SETS)
    pp, fp = cfg.plant.record(), cfg.friction.record()
    fkind = KINDS.index(cfg.friction_kind)
    batches = max(1, steps // n)

    def run():
        xs = np.zeros((n, 5))
        xs[:, 0] = 0.01
        us = np.zeros(n)
        mems = np.zeros(n)
        _batched(xs, us, mems, cfg.substeps, cfg.pendulum_ratio, cfg.design.h, pp, fkind, fp,
                 batches)

    return batches * n / _best(run, repeats)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--envs", default="16,64", help="copies of the vector envs, comma-separated")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    counts = [int(n) for n in args.envs.split(",")]
    out = {
        "env_steps_per_s": env_rate(args.steps, args.repeats),
        "made_env_steps_per_s": made_env_rate(args.steps, args.repeats),
    }
    for n in counts:
        sync = out[f"sync_vector_steps_per_s_{n}"] = vector_rate(args.steps, n, args.repeats)
        native = out[f"native_vector_steps_per_s_{n}"] = native_vector_rate(args.steps, n,
                                                                            args.repeats)
        out[f"vector_speedup_{n}"] = native / sync
    out["plant_tick_steps_per_s"] = plant_rate(args.steps, max(counts), args.repeats)
    out["load_avg_1min"] = os.getloadavg()[0]
    out["kernel_fraction"] = out["env_steps_per_s"] / out["plant_tick_steps_per_s"]
    for k, v in out.items():
        print(f"{k:30s} {v:,.3f}" if isinstance(v, float) else f"{k:30s} {v}")
    print(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in out.items()}))


if __name__ == "__main__":
    main()
