r"""The motor plant's balancing estimators on plants drawn within +-20 %.

For ``--n`` plants (default 300) drawn from the preset ``--plant`` (default
qube2) with the arm and pendulum masses and lengths and the motor's R_m, k_t
and k_m each uniform within +-20 % (as benchmarks/swingup.py's QUBE Monte
Carlo; :func:`frictionlab.studies.dc_robustness.draw_params`), the nominal
fast design's sampled closed loop at upright, linear
(:func:`frictionlab.studies.dc_robustness.loop_matrix`), is counted unstable
(spectral radius >= 1):

* with the true state fed back (no estimator: the reference),
* with the full-model predictor (``design.full_observer=1``) at the former
  default, observer_omega1 = 20/6.8 omega0 (36.6 rad/s on the QUBE-Servo 2),
* with the pendulum observer (the default) at each ``observer_omega1`` of
  ``--omegas`` (rad/s; ``default`` = the preset's).

Usage::

    .venv/bin/python benchmarks/dc_observer.py [--n 300] [--seed 1] [--plant qube2]
        [--omegas default,50,80]

Prints a table and a JSON object as the last line.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from frictionlab.config import build_config
from frictionlab.runs import make_controller
from frictionlab.studies.dc_robustness import draw_params, loop_matrix, spectral_radius


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--plant", default="qube2")
    ap.add_argument("--omegas", default="default,50,80")
    args = ap.parse_args()
    nominal = build_config(plant=args.plant)
    plants = draw_params(nominal.plant, args.n, args.seed)
    former = 20.0 / 6.8 * nominal.plant.omega0
    cases = {"true state": (make_controller(nominal), True),
             "full-model predictor": (make_controller(build_config(
                 plant=args.plant, sets=[("design.full_observer", 1),
                                         ("design.observer_omega1", former)])), False)}
    for w in args.omegas.split(","):
        sets = [] if w == "default" else [("design.observer_omega1", float(w))]
        c = make_controller(build_config(plant=args.plant, sets=sets))
        cases[f"pendulum observer, omega_o1 {c.design.spec.observer_omega1:.1f}"] = (c, False)
    out = {}
    print(f"{args.n} {args.plant} plants within +-20 %, nominal fast design")
    print(f"{'estimator':44s} {'unstable':>9s} {'nominal rho':>12s} {'max rho':>8s}")
    for name, (c, true) in cases.items():
        rho = np.array([spectral_radius(loop_matrix(c, p, true)) for p in plants])
        rho0 = spectral_radius(loop_matrix(c, nominal.plant, true))
        out[name] = {"unstable": int(np.sum(rho >= 1.0)), "n": args.n,
                     "nominal_radius": rho0, "max_radius": float(rho.max())}
        print(f"{name:44s} {out[name]['unstable']:9d} {rho0:12.4f} {rho.max():8.4f}")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
