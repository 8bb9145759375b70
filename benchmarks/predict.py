r"""Does the exact periodic orbit pay for sweeps and identification?

For each loop of the Table 2-5 grids (classical friction, F_C 1.1..1.9 at
F_S 2.3 and F_S 1.9..2.7 at F_C 1.5; fast design with the zero-velocity band
0.03 rad/s: Tables 2-3, slow design with 0.001 rad/s: Tables 4-5, as
``frictionlab reproduce`` runs them) it measures, single-threaded:

* the reference: a 300 s run of ``simulate`` with the features over its last
  200 s;
* ``orbit``: :func:`frictionlab.model.periodic.periodic_orbit` (seed transient,
  Newton, Floquet multipliers, features) -- its wall time and its largest
  relative feature error against the reference;
* ``sim D``: :func:`frictionlab.model.simulation.run_features` over D s with the
  features over the last D/2 s (the unit of work of sweeps and
  identification; they use D = 30-40 s) for D in 5, 10, 20, 40 s -- wall time
  and error;
* ``sim at orbit accuracy``: the shortest of those runs whose error is at most
  the orbit's (the orbit's accuracy matched by plain simulation);
* ``df``: the describing function (:func:`frictionlab.studies.predict.describing_function`).

Timings are the minimum over ``--repeats`` calls after a warm-up (numba
compilation), thread pools pinned to one thread.  The last line is a JSON
object with the medians per design.

Usage::

    .venv/bin/python benchmarks/predict.py [--repeats 5]
"""

from __future__ import annotations

import os

if __name__ == "__main__":  # single-threaded; set before numpy/numba load
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                 "NUMBA_NUM_THREADS"):
        os.environ[_var] = "1"

import argparse
import json
import statistics
import time

from frictionlab.config import build_config
from frictionlab.model.limit_cycles import FEATURES
from frictionlab.model.periodic import periodic_orbit
from frictionlab.runs import loop_spec, run_features
from frictionlab.studies.predict import describing_function

DURATIONS = (5.0, 10.0, 20.0, 40.0)


def configs():
    for design in ("fast", "slow"):
        for key, values in (("friction.coulomb", (1.1, 1.3, 1.5, 1.7, 1.9)),
                            ("friction.stiction", (1.9, 2.1, 2.3, 2.5, 2.7))):
            for v in values:
                band = 0.03 if design == "fast" else 0.001
                yield design, f"{key}={v}", build_config(
                    design, "classical", sets=[f"friction.zero_velocity_band={band}",
                                               f"{key}={v}"])


def max_error(f, ref) -> float:
    worst = 0.0
    for k in FEATURES:
        a, b = getattr(f, k), getattr(ref, k)
        if a is None or b is None:
            if a is not b:
                return float("inf")
            continue
        worst = max(worst, abs(a - b) / abs(b))
    return worst


def best_ms(fn, repeats: int):
    out = fn()  # warm-up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(1e3 * (time.perf_counter() - t0))
    return min(times), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    rows = []
    head = (f"{'design':6s} {'row':22s} {'orbit ms':>9s} {'orbit err':>10s} "
            + " ".join(f"{f'sim {d:g}s ms/err':>18s}" for d in DURATIONS)
            + f" {'sim@orbit acc':>14s} {'df ms':>7s}")
    print(head)
    for design, label, cfg in configs():
        ref = run_features(cfg, 300.0, 200.0)
        t_orbit, orbit = best_ms(lambda cfg=cfg: periodic_orbit(loop_spec(cfg)), args.repeats)
        e_orbit = max_error(orbit.features, ref) if orbit.found else float("inf")
        sims = []
        for d in DURATIONS:
            t, f = best_ms(lambda cfg=cfg, d=d: run_features(cfg, d, d / 2), args.repeats)
            sims.append((d, t, max_error(f, ref)))
        match = next(((d, t) for d, t, e in sims if e <= e_orbit), None)
        t_df, _ = best_ms(lambda cfg=cfg: describing_function(cfg), 1)
        rows.append({"design": design, "row": label, "orbit_ms": t_orbit, "orbit_err": e_orbit,
                     "sims": sims, "match": match, "df_ms": t_df})
        print(f"{design:6s} {label:22s} {t_orbit:9.2f} {100 * e_orbit:9.3f}% "
              + " ".join(f"{t:8.2f}/{100 * e:7.3f}%" for _d, t, e in sims)
              + (f" {match[1]:7.2f} ({match[0]:g}s)" if match else f" {'none':>14s}")
              + f" {t_df:7.0f}", flush=True)
    summary = {}
    for design in ("fast", "slow"):
        rs = [r for r in rows if r["design"] == design]
        summary[design] = {
            "orbit_ms": statistics.median(r["orbit_ms"] for r in rs),
            "orbit_err_max": max(r["orbit_err"] for r in rs),
            **{f"sim{d:g}_ms": statistics.median(r["sims"][i][1] for r in rs)
               for i, d in enumerate(DURATIONS)},
            **{f"sim{d:g}_err_max": max(r["sims"][i][2] for r in rs)
               for i, d in enumerate(DURATIONS)},
            "sim_at_orbit_accuracy_ms": statistics.median(
                r["match"][1] if r["match"] else float("inf") for r in rs),
            "orbit_faster_than_sim40": sum(r["orbit_ms"] < r["sims"][-1][1] for r in rs),
            "orbit_faster_at_equal_accuracy": sum(
                r["match"] is None or r["orbit_ms"] < r["match"][1] for r in rs),
            "rows": len(rs),
            "df_ms": statistics.median(r["df_ms"] for r in rs),
        }
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
