r"""The simulated identification experiments: CPU per tick and the estimates.

Each experiment of ``frictionlab identify experiment NAME --simulate`` (stiction,
stribeck, free-oscillation, control-scaling) runs its schedule - the rig's,
:mod:`frictionlab.realtime.experiment` - against the simulated rig of
docs/identification.md's example figures (F_S 2.1, F_C 1.35, F_v 0.05, omega_0
7.1, zeta 0.06, k_u 1.2, ``sim.noise`` 0.002, seed 5) and is analysed.  Printed
per experiment: the ticks, the CPU seconds of the best of ``--repeats`` runs,
the CPU per tick (us) and the estimates against the true values.  The last
printed line is a JSON object.

To compare two trees, run it with each tree's ``src`` first on ``PYTHONPATH``,
alternating (docs/performance.md, "One schedule per experiment").

Usage::

    .venv/bin/python benchmarks/sim_experiments.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import time

from frictionlab.config import build_config
from frictionlab.studies.identification import experiments as ex

TRUE = {"friction.stiction": 2.1, "friction.coulomb": 1.35, "friction.viscous": 0.05,
        "plant.omega0": 7.1, "plant.zeta": 0.06, "plant.input_gain": 1.2}
#: experiment -> (friction model, simulate, analyse, {estimate: true value})
CASES = {
    "stiction": ("classical", ex.simulate_stiction,
                 lambda log: ex.analyse_stiction(log, input_gain=1.2),
                 {"stiction": 2.1, "coulomb": 1.35}),
    "stribeck": ("lugre", ex.simulate_stribeck,
                 lambda log: ex.analyse_stribeck(log, input_gain=1.2),
                 {"coulomb": 1.35, "viscous": 0.05, "stiction": 2.1}),
    "free-oscillation": ("classical", ex.simulate_free_oscillation,
                         lambda log: ex.analyse_free_oscillation(_free_decay(log)),
                         {"omega0": 7.1, "zeta": 0.06}),
    "control-scaling": ("classical", ex.simulate_control_scaling,
                        lambda log: ex.analyse_control_scaling(log, coulomb=1.35),
                        {"input_gain": 1.2}),
}


def _free_decay(log):
    # from the mark "free" (a tree before the shared schedules released the pendulum
    # at an angle: all of its log is free)
    keep = log["t"] >= log.meta.get("marks", {}).get("free", 0.0)
    return {"t": log["t"][keep], "theta_m": log["theta_m"][keep]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3, help="runs per experiment (best CPU)")
    args = ap.parse_args()
    out = {}
    for name, (friction, simulate, analyse, truth) in CASES.items():
        cfg = build_config(friction=friction, sets=[*TRUE.items(), ("sim.noise", 0.002),
                                                    ("sim.seed", 5)])
        simulate(cfg)  # compile or load the compiled code
        best = None
        for _ in range(args.repeats):
            c = time.process_time()
            log = simulate(cfg)
            c = time.process_time() - c
            best = c if best is None else min(best, c)
        res = analyse(log)
        errors = {k: (res[k] - v) / v for k, v in truth.items()}
        out[name] = {"ticks": len(log), "cpu_s": best, "us_per_tick": 1e6 * best / len(log),
                     "relative_error": errors}
        print(f"{name:17s} {len(log):6d} ticks  CPU {best:.3f} s  "
              f"{1e6 * best / len(log):5.1f} us/tick  "
              + "  ".join(f"{k} {100 * e:+.2f} %" for k, e in errors.items()), flush=True)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
