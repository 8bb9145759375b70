r"""Limit-cycle identification benchmark: two experiments, four free keys.

Runs :func:`frictionlab.studies.identification.fit_limit_cycle` exactly as
``frictionlab identify limit-cycle`` does with its defaults (30 s runs,
features over the last 20 s, differential evolution with 40 generations at
most and a population of 8 per key, then the least-squares polish and the
Jacobian for the standard errors), on two problems:

* ``synthetic`` - features of the fast and slow designs simulated at a known
  plant (``friction.coulomb`` 1.35, ``friction.stiction`` 2.1,
  ``plant.omega0`` 7.1, ``plant.input_gain`` 1.1, classical friction eq. 17),
  fitting those four keys; reports the wall time, the number of parameter
  sets (each one run per experiment) and the relative error of each
  estimate;
* ``table1`` - the thesis's real-rig features (Table 1, both rows;
  ``examples/table1.json``), fitting the same four keys; reports the wall
  time, the estimates with standard errors, and the cost.

The target of issue 5 is under 2 minutes per fit on the 2-core machine.  The
evaluations go through :func:`frictionlab.studies.sweep.evaluate` with ``--workers``
(default: all cores), i.e. the compiled batch evaluator
(:mod:`frictionlab.studies.batch`) on threads: one generation of the global
search is one compiled call.  The synthetic fit is repeated in-process
(``synthetic_inprocess``, ``workers = 1``: the same batches on one thread).

Issue 21's target 3 is ``table1_docs_budget``: the Table 1 fit with the
budget of docs/identification.md (``--maxiter 80 --popsize 12 --seed 0``,
about 3,300 parameter sets) in 6 s or less, at the same optimum (cost within
1 %).  It is run three ways, side by side on the same (possibly busy)
machine:

* ``full`` - every run of the search 30 s long (features over the last 20 s);
  the reference optimum;
* ``short_search`` - the global search on ``--search-duration``
  (default 15 s, window scaled to 10 s), the polish and standard errors on
  30 s runs (``frictionlab identify limit-cycle ... --search-duration 15``);
  its ``cost_vs_reference`` is its cost relative to ``full``'s;
* ``per_run_pool`` (unless ``--skip-per-run``) - ``full`` through the
  previous engine: one Python-driven run and feature extraction per set, in a
  process pool of all cores (``reduce=reduce_features``), for comparison.

The last printed line is a JSON object.

Usage::

    .venv/bin/python benchmarks/identify.py [--workers N] [--seed S] [--search-duration S]
        [--skip-per-run]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

from _measure import cpu_seconds, load_average

from frictionlab.config import build_config
from frictionlab.runs import run_features
from frictionlab.studies.identification.limit_cycle import fit_limit_cycle, parse_experiments

TRUTH = {"friction.coulomb": 1.35, "friction.stiction": 2.1, "plant.omega0": 7.1,
         "plant.input_gain": 1.1}
KEYS = list(TRUTH)
DURATION, WINDOW = 30.0, 20.0
TABLE1 = Path(__file__).resolve().parents[1] / "examples" / "table1.json"


def synthetic_measured() -> dict:
    """Fast and slow features of the simulated plant at :data:`TRUTH`."""
    exps = []
    for design in ("fast", "slow"):
        cfg = build_config(design=design, friction="classical", sets=list(TRUTH.items()))
        feats = run_features(cfg, DURATION, WINDOW)
        exps.append({"design": design, "features": feats.interface_dict()})
    return {"experiments": exps}


#: The budget of docs/identification.md's Table 1 command.
DOCS_BUDGET = {"maxiter": 80, "popsize": 12}
#: The optimum docs/identification.md reports for that command (seed 0).
DOCS_COST = 0.1452


#: CPU seconds of the last :func:`run`.
LAST_CPU = [0.0]


def run(measured: dict, workers: int | None, seed: int, **kw) -> tuple[dict, float]:
    c0, t0 = cpu_seconds(), time.perf_counter()
    res = fit_limit_cycle(parse_experiments(measured), KEYS, duration=DURATION, window=WINDOW,
                          workers=workers, seed=seed, **kw)
    LAST_CPU[0] = cpu_seconds() - c0
    return res, time.perf_counter() - t0


def _per_run_pool(base, points, **kw):
    """The previous engine: a Python-driven run and feature extraction per set, in a
    process pool (a custom ``reduce`` runs there)."""
    from frictionlab.studies.sweep import evaluate, reduce_features

    kw["workers"] = kw.get("workers") or os.cpu_count() or 1
    return evaluate(base, points, reduce=reduce_features, **kw)


def docs_budget(workers: int | None, seed: int, search_duration: float,
                per_run: bool) -> dict:
    """The Table 1 fit at the docs' budget: full-length search, short search, old engine."""
    table1 = json.loads(TABLE1.read_text())
    out: dict = {"budget": DOCS_BUDGET, "docs_cost": DOCS_COST}
    ref, secs = run(table1, workers, seed, **DOCS_BUDGET)
    out["full"] = {"seconds": secs, "cpu_seconds": LAST_CPU[0], "cost": ref.cost,
                   "parameter_sets": ref.evaluations, "estimate": ref.estimate}
    print(f"table1 at the docs' budget, 30 s search runs: {secs:.1f} s (CPU "
          f"{LAST_CPU[0]:.1f} s), {ref.evaluations} parameter sets, cost {ref.cost:.4f}")
    short, secs = run(table1, workers, seed, search_duration=search_duration, **DOCS_BUDGET)
    rel = short.cost / ref.cost - 1.0
    out["short_search"] = {"seconds": secs, "cpu_seconds": LAST_CPU[0],
                           "search_duration": search_duration,
                           "cost": short.cost, "cost_vs_reference": rel,
                           "parameter_sets": short.evaluations, "estimate": short.estimate}
    print(f"table1 at the docs' budget, {search_duration:g} s search runs: {secs:.1f} s (CPU "
          f"{LAST_CPU[0]:.1f} s), cost {short.cost:.4f} ({100 * rel:+.2f} % vs the 30 s search)")
    for k in KEYS:
        print(f"  {k:20s} {short.estimate[k]:.4f} (30 s search: {ref.estimate[k]:.4f})")
    if per_run:
        old, secs = run(table1, workers, seed, evaluate=_per_run_pool, **DOCS_BUDGET)
        out["per_run_pool"] = {"seconds": secs, "cpu_seconds": LAST_CPU[0], "cost": old.cost,
                               "same_estimate": old.estimate == ref.estimate}
        same = "same" if old.estimate == ref.estimate else "DIFFERENT"
        print(f"table1 at the docs' budget through the per-run process pool: {secs:.1f} s "
              f"(CPU {LAST_CPU[0]:.1f} s), cost {old.cost:.4f} ({same} estimate)")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=None,
                    help="workers of the sweep engine for the main fits (default: its "
                         "automatic choice, as the CLI; 1 = in-process)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the global search")
    ap.add_argument("--search-duration", type=float, default=15.0,
                    help="search run length of the short-search fit (default 15 s)")
    ap.add_argument("--skip-per-run", action="store_true",
                    help="do not time the fit through the previous per-run process pool")
    args = ap.parse_args()
    workers = args.workers
    cpus = os.cpu_count() or 1
    # load the compiled code (and start the per-run pool) outside the timed fits
    from frictionlab.studies.sweep import evaluate, reduce_features

    t0 = time.perf_counter()
    evaluate(build_config(), [{"friction.coulomb": 1.5}] * (2 * cpus), duration=2.0,
             workers=workers)
    if not args.skip_per_run:
        evaluate(build_config(), [{"friction.coulomb": 1.5}] * (2 * cpus), duration=2.0,
                 workers=cpus, reduce=reduce_features)
    start = time.perf_counter() - t0
    print(f"load average {load_average()}")
    print(f"compiled code loaded (and the per-run pool of {cpus} warm) in {start:.1f} s "
          "(not part of the fit times)")

    out: dict = {"workers": "auto" if workers is None else workers, "cpus": cpus,
                 "keys": KEYS, "duration_s": DURATION, "window_s": WINDOW,
                 "warm_up_seconds": start}
    measured = synthetic_measured()
    syn, secs = run(measured, workers, args.seed)
    errors = {k: (syn.estimate[k] - v) / v for k, v in TRUTH.items()}
    out["synthetic"] = {"seconds": secs, "parameter_sets": syn.evaluations,
                        "runs": 2 * syn.evaluations, "generations": syn.generations,
                        "cost": syn.cost, "relative_error": errors}
    print(f"synthetic: {secs:.1f} s, {syn.evaluations} parameter sets "
          f"({2 * syn.evaluations} runs), {syn.generations} generations, cost {syn.cost:.3g}")
    for k, e in errors.items():
        print(f"  {k:20s} {syn.estimate[k]:.4f} (truth {TRUTH[k]}; error {100 * e:+.2f} %)")
    if workers != 1:
        # the same fit in-process (every batch serial)
        serial, secs_serial = run(measured, 1, args.seed)
        same = serial.estimate == syn.estimate
        out["synthetic_inprocess"] = {"workers": 1, "seconds": secs_serial,
                                      "same_estimate": same}
        print(f"synthetic in-process: {secs_serial:.1f} s "
              f"({'same' if same else 'DIFFERENT'} estimate)")

    t1, secs = run(json.loads(TABLE1.read_text()), workers, args.seed)
    out["table1"] = {"seconds": secs, "parameter_sets": t1.evaluations,
                     "generations": t1.generations, "cost": t1.cost,
                     "estimate": t1.estimate, "stderr": t1.stderr, "warnings": t1.warnings}
    print(f"table1: {secs:.1f} s, {t1.evaluations} parameter sets, cost {t1.cost:.4f}")
    for k, v in t1.estimate.items():
        se = t1.stderr[k]
        print(f"  {k:20s} {v:.4f} +- {'-' if se is None else f'{se:.3g}'}")
    for w in t1.warnings:
        print(f"  warning: {w}")
    out["table1_docs_budget"] = docs_budget(workers, args.seed, args.search_duration,
                                            not args.skip_per_run)
    out["max_seconds"] = max(out["synthetic"]["seconds"], out["table1"]["seconds"])
    print(json.dumps(out))


if __name__ == "__main__":
    main()
