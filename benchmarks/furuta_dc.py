r"""The DC-motor Furuta plant's tick: accuracy against solve_ivp and its cost.

Prints, for the QUBE-Servo 2 preset (:data:`frictionlab.model.plants.furuta_dc.QUBE2`)
at h = 5 ms and ``substeps`` 1, 2, 5 and 10 per sample:

* ``driven_error``: the largest state error (rad, rad/s) of a 4 s driven run
  (u = 1 + 3 sin(2.7 t) V held over each sample, from theta = pi - 0.5, no
  friction) against ``solve_ivp`` (DOP853, rtol 1e-11, atol 1e-12) restarted
  every sample with the same held u;
* ``energy_drift``: the relative change of the total mechanical energy over
  10 s of free swinging (theta = 2.5 rad, theta_dot = 1, arm_dot = 3; no
  damping, back-EMF, friction or input);
* ``us_per_tick``: CPU time of one tick inside a compiled loop of 6000
  ticks (30 s; min of ``--repeats``), next to the thesis plant's
  :func:`frictionlab.model.plants.thesis.tick` at its default steps
  (classical friction, 10 substeps, 2 pendulum steps) in the same loop.

It also runs the designs of :mod:`frictionlab.model.plants.furuta_dc_design`
on the presets in a plain closed loop (the tick, the predictor observer,
u = -L xhat saturated at the voltage limit, exact measurements, from
theta = 0.1 rad, classical friction at the preset's levels, 20 s):
``closed_loop`` gives theta's amplitude and period over the last 10 s and
the largest |u|, or when it fell; ``substep_error`` the largest relative
change of amplitude and period of the QUBE-Servo 2's fast-design cycle
against 100 substeps.

Usage: ``.venv/bin/python benchmarks/furuta_dc.py [--repeats N]``;
``--plot PNG`` draws the QUBE-Servo 2's fast-design limit cycles instead.  The last
line is a JSON object.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

from frictionlab.model.friction import KINDS, FrictionParams  # noqa: E402
from frictionlab.model.plants.furuta_dc import (  # noqa: E402
    PRESET_FRICTION,
    PRESETS,
    QUBE2,
    mechanical_energy,
    rhs,
    tick,
)
from frictionlab.model.plants.furuta_dc_design import (  # noqa: E402
    dc_design,
    dc_observer_step,
    dc_spec,
    observer_row,
)
from frictionlab.model.plants.thesis import PlantParams  # noqa: E402
from frictionlab.model.plants.thesis import tick as plant_tick  # noqa: E402

H = 0.005


def driven_error(substeps: int) -> float:
    pp = QUBE2.record()
    fp = FrictionParams().record()
    x = np.array([math.pi - 0.5, 0.0, 0.0, 0.0, 0.0])
    y = x[:4].copy()
    err = 0.0
    for k in range(int(4.0 / H)):
        u = 1.0 + 3.0 * math.sin(2.7 * k * H)
        tick(x, u, 0.0, substeps, 1, H, pp, 0, fp)
        sol = solve_ivp(lambda t, s, u=u: rhs(t, s, u, QUBE2), (0.0, H), y, method="DOP853",
                        rtol=1e-11, atol=1e-12)
        y = sol.y[:, -1]
        err = max(err, float(np.max(np.abs(x[:4] - y))))
    return err


def energy_drift(substeps: int) -> float:
    p0 = dataclasses.replace(QUBE2, arm_damping=0.0, pendulum_damping=0.0, emf_constant=0.0)
    pp = p0.record()
    fp = FrictionParams().record()
    x = np.array([2.5, 1.0, 0.0, 3.0, 0.0])
    e0 = mechanical_energy(x, p0)
    for _ in range(int(10.0 / H)):
        tick(x, 0.0, 0.0, substeps, 1, H, pp, 0, fp)
    return abs(mechanical_energy(x, p0) - e0) / abs(e0)


@njit(cache=False)
def _loop_dc(x, n, substeps, pp, fkind, fp):
    mem = 0.0
    f = 0.0
    for _ in range(n):
        u = -40.0 * x[0] - 3.0 * x[1] - 5.0 * x[2] - 2.0 * x[3]
        u = min(10.0, max(-10.0, u))
        f, mem = tick(x, u, mem, substeps, 1, 0.005, pp, fkind, fp)
    return f


@njit(cache=False)
def _loop_thesis(x, n, pp, fkind, fp):
    mem = 0.0
    f = 0.0
    for _ in range(n):
        u = 40.0 * x[0] + 3.0 * x[1] + 5.0 * x[2] + 2.0 * x[3]
        u = min(45.0, max(-45.0, u))
        f, mem = plant_tick(x, u, mem, 10, 5, 0.005, pp, fkind, fp)
    return f


def cost(repeats: int) -> dict:
    n = 6000
    out = {}
    fdc = FrictionParams(coulomb=0.15, stiction=0.2, zero_velocity_band=0.02).record()
    code = KINDS.index("classical")
    for substeps in (1, 2, 5, 10):
        best = math.inf
        for _ in range(repeats + 1):
            x = np.array([0.05, 0.0, 0.0, 0.0, 0.0])
            t0 = time.process_time()
            _loop_dc(x, n, substeps, QUBE2.record(), code, fdc)
            best = min(best, time.process_time() - t0)
        out[f"dc_substeps_{substeps}"] = best / n * 1e6
    fth = FrictionParams(zero_velocity_band=0.03).record()
    best = math.inf
    for _ in range(repeats + 1):
        x = np.array([0.05, 0.0, 0.0, 0.0, 0.0])
        t0 = time.process_time()
        _loop_thesis(x, n, PlantParams().record(), code, fth)
        best = min(best, time.process_time() - t0)
    out["thesis_default"] = best / n * 1e6
    return out


def closed_loop(name: str, spec, substeps: int = 2, duration: float = 20.0,
                trace: list | None = None) -> dict:
    """One closed-loop run (module docstring); ``trace`` receives (t, theta, arm, u)."""
    p = PRESETS[name]
    d = dc_design(spec, p)
    row, pp = observer_row(d), p.record()
    f = PRESET_FRICTION[name]
    fp = FrictionParams(coulomb=f["friction.coulomb"], stiction=f["friction.stiction"],
                        zero_velocity_band=f["friction.zero_velocity_band"]).record()
    code = KINDS.index("classical")
    x = np.array([0.1, 0.0, 0.0, 0.0, 0.0])
    xhat = np.zeros(4)
    mem, umax = 0.0, 0.0
    n = round(duration / H)
    theta, arm, us = np.empty(n), np.empty(n), np.empty(n)
    for k in range(n):
        u = min(p.voltage_limit, max(-p.voltage_limit, -float(d.L @ xhat)))
        umax = max(umax, abs(u))
        dc_observer_step(xhat, x[0], x[2], x[3], u, row)
        _, mem = tick(x, u, mem, substeps, 1, H, pp, code, fp)
        theta[k], arm[k], us[k] = x[0], x[2], u
        if abs(x[0]) > 1.5:
            return {"fell_at": k * H}
    if trace is not None:
        trace.append((np.arange(1, n + 1) * H, theta, arm, us))
    late = theta[n // 2:]
    y0, y1 = late[:-1], late[1:]
    i = np.where((y0 < 0) & (y1 >= 0))[0]
    t = (i + y0[i] / (y0[i] - y1[i])) * H
    return {"amplitude": float(late.max()), "period": float(np.mean(np.diff(t))),
            "max_u": umax}


def _variants():
    fast, slow = dc_spec("fast", QUBE2), dc_spec("slow", QUBE2)
    home = dc_spec("fast", PRESETS["homebuilt"])
    return [
        ("qube2", "fast", "fast"), ("qube2", "slow", "slow"),
        ("qube2", "fast, observer_omega2 30",
         dataclasses.replace(fast, observer_omega2=30.0)),
        ("qube2", "slow, observer_omega2 30",
         dataclasses.replace(slow, observer_omega2=30.0)),
        ("qube3", "fast", "fast"), ("qube3", "slow", "slow"),
        ("homebuilt", "fast", "fast"), ("homebuilt", "slow", "slow"),
        ("homebuilt", "fast, observer_omega1 = observer_omega2 = 60",
         dataclasses.replace(home, observer_omega1=60.0, observer_omega2=60.0)),
    ]


def plot(path: str) -> None:
    """The QUBE-Servo 2's fast-design limit cycle, default observer and a faster
    arm observer: theta, the arm and u over the last 5 s of 20."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fast = dc_spec("fast", QUBE2)
    runs = [("fast design (observer_omega2 10 rad/s)", "fast"),
            ("observer_omega2 30 rad/s", dataclasses.replace(fast, observer_omega2=30.0))]
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 6.5))
    for label, spec in runs:
        trace: list = []
        closed_loop("qube2", spec, trace=trace)
        t, theta, arm, u = trace[0]
        keep = t >= 15.0
        axes[0].plot(t[keep], theta[keep], label=label)
        axes[1].plot(t[keep], arm[keep], label=label)
        axes[2].plot(t[keep], u[keep], label=label)
    axes[0].set_ylabel("theta (rad)")
    axes[1].set_ylabel("arm (rad)")
    axes[2].set_ylabel("u (V)")
    axes[2].set_xlabel("t (s)")
    axes[0].legend(loc="upper right", fontsize=8)
    axes[0].set_title("QUBE-Servo 2, classical friction F_S 0.2 V, F_C 0.15 V")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    print(f"wrote {path}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--plot", metavar="PNG", help="also draw the QUBE-Servo 2's limit "
                    "cycles (docs/figures/qube2_limit_cycle.png) and stop")
    args = ap.parse_args()
    if args.plot:
        plot(args.plot)
        return
    res = {"driven_error": {}, "energy_drift": {}}
    for s in (1, 2, 5, 10):
        res["driven_error"][s] = driven_error(s)
        res["energy_drift"][s] = energy_drift(s)
        print(f"substeps {s:2d}: driven error {res['driven_error'][s]:.2e}, "
              f"energy drift {res['energy_drift'][s]:.2e}")
    res["closed_loop"] = {}
    for name, label, spec in _variants():
        r = closed_loop(name, spec)
        res["closed_loop"][f"{name}, {label}"] = r
        print(f"{name}, {label}: " + ", ".join(f"{k} {v:.4g}" for k, v in r.items()))
    ref = closed_loop("qube2", "fast", substeps=100)
    res["substep_error"] = {}
    for s in (1, 2, 5, 10):
        r = closed_loop("qube2", "fast", substeps=s)
        res["substep_error"][s] = max(abs(r[k] / ref[k] - 1.0) for k in ("amplitude", "period"))
        print(f"qube2 fast cycle at {s} substeps: {res['substep_error'][s]:.2%} from 100")
    res["us_per_tick"] = cost(args.repeats)
    for k, v in res["us_per_tick"].items():
        print(f"{k}: {v:.3f} us per tick")
    print(json.dumps(res))


if __name__ == "__main__":
    main()
