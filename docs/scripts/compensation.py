"""Evidence for docs/compensation.md: tables (markdown on stdout) and figures.

Run: .venv/bin/python docs/scripts/compensation.py [--no-tune] [--workers N]

Every run: 30 s closed loop, features over the last 15 s, measurement noise
sim.noise = 0.002 (rad, rad, rad/s), seed 0, unless a table says otherwise.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

import numpy as np

from frictionlab.cli.compensate import plot_before_after
from frictionlab.config import build_config
from frictionlab.model.controller import ERROR_SIGNALS, Controller
from frictionlab.model.design import design as make_design
from frictionlab.model.friction import (
    FrictionParams,
    copy_friction,
    lugre_force,
    lugre_step_exact,
    stribeck_curve,
)
from frictionlab.runs import simulate_config
from frictionlab.studies.compensation import COMPENSATORS, compare, tune

FIG = Path(__file__).resolve().parent.parent / "figures"
DUR, WIN = 30.0, 15.0
NOISE = "sim.noise=0.002"
MATCHED = ["compensation.stiction=2.3", "compensation.coulomb=1.5", "compensation.viscous=0.07",
           "compensation.sigma0=100", "compensation.sigma1=5",
           "compensation.stribeck_velocity=1"]

#: plants: name -> (friction kind, sets)
PLANTS = {
    "classical (eq. 20)": ("classical", []),
    "classical, band 0.03": ("classical", ["friction.zero_velocity_band=0.03"]),
    "LuGre (eq. 21)": ("lugre", []),
    "rig-like": (None, []),  # per design: Sec. 5.2's best-matching plant omega0, F_C 1.3
    "rig-like LuGre, asymmetric, noisier": (None, ["sim.noise=0.005", "sim.quantization=1",
                                                   "friction.coulomb_negative=1.1",
                                                   "friction.stiction_negative=2.0"]),
}
RIG_LIKE = {"fast": ["plant.omega0=7.5", "friction.coulomb=1.3"],
            "slow": ["plant.omega0=6.1", "friction.coulomb=1.3"]}


def fmt(v, spec=".3g"):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return format(v, spec)


def plant(design: str, name: str):
    kind, sets = PLANTS[name]
    if kind is None:
        return ("lugre" if "LuGre" in name else "classical"), RIG_LIKE[design] + sets
    return kind, sets


class _FlippedGain:
    """A controller whose LuGre observer uses -k (the candidate signal with the
    opposite sign), for the error-signal comparison only."""

    def __init__(self, ctrl: Controller):
        self.ctrl = ctrl

    def record(self):
        gp, cp = self.ctrl.record()
        cp = copy_friction(cp)
        cp["k"] = -cp["k"]
        return gp, cp

    def init(self, theta0=0.0):
        return self.ctrl.init(theta0)


def controller(cfg, error_signal="velocity_innovation", feed_net=True):
    return Controller(make_design(cfg.design, cfg.plant), cfg.compensation_kind,
                      cfg.compensation, error_signal=error_signal, feed_net=feed_net)


def row_cells(status, f, chatter) -> str:
    """The cells of one run in the main table: status, features, chatter."""
    return (f"{status} | {fmt(f['peak_to_peak'])} | {fmt(f['period'])} | {fmt(f['max_u'])} | "
            f"{fmt(f['max_arm_velocity'])} | {fmt(chatter.reversals_per_s, '.1f')} | "
            f"{fmt(chatter.u_roughness, '.2f')}")


def cell(res):
    if res.status == "fell":
        return "fell"
    if res.features["peak_to_peak"] < 1e-6:
        return "settles exactly"
    return (f"{fmt(res.reduction, '.1f')}x ({fmt(res.chatter.reversals_per_s, '.1f')}/s, "
            f"{fmt(res.chatter.u_roughness, '.2f')})")


# ---------------------------------------------------------------------------


def main_table() -> None:
    print("\n### With and without compensation (Sec. 6 settings)\n")
    print("| design | plant friction | compensator | status | peak-to-peak [rad] | T [s] | "
          "max(u) | max(Ω̇) | reversals/s | u roughness | reduction |")
    print("|---" * 11 + "|")
    for design in ("fast", "slow"):
        for pname in PLANTS:
            kind, sets = plant(design, pname)
            base = None
            for cname in COMPENSATORS:
                cfg = build_config(design, kind, cname, sets=[NOISE, *sets])
                res = compare(cfg, DUR, WIN)
                if base is None:
                    base = res.baseline_features
                    print(f"| {design} | {pname} | none | "
                          f"{row_cells(res.baseline_status, base, res.baseline_chatter)} | 1 |")
                print(f"| | | {cname} | {row_cells(res.status, res.features, res.chatter)} | "
                      f"**{fmt(res.reduction, '.1f')}x** |")


def free_plant_table() -> None:
    print("\n### Nothing to compensate: friction-free plant\n")
    print("| design | compensator | status without | p-p without | status with | p-p with | "
          "T with | reversals/s |")
    print("|---" * 8 + "|")
    for design in ("fast", "slow"):
        for cname in COMPENSATORS:
            res = compare(build_config(design, "none", cname, sets=[NOISE]), DUR, WIN)
            print(f"| {design} | {cname} | {res.baseline_status} | "
                  f"{fmt(res.baseline_features['peak_to_peak'])} | {res.status} | "
                  f"{fmt(res.features['peak_to_peak'])} | {fmt(res.features['period'])} | "
                  f"{fmt(res.chatter.reversals_per_s, '.1f')} |")


def figures() -> None:
    for design in ("fast", "slow"):
        for cname in COMPENSATORS:
            cfg = build_config(design, "lugre", cname, sets=[NOISE])
            _, on, off = compare(cfg, DUR, WIN, return_trajectories=True)
            path = FIG / f"compensation_{design}_{cname}.png"
            plot_before_after(off, on, str(path), 8.0,
                              title=f"{design} design, LuGre plant (eq. 21), {cname} "
                                    "compensator (Sec. 6 settings), noise 0.002", dpi=70)
            print(f"figure: {path.relative_to(FIG.parent)}")


def error_signal_table() -> None:
    cases = {
        "matched": ("lugre", MATCHED),
        "σ0 300 vs 100": ("lugre", [*MATCHED, "compensation.sigma0=300"]),
        "Sec. 6 settings": ("lugre", []),
        "classical plant": ("classical", []),
        "rig-like plant": (None, []),
    }
    print("\n### The error signal e of eq. (19)\n")
    print("Reduction of the peak-to-peak (reversals of F̂ per second, u roughness in "
          "m/s² per sample); `fell` = the pendulum fell.  k = 7.\n")
    for design in ("fast", "slow"):
        print(f"\n**{design} design**\n")
        print("| e | sign | " + " | ".join(cases) + " |")
        print("|---|---" + "|---" * len(cases) + "|")
        for err in ERROR_SIGNALS:
            for flip in (False, True):
                if err == "none" and flip:
                    continue
                cells = []
                for kind, sets in cases.values():
                    if kind is None:
                        kind, sets = "classical", RIG_LIKE[design]
                    cfg = build_config(design, kind, "lugre",
                                       sets=[NOISE, *sets, "compensation.observer_gain=7"])
                    ctrl = controller(cfg, err)
                    res = compare(cfg, DUR, WIN,
                                  controller=_FlippedGain(ctrl) if flip else ctrl)
                    cells.append(cell(res))
                print(f"| {err} | {'-' if flip else '+'} | " + " | ".join(cells) + " |")


def noise_table() -> None:
    print("\n### Sensitivity to measurement noise (LuGre compensator, velocity innovation)\n")
    print("| design | plant | noise | quantised | baseline p-p | compensated p-p | "
          "reduction |")
    print("|---" * 7 + "|")
    for design in ("fast", "slow"):
        for kind in ("lugre", "classical"):
            for noise in (0.0, 0.002, 0.005, 0.01):
                for q in (0, 1):
                    if noise == 0.0 and q:
                        continue
                    cfg = build_config(design, kind, "lugre",
                                       sets=[f"sim.noise={noise}", f"sim.quantization={q}"])
                    res = compare(cfg, DUR, WIN)
                    print(f"| {design} | {kind} | {noise} | {'yes' if q else 'no'} | "
                          f"{fmt(res.baseline_features['peak_to_peak'])} | "
                          f"{fmt(res.features['peak_to_peak'])} | {cell(res)} |")


def feed_table() -> None:
    print("\n### What the observers are fed\n")
    print("| design | plant | compensator | observers get u − F̂ | observers get u |")
    print("|---|---|---|---|---|")
    for design in ("fast", "slow"):
        for kind in ("lugre", "classical"):
            for cname in COMPENSATORS:
                cfg = build_config(design, kind, cname, sets=[NOISE])
                a = compare(cfg, DUR, WIN, controller=controller(cfg, feed_net=True))
                b = compare(cfg, DUR, WIN, controller=controller(cfg, feed_net=False))
                print(f"| {design} | {kind} | {cname} | {cell(a)} | {cell(b)} |")


# ---------------------------------------------------------------------------
# discretisation of the bristle state
# ---------------------------------------------------------------------------


def observer_run(v, prm: FrictionParams, h: float, method: str) -> np.ndarray:
    """F_hat along the velocity sequence ``v`` (e = 0) with one update scheme."""
    p = prm.record()
    s0, s1, fv, fc, fs, vs = (prm.sigma0, prm.sigma1, prm.viscous, prm.coulomb,
                              prm.stiction, prm.stribeck_velocity)
    z = 0.0
    out = np.empty(len(v))
    with np.errstate(all="ignore"):
        for k, vk in enumerate(v):
            if method == "exact":
                z_new, zm, dzm = lugre_step_exact(vk, z, 0.0, h, p)
                out[k] = lugre_force(vk, zm, dzm, p)
                z = z_new
                continue
            a = s0 * abs(vk) / (fc + (fs - fc) * math.exp(-(vk / vs) ** 2))
            if method == "forward_euler":
                dz = vk - a * z
                z_new = z + h * dz
                out[k] = s0 * z + s1 * dz + fv * vk
            else:  # backward (implicit) Euler
                z_new = (z + h * vk) / (1.0 + a * h)
                dz = (z_new - z) / h
                out[k] = s0 * z_new + s1 * dz + fv * vk
            z = z_new if math.isfinite(z_new) else math.inf
    return out


def discretisation() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    h = 0.005
    print("\n### Bristle update at h = 5 ms\n")
    print("Observer driven (e = 0) by the measured arm velocity of an uncompensated "
          "fast-design limit cycle of a LuGre plant with the same σ0 (noise-free); "
          "error against the plant's true friction averaged over each sample, where "
          "|Ω̇| > 0.3 rad/s.  `diverged` = the estimate overflowed.\n")
    print("| σ0 | max ah | exact: max error | backward Euler | forward Euler | "
          "steady sliding v = 1: exact | forward Euler |")
    print("|---" * 7 + "|")
    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for sigma0 in (100.0, 300.0, 1000.0):
        cfg = build_config("fast", "lugre", "none", sets=[f"friction.sigma0={sigma0}"])
        traj = simulate_config(cfg, 10.0)
        v = traj["arm_dot_m"]
        truth = traj["friction"]
        prm = dataclasses.replace(cfg.friction, observer_gain=0.0)
        sliding = np.abs(v) > 0.3
        a_max = np.max(sigma0 * np.abs(v) / (prm.coulomb + (prm.stiction - prm.coulomb)
                                            * np.exp(-(v / prm.stribeck_velocity) ** 2)))
        cells = []
        for method in ("exact", "backward_euler", "forward_euler"):
            f = observer_run(v, prm, h, method)
            if not np.all(np.isfinite(f)):
                k_bad = int(np.argmax(~np.isfinite(f)))
                cells.append(f"diverged at t = {k_bad * h:.2f} s")
            else:
                cells.append(f"{np.max(np.abs(f - truth)[sliding]):.3g}")
            if sigma0 == 1000.0 and method != "backward_euler":
                ax = axes[0] if method == "exact" else axes[1]
                t = traj.t
                m = t < 4.0
                ax.plot(t[m], truth[m], color="C3", lw=1.0, label="plant friction")
                ax.plot(t[m], np.clip(f[m], -20, 20), "--", color="C0", lw=0.9,
                        label=f"observer, {method.replace('_', ' ')}")
                ax.set_ylim(-8, 8)
                ax.set_ylabel(r"friction [m/s$^2$]")
                ax.legend(loc="upper right", fontsize=8)
                ax.grid(alpha=0.3)
        steady = []
        for method in ("exact", "forward_euler"):
            f = observer_run(np.full(400, 1.0), prm, h, method)
            err = abs(f[-1] - stribeck_curve(1.0, prm.record()))
            steady.append(f"{err:.2g}" if np.isfinite(err) else "diverged")
        print(f"| {sigma0:g} | {a_max * h:.2f} | " + " | ".join(cells + steady) + " |")
    axes[1].set_xlabel("time [s]")
    fig.suptitle(r"LuGre observer at $\sigma_0$ = 1000, h = 5 ms (fast-design limit cycle)",
                 fontsize=10)
    fig.tight_layout()
    path = FIG / "compensation_discretisation.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    print(f"\nfigure: {path.relative_to(FIG.parent)}")


# ---------------------------------------------------------------------------


def tuned(workers: int | None) -> None:
    print("\n### Tuned compensators (`frictionlab compensate tune`, default grids)\n")
    print("| design | plant | compensator | best settings | peak-to-peak | reversals/s | "
          "reduction | points (fell) |")
    print("|---" * 8 + "|")
    for design in ("fast", "slow"):
        for kind in ("lugre", "classical"):
            for cname in COMPENSATORS:
                cfg = build_config(design, kind, cname, sets=[NOISE])
                res = tune(cfg, duration=DUR, workers=workers)
                best = ", ".join(f"{k.split('.')[1]} {v:g}" for k, v in res.best.items())
                print(f"| {design} | {kind} | {cname} | {best} | {fmt(res.peak_to_peak)} | "
                      f"{fmt(res.chatter.reversals_per_s, '.1f')} | "
                      f"{fmt(res.reduction, '.1f')}x | {res.evaluated} ({res.failed}) |")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--no-tune", action="store_true")
    ap.add_argument("--only", default=None, help="comma-separated parts to run")
    ap.add_argument("--workers", type=int, default=None)
    args = ap.parse_args()
    FIG.mkdir(exist_ok=True)
    parts = {"main": main_table, "free": free_plant_table, "figures": figures,
             "error": error_signal_table,
             "noise": noise_table, "feed": feed_table, "discretisation": discretisation,
             "tune": lambda: tuned(args.workers)}
    chosen = args.only.split(",") if args.only else list(parts)
    if args.no_tune and "tune" in chosen:
        chosen.remove("tune")
    for name in chosen:
        parts[name]()


if __name__ == "__main__":
    main()
