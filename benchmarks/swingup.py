r"""Swing-up robustness: success rate and catch time over randomised plants.

Each of ``--n`` plants (default 200) draws, from a generator seeded with
``--seed``: the plant's Coulomb level F_C uniform in [0.5, 3] m/s^2, its
stiction F_S uniform in [F_C, F_C + 1], its natural frequency omega0 uniform
in [6.1, 7.5] rad/s (around the nominal 6.8), and a measurement-noise seed;
classical friction (thesis zero-velocity band), the fast design with
``design.omega0`` = ``--design-omega0`` (default 6.2, the low end of the
plants' range: a mismatch of -2 % to +21 %), no compensation, the swing-up's
defaults, measurement noise 0.002 (rad, rad, rad/s), starting hanging at
rest.  A plant is a success when the
run (``--duration`` s, default 20, the swing-up's time limit) reaches the
balancing phase and is still balancing at the end (status ``limit_cycle``
or ``settled``).

Prints one line per failure, the success rate, catch-time statistics, and a
JSON object as the last line; ``--plot PATH`` writes the map figure
(success and catch time over F_C, F_S and the omega0 mismatch).

Usage::

    .venv/bin/python benchmarks/swingup.py [--n 200] [--seed 1] \
        [--plot docs/figures/swingup_map.png]
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

from frictionlab.config import build_config
from frictionlab.studies.swingup_sim import simulate_swingup, swingup_outcome

#: The omega0 the plants' natural frequencies are drawn around (and the default design's).
NOMINAL_OMEGA0 = 6.8
#: The design's omega0 in this benchmark: the low end of the plants' range (the fast
#: design tolerates a plant faster than designed, +21 %, but not one 5 % slower;
#: docs/swingup.md).  ``--design-omega0 6.8`` gives the nominal design's numbers.
DESIGN_OMEGA0 = 6.2


def draw(n: int, seed: int) -> list[dict]:
    """The randomised plants (key -> value), reproducible from ``seed``."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        fc = rng.uniform(0.5, 3.0)
        out.append({"friction.coulomb": fc, "friction.stiction": fc + rng.uniform(0.0, 1.0),
                    "plant.omega0": rng.uniform(6.1, 7.5), "sim.seed": i})
    return out


def run_one(values: dict, duration: float, noise: float, design_omega0: float) -> dict:
    sets = [("sim.initial_angle", math.pi), ("sim.noise", noise),
            ("design.omega0", design_omega0), *values.items()]
    cfg = build_config("fast", "classical", sets=sets)
    res = simulate_swingup(cfg, duration)
    status, _ = swingup_outcome(res)
    ok = status in ("limit_cycle", "settled")
    return {**values, "design.omega0": design_omega0, "status": status, "success": ok,
            "catch_time": res.swing_up_time,
            "catches": res.catches, "stop_reason": res.stop_reason,
            "max_u_swinging": res.max_u_swinging,
            "max_u": float(np.abs(res.trajectory["u"]).max())}


def plot(rows: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fc = np.array([r["friction.coulomb"] for r in rows])
    fs = np.array([r["friction.stiction"] for r in rows])
    mis = np.array([100 * (r["plant.omega0"] / r["design.omega0"] - 1) for r in rows])
    ok = np.array([r["success"] for r in rows])
    tc = np.array([np.nan if r["catch_time"] is None else r["catch_time"] for r in rows])
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8))
    fig.subplots_adjust(bottom=0.22, top=0.88, right=0.82)
    for ax, x, xl in ((axes[0], fc, "plant Coulomb level F_C (m/s$^2$)"),
                      (axes[1], mis, f"plant omega0 mismatch vs the design's "
                                     f"{rows[0]['design.omega0']:g} rad/s (%)")):
        sc = ax.scatter(x[ok], fs[ok] - fc[ok], c=tc[ok], cmap="viridis", marker="o", s=28,
                        label="caught and balancing (colour: catch time)")
        if (~ok).any():
            ax.scatter(x[~ok], fs[~ok] - fc[~ok], c="red", marker="x", s=50,
                       label="failed")
        ax.set_xlabel(xl)
        ax.set_ylabel("F_S - F_C (m/s$^2$)")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=9)
    cb = fig.colorbar(sc, cax=fig.add_axes((0.85, 0.22, 0.02, 0.66)))
    cb.set_label("catch time (s)")
    fig.suptitle(f"Swing-up from hanging, fast design (omega0 {rows[0]['design.omega0']:g} "
                 f"rad/s), classical friction, noise 0.002: {ok.sum()}/{len(ok)} caught and "
                 "balancing")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--noise", type=float, default=0.002)
    ap.add_argument("--design-omega0", type=float, default=DESIGN_OMEGA0)
    ap.add_argument("--plot", metavar="PATH")
    args = ap.parse_args()
    t0 = time.perf_counter()
    rows = [run_one(v, args.duration, args.noise, args.design_omega0)
            for v in draw(args.n, args.seed)]
    seconds = time.perf_counter() - t0
    for r in rows:
        if not r["success"]:
            print(f"failed: F_C {r['friction.coulomb']:.2f} F_S {r['friction.stiction']:.2f} "
                  f"omega0 {r['plant.omega0']:.2f} seed {r['sim.seed']}: {r['status']} "
                  f"{r['stop_reason']} catches {r['catches']}")
    ok = [r for r in rows if r["success"]]
    tc = np.array([r["catch_time"] for r in ok])
    rate = len(ok) / len(rows)
    summary = {
        "plants": len(rows), "successes": len(ok), "success_rate": rate,
        "catch_time_s": {"median": float(np.median(tc)) if len(tc) else None,
                         "p90": float(np.percentile(tc, 90)) if len(tc) else None,
                         "max": float(tc.max()) if len(tc) else None},
        "max_u_swinging": max(r["max_u_swinging"] for r in rows),
        "max_u": max(r["max_u"] for r in rows),
        "first_catch_fraction": (sum(1 for r in ok if r["catches"] == 1) / len(ok)
                                 if ok else None),
        "seconds": round(seconds, 2),
    }
    print(f"{len(ok)}/{len(rows)} plants caught and balancing ({100 * rate:.1f} %)")
    if len(tc):
        print(f"catch time: median {summary['catch_time_s']['median']:.2f} s, "
              f"90th percentile {summary['catch_time_s']['p90']:.2f} s, "
              f"max {summary['catch_time_s']['max']:.2f} s")
    print(f"largest |u| while swinging {summary['max_u_swinging']:.2f} m/s^2, "
          f"overall {summary['max_u']:.2f} m/s^2; {seconds:.1f} s")
    if args.plot:
        plot(rows, args.plot)
        summary["plot"] = args.plot
        print(f"figure: {args.plot}")
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
