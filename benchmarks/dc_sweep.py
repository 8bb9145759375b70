r"""Sweep speed of the DC-motor plant against the thesis plant.

The same sweep on both plants: ``--points`` parameter sets (default 100), a
grid of ``friction.coulomb`` over +-30 % of each plant's default (the thesis
plant's 1.5 m/s^2, the QUBE-Servo 2's 0.15 V) with the classical plant
friction and the fast design, each a 30 s closed-loop run reduced to its
limit-cycle features by the compiled batch evaluator on one thread
(:func:`frictionlab.studies.batch.evaluate_rows`: what ``frictionlab sweep``
runs on each of its threads).  The two are timed in alternation
(``--rounds``, default 3) and each figure is the CPU time per set of the
least disturbed round (CPU, not wall time: the machine is shared).

The issue asks for the DC plant's sweeps at the thesis plant's speed within a
factor of 2: ``ratio`` = the DC plant's CPU time per set over the thesis
plant's.  The last printed line is a JSON object.

Usage::

    .venv/bin/python benchmarks/dc_sweep.py [--points 100] [--rounds 3]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from frictionlab.config import build_config
from frictionlab.studies.batch import evaluate_rows


def _points(base: float, n: int) -> list[dict]:
    return [{"friction.coulomb": float(v)} for v in np.linspace(0.7 * base, 1.3 * base, n)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=100)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    plants = {}
    for name in ("thesis", "qube2"):
        cfg = build_config("fast", "classical", plant=name)
        plants[name] = (cfg, _points(cfg.friction.coulomb, args.points))
        evaluate_rows(cfg, plants[name][1][:2], 30.0, None)  # compile / load the kernels
    best = {name: float("inf") for name in plants}
    statuses = {}
    for _ in range(args.rounds):
        for name, (cfg, pts) in plants.items():
            t0 = time.process_time()
            rows = evaluate_rows(cfg, pts, 30.0, None)
            best[name] = min(best[name], (time.process_time() - t0) / len(pts))
            statuses[name] = sorted({r["status"] for r in rows})
    for name in plants:
        print(f"{name:7s} {best[name] * 1e3:8.2f} ms CPU per 30 s set  statuses {statuses[name]}")
    ratio = best["qube2"] / best["thesis"]
    print(f"qube2 / thesis: {ratio:.2f}")
    print(json.dumps({"points": args.points, "thesis_cpu_ms_per_set": best["thesis"] * 1e3,
                      "qube2_cpu_ms_per_set": best["qube2"] * 1e3, "ratio": ratio,
                      "statuses": statuses}))


if __name__ == "__main__":
    main()
