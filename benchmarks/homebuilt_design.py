r"""The home-built rig's balancing design, through the firmware's sensors.

    .venv/bin/python benchmarks/homebuilt_design.py [--duration S] [--json]

Why the home-built rig (:data:`frictionlab.model.plants.furuta_dc.HOMEBUILT`,
a 12 V 30:1 gear motor on an H-bridge) needs a design of its own, and which
(docs/build-a-rig.md, "The balancing design").  Each design runs in the loop
of firmware/hil/homebuilt_loop.py (the emulated rig's plant, the firmware's
readings, frictionlab's controller step, in simulated time) from theta =
0.05 rad; it prints theta's amplitude and period over the second half of the
run and the largest |u|, or when the pendulum fell, with the encoders and
with ideal sensors, then the default design on rigs that differ from the
model (``robustness``).  The last line is a JSON object.

``--plot PNG [--hil-log CSV]`` draws the default design's cycle and the
thesis pattern's fall instead (docs/figures/homebuilt_limit_cycle.png), with
the log of an emulated run (``firmware/test-hil --keep DIR``: DIR/runs/*.csv)
over them when given.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "firmware" / "hil"))
import rig as R  # noqa: E402  (firmware/hil/rig.py)
from homebuilt_loop import closed_loop  # noqa: E402

from frictionlab.model.plants.furuta_dc import HOMEBUILT, PRESET_FRICTION  # noqa: E402
from frictionlab.model.plants.furuta_dc_design import dc_spec  # noqa: E402


def spec_keys(base: str = "fast", **changes: float) -> dict[str, float]:
    """The ``design.*`` keys of :func:`~frictionlab.model.plants.furuta_dc_design.dc_spec`
    (``base`` on the home-built rig) with ``changes``."""
    spec = dc_spec(base, HOMEBUILT)
    keys = {f"design.{k}": getattr(spec, k) for k in
            ("omega1", "zeta1", "omega2", "zeta2", "observer_omega1", "observer_zeta1",
             "observer_omega2", "observer_zeta2")}
    keys.update({f"design.{k}": v for k, v in changes.items()})
    return keys


def variants() -> list[tuple[str, dict]]:
    """(label, design.* keys) of the designs compared."""
    d = {k.split(".", 1)[1]: v for k, v in R.HOMEBUILT_DESIGN.items()}
    out = [("fast (the thesis's pattern)", spec_keys("fast")),
           ("slow (the thesis's pattern)", spec_keys("slow")),
           ("fast, observer_omega1 = observer_omega2 = 60",
            spec_keys("fast", observer_omega1=60.0, observer_omega2=60.0))]
    for w in (30.0, 40.0, 50.0, 60.0, 80.0, 100.0, 150.0):
        label = f"omega1 {d['omega1']:g}, omega2 {d['omega2']:g}, all observer poles {w:g}"
        if w == d["observer_omega1"] == d["observer_omega2"]:
            label += " (the default)"
        out.append((label, spec_keys("fast", **{**d, "observer_omega1": w,
                                                "observer_omega2": w})))
    return out


def robustness() -> list[tuple[str, dict]]:
    """(label, closed_loop keyword arguments): the default design on rigs that
    differ from its model, and with other latencies and starts."""
    pf = PRESET_FRICTION["homebuilt"]

    def friction(k):
        return [("friction.stiction", pf["friction.stiction"] * k),
                ("friction.coulomb", pf["friction.coulomb"] * k)]

    return [
        ("as modelled", {}),
        ("friction x 0.5", {"plant_sets": friction(0.5)}),
        ("friction x 1.5", {"plant_sets": friction(1.5)}),
        ("no friction", {"plant_sets": friction(0.0)}),
        ("rotor inertia x 0.5", {"plant_sets": [("plant.rotor_inertia",
                                                  HOMEBUILT.rotor_inertia * 0.5)]}),
        ("rotor inertia x 2.5", {"plant_sets": [("plant.rotor_inertia",
                                                  HOMEBUILT.rotor_inertia * 2.5)]}),
        ("torque constant x 0.8", {"plant_sets": [("plant.torque_constant",
                                                    HOMEBUILT.torque_constant * 0.8)]}),
        ("pendulum mass x 1.3", {"plant_sets": [("plant.pendulum_mass",
                                                  HOMEBUILT.pendulum_mass * 1.3)]}),
        ("command 0 ms after the sample", {"latency_ms": 0}),
        ("command 2 ms after the sample", {"latency_ms": 2}),
        ("start at theta = -0.15 rad", {"theta0": -0.15}),
    ]


def plot(path: str, hil_log: str | None = None, seconds: float = 8.0) -> None:
    """theta and u of the default design through the encoders and of the
    thesis's fast pattern (simulated), and of an emulated run's log."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 5.5))
    if hil_log:
        from frictionlab.io.logs import read_log

        log = read_log(hil_log)
        keep = log["t"] <= seconds
        for ax, col in zip(axes, ("theta_m", "u"), strict=True):
            ax.plot(log["t"][keep], log[col][keep], color="0.6", lw=2.5,
                    label="the firmware in simavr, run --plant furuta-dc (test-hil)")
    for label, design, style in (
            ("default design, simulated through the encoders", None, "C0"),
            ("the thesis's fast pattern, simulated (falls)", spec_keys("fast"), "C3")):
        trace: list = []
        res = closed_loop(design, seconds, trace=trace)
        if trace:
            t, theta, u = trace[0]
        else:  # fell: run it again up to the fall for its trace
            trace_fall: list = []
            closed_loop(design, res["fell_at"] - 0.005, trace=trace_fall)
            t, theta, u = trace_fall[0]
        axes[0].plot(t, theta, style, lw=1, label=label)
        axes[1].plot(t, u, style, lw=1, label=label)
    axes[0].set_ylabel("theta (rad)")
    axes[0].set_ylim(-0.3, 0.3)
    axes[1].set_ylabel("u (V)")
    axes[1].set_ylim(-2.0, 2.0)
    axes[1].set_xlabel("t (s)")
    axes[0].legend(loc="upper right", fontsize=8)
    axes[0].set_title("Home-built rig (12 V gear motor, F_S 0.57 V, F_C 0.44 V), "
                      "600-line encoders")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    print(f"wrote {path}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--json", action="store_true", help="only the JSON line")
    ap.add_argument("--plot", metavar="PNG", help="draw the cycles instead")
    ap.add_argument("--hil-log", metavar="CSV", help="with --plot: an emulated run's log")
    args = ap.parse_args()
    if args.plot:
        plot(args.plot, args.hil_log)
        return
    out: dict = {"designs": {}, "robustness": {}}
    for label, sets in variants():
        res = {"encoders": closed_loop(sets, args.duration),
               "ideal": closed_loop(sets, args.duration, ideal=True)}
        out["designs"][label] = res
        if not args.json:
            print(f"{label:62s} " + "  ".join(f"{k}: {_fmt(v)}" for k, v in res.items()),
                  flush=True)
    for label, kw in robustness():
        res = closed_loop(None, args.duration, **kw)
        out["robustness"][label] = res
        if not args.json:
            print(f"default design, {label:46s} encoders: {_fmt(res)}", flush=True)
    print(json.dumps(out))


def _fmt(r: dict) -> str:
    if "fell_at" in r:
        return f"falls after {r['fell_at']:.2f} s"
    return f"cycle {r['amplitude']:.3f} rad, {r['period'] or float('nan'):.2f} s, " \
           f"|u| <= {r['max_u']:.1f} V"


if __name__ == "__main__":
    main()
