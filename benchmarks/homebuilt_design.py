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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--json", action="store_true", help="only the JSON line")
    args = ap.parse_args()
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
