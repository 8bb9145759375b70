r"""The balancing loop's margin on motor plants the design does not know.

For ``--n`` plants (default 1,000) drawn from the preset ``--plant`` (default
qube2) as in benchmarks/swingup.py's QUBE Monte Carlo (masses, lengths, R_m,
k_t and k_m each uniform within +-20 %;
:func:`frictionlab.studies.dc_robustness.draw_params`), the sampled linear
closed loop at upright of the design made for the NOMINAL plant
(:func:`frictionlab.studies.dc_robustness.loop_matrix`, the controller's own
compiled step with its default pendulum observer) is counted unstable
(spectral radius >= 1) and nearly so (> 0.995, a mode decaying slower than
1 /s at h = 5 ms), for

* the fast preset (the default), and
* the design for a plant it does not know
  (:data:`frictionlab.studies.swingup_sim.ROBUST_DESIGN`: design.omega2=5,
  design.zeta1=1, design.zeta2=1).

A loop that is stable but barely so holds the pendulum started near upright
and loses it after a swing-up's catch (docs/swingup.md, "Plants the design
does not know").

Usage::

    .venv/bin/python benchmarks/swingup_margin.py [--n 1000] [--seed 1] [--plant qube2]

Prints a table and a JSON object as the last line.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from frictionlab.config import build_config
from frictionlab.runs import make_controller
from frictionlab.studies.dc_robustness import draw_params, loop_matrix, spectral_radius
from frictionlab.studies.swingup_sim import ROBUST_DESIGN

#: Spectral radius above which a loop counts as nearly unstable.
NEAR = 0.995


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--plant", default="qube2")
    args = ap.parse_args()
    nominal = build_config(plant=args.plant)
    plants = draw_params(nominal.plant, args.n, args.seed)
    out = {"plant": args.plant, "n": args.n, "seed": args.seed, "designs": {}}
    print(f"{args.n} {args.plant} plants within +-20 %, designs for the nominal plant")
    print(f"{'design':28s} {'unstable':>9s} {'rho > ' + str(NEAR):>12s} {'max rho':>8s} "
          f"{'nominal rho':>12s}")
    for name, sets in (("fast (default)", ()), ("robust (ROBUST_DESIGN)", ROBUST_DESIGN)):
        c = make_controller(build_config(plant=args.plant, sets=list(sets)))
        rho = np.array([spectral_radius(loop_matrix(c, p, False)) for p in plants])
        rho0 = spectral_radius(loop_matrix(c, nominal.plant, False))
        row = {"unstable": int((rho >= 1).sum()), "near": int((rho > NEAR).sum()),
               "max_rho": float(rho.max()), "nominal_rho": float(rho0),
               "settings": dict(sets)}
        out["designs"][name] = row
        print(f"{name:28s} {row['unstable']:9d} {row['near']:12d} {row['max_rho']:8.4f} "
              f"{rho0:12.4f}")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
