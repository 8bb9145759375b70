r"""The loop check's margins: :func:`frictionlab.model.loopcheck.check_loop` of the
default designs with every compensator and of the cases the tests and the console
refuse, one line each, then one JSON object.

For every case: the verdict, the spectral radius of the loop at rest, that of
the compensated loop at its worst sliding speed (and the speed), the predicted
peak of u and the standard deviation of the u the measurement noise (0.002)
causes.  Run it in two trees to see what a change to the check moves::

    .venv/bin/python benchmarks/loopcheck_margins.py
    PYTHONPATH=/tmp/before/src .venv/bin/python benchmarks/loopcheck_margins.py

(docs/architecture.md, "The loop check through the one tick").
"""

from __future__ import annotations

import json
import math

from frictionlab.config import build_config
from frictionlab.model.loopcheck import check_loop
from frictionlab.runs import make_controller

NOISE = 0.002


def cases() -> list[tuple[str, str, str, str, list, str, str]]:
    """(name, design, plant friction, compensation, --set pairs, error signal, plant)."""
    out = []
    for d in ("fast", "slow"):
        for comp in ("none", "coulomb", "classical", "lugre", "adaptive"):
            fr = "lugre" if comp != "none" else "classical"
            out.append((f"{d}/{comp}", d, fr, comp, [], "velocity_innovation", "thesis"))
    vi = "velocity_innovation"
    out += [
        ("fast omega0=100", "fast", "classical", "none", [("design.omega0", 100.0)], vi,
         "thesis"),
        ("fast observer_omega1=1000", "fast", "classical", "none",
         [("design.observer_omega1", 1000.0)], vi, "thesis"),
        ("fast omega1=50", "fast", "classical", "none", [("design.omega1", 50.0)], vi,
         "thesis"),
        ("fast lugre sigma1=1e5", "fast", "lugre", "lugre", [("compensation.sigma1", 1e5)],
         vi, "thesis"),
        ("fast lugre arm_angle", "fast", "lugre", "lugre", [], "arm_angle", "thesis"),
        ("slow lugre arm_velocity", "slow", "lugre", "lugre", [], "arm_velocity", "thesis"),
        ("slow lugre position_innovation", "slow", "lugre", "lugre", [],
         "position_innovation", "thesis"),
        ("fast lugre sigma1=10 k=15", "fast", "lugre", "lugre",
         [("compensation.sigma1", 10.0), ("compensation.observer_gain", 15.0)], vi, "thesis"),
    ]
    for s0 in (100.0, 1000.0):
        for s1 in (4.0, 6.0):
            for k in (7.0, 15.0):
                out.append((f"grid sigma0={s0:g} sigma1={s1:g} k={k:g}", "fast", "lugre",
                            "lugre", [("compensation.sigma0", s0), ("compensation.sigma1", s1),
                                      ("compensation.observer_gain", k)], vi, "thesis"))
    for plant in ("qube2", "qube3"):
        for comp in ("none", "coulomb", "classical", "lugre"):
            out.append((f"{plant}/{comp}", "fast", "classical", comp, [], vi, plant))
    return out


def main() -> dict:
    result = {}
    for name, design, friction, comp, sets, signal, plant in cases():
        try:
            kw = {} if plant == "thesis" else {"plant": plant}
            cfg = build_config(design, friction, comp, sets=[*sets, ("sim.noise", NOISE)], **kw)
            chk = check_loop(make_controller(cfg, signal), cfg.plant, noise=NOISE)
        except Exception as exc:  # a tree whose check cannot take the case (the DC plant)
            row = {"error": f"{type(exc).__name__}: {exc}"[:120]}
        else:
            row = {"verdict": chk.verdict, "radius": round(chk.spectral_radius, 6),
                   "compensator_radius": (None if chk.compensator_radius is None
                                          else round(chk.compensator_radius, 6)),
                   "compensator_speed": chk.compensator_speed,
                   "peak_u": round(chk.peak_u, 4) if math.isfinite(chk.peak_u) else None,
                   "u_noise_std": (round(chk.u_noise_std, 4) if math.isfinite(chk.u_noise_std)
                                   else None)}
        result[name] = row
        print(f"{name:34s} " + "  ".join(f"{k}={v}" for k, v in row.items()), flush=True)
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
