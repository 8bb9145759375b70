r"""Table 1 (the rig) against the rig properties the thesis documents.

Prints, as JSON lines:

* ``periods`` - the fast and slow periods at the nominal set, and with each
  candidate switched on alone: the pivot friction of App. A.2
  (``plant.pivot_friction`` 0.3, with and without App. A.2's zeta 0.0125),
  the 12-bit converters (``sim.quantization`` 1), measurement noise
  (``sim.noise`` 0.002);
* ``fit`` - both rows of Table 1 by one set: differential evolution
  (``scipy.optimize.differential_evolution``, vectorised: one call of the
  compiled batch evaluator per generation) over the keys and bounds below,
  in the plausible box omega0 6.5-7.1, k_u 0.8-1.25; the cost is that of
  ``identify limit-cycle`` (sum of squared relative errors over the 12
  features, 10 for a missing one; a shoulder's missing valley compared as
  its peak2, a single maximum's peak2 and valley as its peak1), 40 s runs
  with the features over the last 20 s as ``frictionlab reproduce`` runs
  them; ``rms`` = sqrt(cost / 12), with the residuals;
* ``neighbourhood`` - RMS min / median / max over 100 sets within +-0.5 % of
  the fitted set and of ``reproduce``'s :data:`TABLE1_SET` (how much of the
  optimum survives the features' piecewise smoothness).

Usage::

    .venv/bin/python benchmarks/table1_rig.py [--seed 2] [--maxiter 80] [--popsize 15] [--no-pivot]

docs/identification.md, "What else the 1996 rig had", quotes its figures
(seed 1 and 2, 80 generations of 15 per key: about 4-5 min on the shared
2-core machine).
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

T1 = {"fast": (0.080, 0.095, 0.074, 1.1, 4.4, 2.0), "slow": (0.18, 0.22, 0.15, 2.1, 6.4, 5.2)}
COLS = ("peak1", "peak2", "valley", "period", "max_u", "max_arm_velocity")
BOUNDS = {
    "friction.coulomb": (0.2, 2.0), "friction.stiction": (0.2, 4.0),
    "plant.omega0": (6.5, 7.1), "plant.input_gain": (0.8, 1.25),
    "plant.pivot_friction": (0.0, 2.0), "plant.zeta": (0.0, 0.04),
    "actuator.curvature": (0.0, 0.2), "actuator.back_emf": (0.0, 5.0),
}


def _missing(v) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v))


def residuals(points: list[dict]) -> list[np.ndarray]:
    """The 12 relative errors of each point (both designs, one batch each)."""
    from frictionlab.config import build_config
    from frictionlab.studies.batch import evaluate_rows

    rows = {d: evaluate_rows(build_config(d, "classical"), points, 40.0, 20.0) for d in T1}
    out = []
    for i in range(len(points)):
        r = []
        for d, ref_row in T1.items():
            row = rows[d][i]
            for c, ref in zip(COLS, ref_row, strict=True):
                v = row.get(c)
                if c == "valley" and _missing(v):
                    v = row.get("peak2")
                if _missing(v):
                    v = row.get("peak1")
                ok = row.get("status") == "limit_cycle" and not _missing(v)
                r.append((v - ref) / ref if ok else 10.0)
        out.append(np.array(r))
    return out


def neighbourhood(center: dict, rel: float = 0.005, n: int = 100) -> dict:
    rng = np.random.default_rng(0)
    pts = [{k: v * (1 + rel * rng.uniform(-1, 1)) for k, v in center.items()} for _ in range(n)]
    rms = [100 * math.sqrt(float(np.mean(r * r))) for r in residuals(pts)]
    return {"min": round(min(rms), 1), "median": round(float(np.median(rms)), 1),
            "max": round(max(rms), 1)}


def main() -> None:
    from scipy.optimize import differential_evolution

    from frictionlab.studies.reproduce import TABLE1_SET

    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--maxiter", type=int, default=80)
    ap.add_argument("--popsize", type=int, default=15)
    ap.add_argument("--no-pivot", action="store_true")
    args = ap.parse_args()

    cand = {"nominal": {}, "pivot 0.3": {"plant.pivot_friction": 0.3},
            "pivot 0.3, zeta 0.0125": {"plant.pivot_friction": 0.3, "plant.zeta": 0.0125},
            "quantization": {"sim.quantization": 1.0}, "noise 0.002": {"sim.noise": 0.002}}
    from frictionlab.config import build_config
    from frictionlab.studies.batch import evaluate_rows

    periods = {}
    for d in T1:
        rows = evaluate_rows(build_config(d, "classical"), list(cand.values()), 40.0, 20.0)
        for name, row in zip(cand, rows, strict=True):
            periods.setdefault(name, {})[d] = round(row["period"], 4)
    print(json.dumps({"periods": periods}), flush=True)

    bounds = {k: v for k, v in BOUNDS.items()
              if not (args.no_pivot and k in ("plant.pivot_friction", "plant.zeta"))}
    keys = list(bounds)
    s_lo, s_hi = bounds["friction.stiction"]

    def point(x) -> dict:
        p = dict(zip(keys, (float(v) for v in x), strict=True))
        # the stiction's coordinate spans [max(lo, F_C), hi]: F_S >= F_C by construction
        lo = max(s_lo, p["friction.coulomb"])
        p["friction.stiction"] = lo + (p["friction.stiction"] - s_lo) / (s_hi - s_lo) * (s_hi - lo)
        return p

    def cost(x):
        x = np.asarray(x).reshape(len(keys), -1)
        return np.array([float(r @ r) for r in residuals([point(x[:, j])
                                                          for j in range(x.shape[1])])])

    res = differential_evolution(cost, list(bounds.values()), seed=args.seed,
                                 maxiter=args.maxiter, popsize=args.popsize, vectorized=True,
                                 updating="deferred", polish=False, tol=1e-6)
    best = point(res.x)
    r = residuals([best])[0]
    print(json.dumps({"fit": {"cost": round(float(r @ r), 4),
                              "rms": round(math.sqrt(float(r @ r) / 12), 4),
                              "set": {k: round(v, 5) for k, v in best.items()},
                              "residuals": [round(float(v), 3) for v in r],
                              "generations": int(res.nit)}}), flush=True)
    print(json.dumps({"neighbourhood": {"fit": neighbourhood(best),
                                        "TABLE1_SET": neighbourhood(dict(TABLE1_SET))}}))


if __name__ == "__main__":
    main()
