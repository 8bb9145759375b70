r"""Two source trees of frictionlab, the same 30 s runs, CPU time compared.

A change to the compiled model (the friction laws, the records, the closed
loop) is judged against the code before it: this runs one 30 s
:func:`~frictionlab.model.simulation.simulate_config` per case (no recording)
in a fresh process per tree (``PYTHONPATH=TREE/src``, each tree with its own
numba cache), the trees alternating, ``--rounds`` processes per tree, and
prints for every case the minimum CPU time (``time.process_time``) over all
of a tree's runs and the ratio.  On a virtual machine whose speed moves by
10-30 % from one process to the next the minimum over alternating processes
is what compares.  The cases: classical friction (eq. 17) with and without the
zero-velocity band 0.03 rad/s of Sec. 5.2 (the sweep benchmark's), Coulomb,
Stribeck (slow design) and LuGre (eq. 18), each with the fast design of eqs.
13-14 unless said.  The last printed line is a JSON object.

Usage::

    git worktree add /tmp/before COMMIT
    .venv/bin/python benchmarks/simulate_ab.py /tmp/before . [--rounds 3] [--runs 30]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

CASES = {
    "classical, band 0.03": ("fast", "classical", ["friction.zero_velocity_band=0.03"]),
    "classical": ("fast", "classical", []),
    "coulomb": ("fast", "coulomb", []),
    "stribeck (slow design)": ("slow", "stribeck", []),
    "lugre": ("fast", "lugre", []),
}

_WORKER = r"""
import json, sys, time
from frictionlab.config import build_config
try:
    from frictionlab.runs import simulate_config
except ImportError:  # a tree from before frictionlab.runs (the model's own simulate_config)
    from frictionlab.model.simulation import simulate_config
cases, runs = json.loads(sys.argv[1]), int(sys.argv[2])
out = {}
for name, (design, friction, sets) in cases.items():
    cfg = build_config(design, friction, sets=sets)
    simulate_config(cfg, 30.0, record=False)  # compile or load the kernel
    best = float("inf")
    for _ in range(runs):
        t = time.process_time()
        simulate_config(cfg, 30.0, record=False)
        best = min(best, time.process_time() - t)
    out[name] = 1e3 * best
print(json.dumps(out))
"""


def run_tree(tree: Path, runs: int) -> dict[str, float]:
    """CPU ms of each case in one fresh process importing ``tree``'s sources."""
    env = {**os.environ, "PYTHONPATH": str(tree / "src")}
    res = subprocess.run([sys.executable, "-c", _WORKER, json.dumps(CASES), str(runs)],
                         env=env, capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path, help="source tree of the code before (has src/)")
    ap.add_argument("after", type=Path, help="source tree of the code after (has src/)")
    ap.add_argument("--rounds", type=int, default=3, help="processes per tree (alternating)")
    ap.add_argument("--runs", type=int, default=30, help="timed runs per case and process")
    args = ap.parse_args(argv)
    trees = {"before": args.before.resolve(), "after": args.after.resolve()}
    for name, tree in trees.items():
        if not (tree / "src" / "frictionlab").is_dir():
            ap.error(f"{name}: {tree} has no src/frictionlab")
    best = {name: dict.fromkeys(CASES, float("inf")) for name in trees}
    for r in range(args.rounds):
        for name, tree in trees.items():
            for case, ms in run_tree(tree, args.runs).items():
                best[name][case] = min(best[name][case], ms)
        print(f"round {r + 1}/{args.rounds} done", file=sys.stderr)
    print(f"{'30 s run, CPU ms (min)':28} {'before':>8} {'after':>8} {'ratio':>6}")
    for case in CASES:
        b, a = best["before"][case], best["after"][case]
        print(f"{case:28} {b:8.3f} {a:8.3f} {a / b:6.3f}")
    result = {case: {"before_ms": round(best["before"][case], 3),
                     "after_ms": round(best["after"][case], 3),
                     "ratio": round(best["after"][case] / best["before"][case], 3)}
              for case in CASES}
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
