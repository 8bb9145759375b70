r"""Two source trees of frictionlab, the same 30 s runs, CPU time compared.

A change to the compiled model (the friction laws, the records, the closed
loop) is judged against the code before it: this runs one 30 s
:func:`~frictionlab.model.simulation.simulate_config` per case (no recording)
in a fresh process per tree (``PYTHONPATH=TREE/src``, each tree with its own
numba cache), the trees alternating, ``--rounds`` processes per tree, and
prints for every case the minimum CPU time (``time.process_time``) over all
of a tree's runs, the median over its processes of each process's minimum,
and the ratios.  On a virtual machine whose speed moves by 10-30 % from one
process to the next the minimum and the median over alternating processes
are what compare.  The thesis plant's cases (``--plant thesis``, the
default): no friction, viscous, classical friction (eq. 17) with and without
the zero-velocity band 0.03 rad/s of Sec. 5.2 (the sweep benchmark's),
Coulomb, Stribeck (slow design) and LuGre (eq. 18), each with the fast design
of eqs. 13-14 unless said.  ``--plant furuta-dc``: the QUBE-Servo 2 preset
(``--plant qube2``) with each friction law in volts; a tree without that
plant prints ``-``.  The last printed line is a JSON object.

Usage::

    git worktree add /tmp/before COMMIT
    .venv/bin/python benchmarks/simulate_ab.py /tmp/before . [--rounds 3] [--runs 30] \
        [--plant thesis|furuta-dc]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

#: Case name -> (plant preset, design, friction, --set values).
CASES = {
    "none": ("thesis", "fast", "none", []),
    "viscous": ("thesis", "fast", "viscous", []),
    "classical, band 0.03": ("thesis", "fast", "classical", ["friction.zero_velocity_band=0.03"]),
    "classical": ("thesis", "fast", "classical", []),
    "coulomb": ("thesis", "fast", "coulomb", []),
    "stribeck (slow design)": ("thesis", "slow", "stribeck", []),
    "lugre": ("thesis", "fast", "lugre", []),
    **{f"qube2 {kind}": ("qube2", "fast", kind, [])
       for kind in ("none", "viscous", "coulomb", "classical", "stribeck", "lugre")},
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
for name, (plant, design, friction, sets) in cases.items():
    try:
        kw = {} if plant == "thesis" else {"plant": plant}
        cfg = build_config(design, friction, sets=sets, **kw)
    except (TypeError, ValueError):  # a tree without the plant
        out[name] = None
        continue
    simulate_config(cfg, 30.0, record=False)  # compile or load the kernel
    best = float("inf")
    for _ in range(runs):
        t = time.process_time()
        simulate_config(cfg, 30.0, record=False)
        best = min(best, time.process_time() - t)
    out[name] = 1e3 * best
print(json.dumps(out))
"""


def run_tree(tree: Path, runs: int, cases: dict) -> dict[str, float | None]:
    """CPU ms of each case in one fresh process importing ``tree``'s sources."""
    env = {**os.environ, "PYTHONPATH": str(tree / "src")}
    res = subprocess.run([sys.executable, "-c", _WORKER, json.dumps(cases), str(runs)],
                         env=env, capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path, help="source tree of the code before (has src/)")
    ap.add_argument("after", type=Path, help="source tree of the code after (has src/)")
    ap.add_argument("--rounds", type=int, default=3, help="processes per tree (alternating)")
    ap.add_argument("--runs", type=int, default=30, help="timed runs per case and process")
    ap.add_argument("--plant", choices=("thesis", "furuta-dc"), default="thesis",
                    help="the thesis plant's cases or the DC plant's (QUBE-Servo 2)")
    args = ap.parse_args(argv)
    cases = {k: v for k, v in CASES.items() if (v[0] == "thesis") == (args.plant == "thesis")}
    trees = {"before": args.before.resolve(), "after": args.after.resolve()}
    for name, tree in trees.items():
        if not (tree / "src" / "frictionlab").is_dir():
            ap.error(f"{name}: {tree} has no src/frictionlab")
    mins: dict[str, dict[str, list[float]]] = {name: {c: [] for c in cases} for name in trees}
    for r in range(args.rounds):
        for name, tree in trees.items():  # the trees alternate, round after round
            for case, ms in run_tree(tree, args.runs, cases).items():
                if ms is not None:
                    mins[name][case].append(ms)
        print(f"round {r + 1}/{args.rounds} done", file=sys.stderr)

    def stat(name, case, f):
        v = mins[name][case]
        return f(v) if v else None

    def fmt(x, spec):
        return format(x, spec) if x is not None else "-".rjust(int(spec.split(".")[0]))

    def ratio(a, b):
        return a / b if a is not None and b else None

    print(f"{'30 s run, CPU ms':24} {'before min':>10} {'after min':>10} {'ratio':>6} "
          f"{'before med':>10} {'after med':>10} {'ratio':>6}")
    result = {}
    for case in cases:
        bm, am = stat("before", case, min), stat("after", case, min)
        bd, ad = stat("before", case, statistics.median), stat("after", case, statistics.median)
        print(f"{case:24} {fmt(bm, '10.3f')} {fmt(am, '10.3f')} {fmt(ratio(am, bm), '6.3f')} "
              f"{fmt(bd, '10.3f')} {fmt(ad, '10.3f')} {fmt(ratio(ad, bd), '6.3f')}")
        result[case] = {"before_ms": bm, "after_ms": am, "ratio": ratio(am, bm),
                        "before_median_ms": bd, "after_median_ms": ad,
                        "median_ratio": ratio(ad, bd)}
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
