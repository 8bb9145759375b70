"""Evidence for docs/predict.md: how close the two predictions come to long runs.

Run (about 4 minutes): .venv/bin/python docs/scripts/predict_study.py [--random 30] [--seed 1]

Prints markdown tables on stdout and writes docs/figures/predict_study.png and
docs/figures/predict_fast.png.  Reference for every case: a 300 s run of
``simulate`` with the features over its last 200 s.  Cases:

* the Table 2-5 grids with the settings of ``frictionlab reproduce``:
  classical friction, F_C in 1.1..1.9 at F_S 2.3 and F_S in 1.9..2.7 at
  F_C 1.5, on the fast design with the 0.03 rad/s zero-velocity band of Sec.
  5.2 (Tables 2, 3) and on the slow design with 0.001 rad/s (Tables 4, 5);
* random parameter sets (:func:`random_sets`);
* a design scan for loops without a stable cycle.
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
import time
from pathlib import Path

import numpy as np

from frictionlab.config import build_config
from frictionlab.model.limit_cycles import FEATURES, features
from frictionlab.model.periodic import orbit_trajectory, periodic_orbit
from frictionlab.runs import loop_spec, run_features, simulate_config
from frictionlab.studies.predict import describing_function, plot_prediction, predict

FIG = Path(__file__).resolve().parent.parent / "figures"
LONG, WINDOW = 300.0, 200.0
BAND = "friction.zero_velocity_band=0.03"
TABLE_BAND = {"fast": BAND, "slow": "friction.zero_velocity_band=0.001"}
REST = 0.05  # rad/s: |arm velocity| below this counts as (near) rest


def table_cases():
    """(label, design, friction, sets) of the Table 2-5 grids."""
    out = []
    for design, tables in (("fast", ("2", "3")), ("slow", ("4", "5"))):
        for table, key, values in ((tables[0], "friction.coulomb", (1.1, 1.3, 1.5, 1.7, 1.9)),
                                   (tables[1], "friction.stiction", (1.9, 2.1, 2.3, 2.5, 2.7))):
            for v in values:
                out.append((f"T{table} {key.split('.')[1]} {v}", design, "classical",
                            [TABLE_BAND[design], f"{key}={v}"]))
    return out


def random_sets(n: int, seed: int):
    """``n`` random loops: design, friction model and levels, plant omega0 and k_u.

    Design fast or slow; friction classical (band 0.03), Coulomb (eps 0 or
    0.05), Stribeck-classical or LuGre; F_C in [1.1, 1.9], F_S in [F_C, 2.7];
    plant omega0 in [6.1, 7.5] (the range Sec. 5.2 tried); input gain k_u in
    [0.8, 1.2]; LuGre sigma0 in [100, 1000], sigma1 in [2, 8].
    """
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        design = str(rng.choice(["fast", "slow"]))
        kind = str(rng.choice(["classical", "coulomb", "stribeck", "lugre"]))
        fc = rng.uniform(1.1, 1.9)
        fs = rng.uniform(fc, 2.7)
        sets = [f"friction.coulomb={fc:.3f}", f"friction.stiction={fs:.3f}",
                f"plant.omega0={rng.uniform(6.1, 7.5):.3f}",
                f"plant.input_gain={rng.uniform(0.8, 1.2):.3f}"]
        if kind == "classical":
            sets.append(BAND)
        elif kind == "coulomb":
            sets.append(f"friction.hysteresis={rng.choice([0.0, 0.05])}")
        elif kind == "lugre":
            sets += [f"friction.sigma0={rng.uniform(100, 1000):.0f}",
                     f"friction.sigma1={rng.uniform(2, 8):.2f}"]
        out.append((f"R{i}", design, kind, sets))
    return out


def rel(a, b):
    if a is None or b is None:
        return None if a is b else math.inf
    return (a - b) / abs(b) if b != 0 else (0.0 if a == 0 else math.inf)


def fundamental(traj, name, period):
    """Amplitude of the first harmonic of ``traj[name]`` over one period from t = 0."""
    t = traj.t
    m = t < period
    y = traj[name][m]
    return float(2.0 / m.sum() * abs(np.sum(y * np.exp(-2j * np.pi * t[m] / period))))


def reference(cfg):
    """Features of the 300 s run over its last 200 s, and how much they move
    (largest relative range over the features) when the 200 s window ends
    anywhere in 300..320 s instead."""
    traj = simulate_config(cfg, LONG + 20.0)
    feats = []
    for end in np.linspace(LONG, LONG + 20.0, 9):
        m = traj.t <= end + 1e-9
        feats.append(features(traj.t[m], traj["theta_m"][m], traj["u"][m],
                              traj["arm_dot_m"][m], window=WINDOW,
                              fell=traj.status == "fell" and end >= traj.t[-1]))
    ref = feats[0]
    spread = 0.0
    for k in FEATURES:
        vals = [getattr(f, k) for f in feats]
        if all(v is not None for v in vals) and getattr(ref, k):
            spread = max(spread, (max(vals) - min(vals)) / abs(getattr(ref, k)))
    return ref, spread


def evaluate(case):
    label, design, kind, sets = case
    cfg = build_config(design, kind, sets=sets)
    ref, spread = reference(cfg)
    t0 = time.perf_counter()
    po = periodic_orbit(loop_spec(cfg))
    t_orbit = time.perf_counter() - t0
    df = describing_function(cfg)
    row = {"label": label, "design": design, "kind": kind, "sets": sets, "ref": ref,
           "spread": spread, "po": po, "df": df, "t_orbit": t_orbit}
    if po.found:
        row["err"] = {k: rel(getattr(po.features, k), getattr(ref, k)) for k in FEATURES}
        traj = orbit_trajectory(loop_spec(cfg), po.state, po.period + cfg.design.h)
        row["v1"] = fundamental(traj, "arm_dot", po.period)
        row["th1"] = fundamental(traj, "theta", po.period)
        v = np.abs(traj["arm_dot"][traj.t < po.period])
        row["rest"] = float(np.mean(v < REST))
    return row


def fmt(x, pct=False):
    if x is None:
        return "-"
    if isinstance(x, float) and not math.isfinite(x):
        return "n/a"
    return f"{100 * x:+.2f}%" if pct else f"{x:.3g}"


def worst(err):
    vals = [abs(v) for v in err.values() if v is not None]
    return max(vals) if vals else None


def print_orbit_table(rows):
    print("| case | sim status | orbit | max error | reference spread | peak1 | valley | period "
          "| max u | max arm vel. | max abs(mu) | ms |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        po, ref = r["po"], r["ref"]
        if not po.found:
            print(f"| {r['label']} | {ref.status} | not found: {po.message} | | | | | | | | | "
                  f"{1e3 * r['t_orbit']:.0f} |")
            continue
        e = r["err"]
        mu = float(np.abs(po.floquet_multipliers).max())
        print(f"| {r['label']} | {ref.status} | {'stable' if po.stable else 'unstable'} | "
              f"{fmt(worst(e), True)} | {100 * r['spread']:.2f}% | {fmt(e['peak1'], True)} | "
              f"{fmt(e['valley'], True)} | "
              f"{fmt(e['period'], True)} | {fmt(e['max_u'], True)} | "
              f"{fmt(e['max_arm_velocity'], True)} | {mu:.3f} | {1e3 * r['t_orbit']:.0f} |")


def print_df_table(rows):
    print("| case | rest % of period | DF period | orbit period | error | DF A (arm vel.) "
          "| orbit fundamental | error | max arm vel. | DF pendulum | orbit fundamental "
          "| error |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        df, po = r["df"], r["po"]
        if not po.found:
            continue
        if df.amplitude is None:
            print(f"| {r['label']} | {100 * r['rest']:.0f} | none ({df.message}) | "
                  f"{fmt(po.period)} | | | | | | | | |")
            continue
        print(f"| {r['label']} | {100 * r['rest']:.0f} | {df.period:.3f} | {po.period:.3f} | "
              f"{fmt(rel(df.period, po.period), True)} | {df.amplitude:.3f} | {r['v1']:.3f} | "
              f"{fmt(rel(df.amplitude, r['v1']), True)} | "
              f"{po.features.max_arm_velocity:.3f} | {df.pendulum_amplitude:.4f} | "
              f"{r['th1']:.4f} | {fmt(rel(df.pendulum_amplitude, r['th1']), True)} |")


def design_scan():
    """Loops with and without a stable cycle: a grid of state-feedback designs
    (fast design's observers, classical friction with band 0.03), the slow arm
    loop and the compensators."""
    grid = []
    for w1, z1, w2, z2 in itertools.product((4.0, 6.8, 10.0, 15.0), (0.4, 0.7, 1.0),
                                            (1.0, 3.0, 10.0, 20.0), (0.4, 0.7, 1.0)):
        cfg = build_config("fast", "classical", sets=[
            BAND, f"design.omega1={w1}", f"design.zeta1={z1}", f"design.omega2={w2}",
            f"design.zeta2={z2}"])
        ref = run_features(cfg, LONG, WINDOW)
        pr = predict(cfg)
        grid.append((ref, pr))
    print(f"{len(grid)} designs: omega1 in 4, 6.8, 10, 15; zeta1 in 0.4, 0.7, 1; omega2 in 1, "
          "3, 10, 20; zeta2 in 0.4, 0.7, 1 (rad/s; fast design's observers, classical "
          "friction, band 0.03)\n")
    print("| 300 s run | designs | periodic orbit found, stable | found, unstable | not found "
          "| DF: stable cycle predicted | DF pendulum amplitude (rad) |")
    print("|---|---|---|---|---|---|---|")
    for status in ("limit_cycle", "settled", "fell"):
        rows = [(r, p) for r, p in grid if r.status == status]
        if not rows:
            print(f"| {status} | 0 | | | | | |")
            continue
        po = [p.periodic_orbit for _r, p in rows]
        amps = [p.describing_function.pendulum_amplitude for _r, p in rows
                if p.describing_function.pendulum_amplitude is not None]
        print(f"| {status} | {len(rows)} | {sum(o.found and o.stable for o in po)} | "
              f"{sum(o.found and not o.stable for o in po)} | {sum(not o.found for o in po)} | "
              f"{len(amps)} | {min(amps):.3f} .. {max(amps):.3f} |")
    cases = []
    for design in ("fast", "slow"):
        for comp in ("coulomb", "classical", "lugre"):
            cases.append((f"{design}, {comp} compensation", design, "classical", comp, [BAND]))
        cases.append((f"{design}, viscous friction only", design, "viscous", "none", []))
    print("\n| loop | 300 s run | periodic orbit | largest feature error | DF |")
    print("|---|---|---|---|---|")
    for label, design, kind, comp, sets in cases:
        cfg = build_config(design, kind, comp, sets=sets)
        ref = run_features(cfg, LONG, WINDOW)
        pr = predict(cfg)
        po, df = pr.periodic_orbit, pr.describing_function
        if po.found:
            mu = float(np.abs(po.floquet_multipliers).max())
            orbit = (f"{'stable' if po.stable else 'unstable'}, T {po.period:.3f} s, "
                     f"max abs(mu) {mu:.3g}")
        else:
            orbit = f"not found ({po.message})"
        dfs = (f"A {df.amplitude:.3g} rad/s, T {df.period:.3g} s" if df.amplitude is not None
               else f"none ({df.message})")
        status = ref.status + (f", T {ref.period:.3f} s" if ref.status == "limit_cycle"
                               else "")
        err = (fmt(worst({k: rel(getattr(po.features, k), getattr(ref, k))
                          for k in FEATURES}), True) if po.found else "")
        print(f"| {label} | {status} | {orbit} | {err} | {dfs} |")
        print(f"  {label}", file=sys.stderr)


def figure(table_rows, random_rows, path):
    from frictionlab.plotting import axis_label, plt, save_figure

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
    ax = axes[0]
    for rows, marker, name in ((table_rows, "o", "Table 2-5 rows"),
                               (random_rows, "s", "random sets")):
        x = [i for i, r in enumerate(rows) if r["po"].found]
        y = [max(worst(r["err"]), 1e-6) for r in rows if r["po"].found]
        ax.semilogy(x, y, marker, ls="none", label=name, mfc="none")
    ax.axhline(0.01, color="k", ls="--", lw=0.8, label="1 %")
    ax.set_xlabel(axis_label("loop (index)", "1"))
    ax.set_ylabel(axis_label("largest relative feature error vs 300 s run", "1"))
    ax.set_title("periodic orbit", fontsize=10)
    ax.legend(fontsize=8, loc="lower left")
    ax.grid(alpha=0.3, which="both")
    rows = [r for r in table_rows + random_rows if r["po"].found and r["df"].amplitude]
    rest = np.array([100 * r["rest"] for r in rows])
    for ax, key, name in ((axes[1], "period", "period"),
                          (axes[2], "amp", "arm-velocity amplitude")):
        if key == "period":
            err = [100 * rel(r["df"].period, r["po"].period) for r in rows]
        else:
            err = [100 * rel(r["df"].amplitude, r["v1"]) for r in rows]
        for design, marker in (("fast", "o"), ("slow", "^")):
            m = np.array([r["design"] == design for r in rows])
            ax.plot(rest[m], np.array(err)[m], marker, ls="none", mfc="none",
                    label=f"{design} design")
        ax.axhline(0, color="k", lw=0.8)
        ax.set_xlabel(axis_label("arm at rest (|arm vel.| < 0.05 rad/s)", "% of the period"))
        ax.set_ylabel(axis_label(("amplitude error vs orbit's 1st harmonic" if key == "amp"
                                  else "period error vs the orbit"), "%"))
        ax.set_title(f"describing function: {name}", fontsize=10)
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    fig.suptitle("Predictions against 300 s simulations: Table 2-5 grids (classical friction) "
                 "and random parameter sets", fontsize=10)
    save_figure(fig, str(path))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--random", type=int, default=30)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--skip", type=int, default=0)
    args = ap.parse_args()
    table_rows, random_rows = [], []
    for case in table_cases():
        print(f"  {case[0]}", file=sys.stderr)
        table_rows.append(evaluate(case))
    for case in random_sets(args.random, args.seed)[args.skip:]:
        print(f"  {case[0]}", file=sys.stderr)
        random_rows.append(evaluate(case))
    print("\n### Periodic orbit against the long run: Table 2-5 grids\n")
    print_orbit_table(table_rows)
    print("\n### Periodic orbit against the long run: random sets\n")
    for r in random_rows:
        print(f"* {r['label']}: {r['design']} design, {r['kind']}, " + ", ".join(r["sets"]))
    print()
    print_orbit_table(random_rows)
    print("\n### Describing function against the periodic orbit\n")
    print_df_table(table_rows + random_rows)
    print("\n### Loops with and without a stable cycle\n")
    design_scan()
    figure(table_rows, random_rows, FIG / "predict_study.png")
    cfg = build_config("fast", "classical", sets=[BAND])
    plot_prediction(cfg, predict(cfg), str(FIG / "predict_fast.png"))


if __name__ == "__main__":
    main()
