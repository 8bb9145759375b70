r"""Golden outputs: ``frictionlab simulate --json`` for 20 sampled configurations.

A refactoring of the simulator, the controller or the plant must leave every
feature of these runs bit for bit as it was.  The configurations cover both
designs, every friction and compensation kind, noise, quantisation, drift,
the LuGre plant's observer gain, swing-up and the adaptive compensator.

Usage::

    .venv/bin/python benchmarks/golden.py --out before.json      # record
    .venv/bin/python benchmarks/golden.py --check before.json    # compare (exit 1 on a change)

The command line is run as a subprocess, so the check does not depend on
where a function lives inside the package.  The last printed line is a JSON
object (``{"configurations": 20, "changed": [...]}``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

CONFIGS: list[list[str]] = [
    ["--design", "fast", "--friction", "classical", "--set", "friction.zero_velocity_band=0.03"],
    ["--design", "slow", "--friction", "classical", "--set", "friction.zero_velocity_band=0.03"],
    ["--design", "fast", "--friction", "coulomb"],
    ["--design", "slow", "--friction", "coulomb", "--set", "friction.hysteresis=0.05"],
    ["--design", "fast", "--friction", "lugre"],
    ["--design", "slow", "--friction", "lugre", "--set", "friction.observer_gain=1"],
    ["--design", "fast", "--friction", "lugre", "--set", "friction.sigma0=1000"],
    ["--design", "fast", "--friction", "none", "--set", "sim.initial_angle=0.1"],
    ["--design", "fast", "--friction", "classical", "--compensation", "coulomb"],
    ["--design", "slow", "--friction", "classical", "--compensation", "classical"],
    ["--design", "fast", "--friction", "lugre", "--compensation", "lugre"],
    ["--design", "slow", "--friction", "lugre", "--compensation", "lugre"],
    ["--design", "fast", "--friction", "classical", "--set", "sim.noise=0.002",
     "--set", "sim.seed=3"],
    ["--design", "slow", "--friction", "lugre", "--set", "sim.noise=0.001",
     "--set", "sim.quantization=1"],
    ["--design", "fast", "--friction", "classical", "--set", "sim.quantization=1"],
    ["--design", "fast", "--friction", "classical", "--set", "friction.drift=0.3",
     "--compensation", "adaptive"],
    ["--design", "fast", "--friction", "classical", "--swing-up",
     "--set", "sim.initial_angle=3.14159"],
    ["--design", "slow", "--friction", "lugre", "--swing-up",
     "--set", "sim.initial_angle=3.14159", "--set", "sim.noise=0.002"],
    ["--design", "fast", "--friction", "classical", "--set", "plant.omega0=7.5",
     "--set", "friction.viscous=0.1"],
    ["--design", "fast", "--friction", "classical", "--set", "plant.input_gain=0.8",
     "--set", "design.omega0=6.5", "--compensation", "classical"],
]


def run_one(args: list[str], exe: str) -> dict:
    cmd = [exe, "simulate", "--duration", "30", *args, "--json"]
    p = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if p.returncode != 0:
        return {"error": p.stderr.strip().splitlines()[-1:] or [f"exit {p.returncode}"]}
    return json.loads(p.stdout)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, help="write the outputs to this JSON file")
    ap.add_argument("--check", type=Path, help="compare with the outputs in this JSON file")
    ap.add_argument("--exe", default=str(Path(sys.executable).with_name("frictionlab")))
    a = ap.parse_args()
    with ThreadPoolExecutor(2) as pool:
        outs = list(pool.map(lambda c: run_one(c, a.exe), CONFIGS))
    results = {" ".join(c): o for c, o in zip(CONFIGS, outs, strict=True)}
    if a.out:
        a.out.write_text(json.dumps(results, indent=1, sort_keys=True))
    changed = []
    if a.check:
        before = json.loads(a.check.read_text())
        for key, out in results.items():
            if before.get(key) != out:
                changed.append(key)
                print(f"CHANGED: {key}\n  before {before.get(key)}\n  after  {out}",
                      file=sys.stderr)
    print(json.dumps({"configurations": len(CONFIGS), "changed": changed}))
    return 1 if changed else 0


if __name__ == "__main__":
    sys.exit(main())
