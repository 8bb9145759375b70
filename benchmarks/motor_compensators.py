"""The friction compensators on the motor plants: how much each shrinks the cycle.

Three measurements, each printed as a table and collected in one JSON object on
the last line (docs/qube.md, "The compensators on a motor plant"):

1. ``nominal``: on the nominal ``qube2``, ``qube3`` and ``furuta-dc`` plants,
   classical and LuGre plant friction at the preset's levels, every
   compensator at its defaults: the shrink factor (peak-to-peak of the
   pendulum angle without over with the compensator, the compensated one
   counted as at least one 12-bit quantum, as ``compensate compare``).
2. ``levels``: the nominal QUBE-Servo 2 with its plant's F_C from 0 to 0.3 V
   (F_S = F_C + 0.05 V), the compensators keeping their default levels (tuned
   for F_C 0.15 V: over-compensating below it), noise-free and with
   ``sim.noise`` 0.002.
3. ``drawn``: ``--n`` QUBE-Servo 2 plants drawn as ``benchmarks/swingup.py``
   draws them (masses, lengths, R_m, k_t, k_m within +-20 %, F_C uniform in
   [0, 0.3] V, F_S in [F_C, F_C + 0.1] V, noise 0.002), the controller and
   the compensators those of the nominal plant: the median and the smallest
   shrink factor, how many runs are more than 1.25 times worse than without
   (shrink below 0.8) and how many fall.

Every run: fast design, 0.05 rad from upright, 30 s, features over the last 15 s.

Usage::

    .venv/bin/python benchmarks/motor_compensators.py [--n 40] [--seed 7]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from frictionlab import runs
from frictionlab.config import build_config
from frictionlab.model.limit_cycles import trajectory_features
from frictionlab.studies.compensation import PEAK_TO_PEAK_FLOOR

sys.path.insert(0, str(Path(__file__).parent))
from swingup import draw  # the same drawn plants

COMPENSATORS = ("classical", "lugre", "adaptive")
DURATION, WINDOW = 30.0, 15.0


def peak_to_peak(cfg, controller=None) -> float | None:
    """The run's pendulum peak-to-peak (rad), None when it fell."""
    traj = runs.simulate_config(cfg, DURATION, controller=controller)
    if traj.status == "fell":
        return None
    return float(trajectory_features(traj, WINDOW).peak_to_peak)


def shrink(base: float | None, comp: float | None) -> float | None:
    if base is None or comp is None:
        return None
    return base / max(comp, PEAK_TO_PEAK_FLOOR)


def fmt(x: float | None) -> str:
    return "fell" if x is None else f"{x:.2f}"


def nominal() -> list[dict]:
    rows = []
    print("nominal plants: shrink factor (peak-to-peak without, rad)")
    for plant in ("qube2", "qube3", "furuta-dc"):
        for fric in ("classical", "lugre"):
            base = peak_to_peak(build_config("fast", fric, "none", plant=plant))
            row = {"plant": plant, "friction": fric, "without": base}
            for c in COMPENSATORS:
                row[c] = shrink(base, peak_to_peak(build_config("fast", fric, c, plant=plant)))
            rows.append(row)
            print(f"  {plant:9s} {fric:9s} without {base:.4f}  "
                  + "  ".join(f"{c} {fmt(row[c])}" for c in COMPENSATORS))
    return rows


def levels() -> list[dict]:
    rows = []
    print("qube2, plant F_C (V) against the compensators' default levels: shrink factor")
    for noise in (0.0, 0.002):
        for fc in (0.0, 0.025, 0.05, 0.1, 0.15, 0.2, 0.3):
            sets = [f"friction.coulomb={fc}", f"friction.stiction={fc + 0.05}",
                    f"sim.noise={noise}"]
            base = peak_to_peak(build_config("fast", "classical", "none", sets=sets,
                                             plant="qube2"))
            row = {"noise": noise, "coulomb": fc, "without": base}
            for c in COMPENSATORS:
                row[c] = shrink(base, peak_to_peak(build_config("fast", "classical", c,
                                                                sets=sets, plant="qube2")))
            rows.append(row)
            print(f"  noise {noise:5.3f} F_C {fc:5.3f} without {base or 0:.4f}  "
                  + "  ".join(f"{c} {fmt(row[c])}" for c in COMPENSATORS))
    return rows


def drawn(n: int, seed: int) -> dict:
    common = [("sim.noise", 0.002)]
    out: dict = {}
    values = {c: [] for c in COMPENSATORS}
    base_fell = 0
    nominal_ctl = {c: runs.make_controller(build_config("fast", "classical", c, sets=common,
                                                        plant="qube2"))
                   for c in ("none", *COMPENSATORS)}
    for vals in draw(n, seed, "qube2"):
        sets = [*common, *vals.items()]
        base = peak_to_peak(build_config("fast", "classical", "none", sets=sets, plant="qube2"),
                            nominal_ctl["none"])
        if base is None:
            base_fell += 1
            continue
        for c in COMPENSATORS:
            pp = peak_to_peak(build_config("fast", "classical", c, sets=sets, plant="qube2"),
                              nominal_ctl[c])
            values[c].append(shrink(base, pp))
    print(f"{n} drawn QUBE-Servo 2 plants (noise 0.002; {base_fell} fell without "
          "compensation and are left out): shrink factor")
    for c in COMPENSATORS:
        ok = np.array([v for v in values[c] if v is not None])
        res = {"runs": len(values[c]), "fell": len(values[c]) - len(ok),
               "median": float(np.median(ok)), "min": float(ok.min()),
               "below_0_8": int((ok < 0.8).sum())}
        out[c] = res
        print(f"  {c:9s} median {res['median']:.2f}  min {res['min']:.2f}  "
              f"below 0.8: {res['below_0_8']}  fell: {res['fell']} of {res['runs']}")
    out["fell_without"] = base_fell
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=40, help="drawn plants (default 40)")
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    result = {"nominal": nominal(), "levels": levels(), "drawn": drawn(args.n, args.seed)}
    result["seconds"] = round(time.perf_counter() - t0, 1)
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
