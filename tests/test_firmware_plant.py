"""The home-built rig behind the emulated firmware (firmware/hil/rig.py
``--plant furuta-dc``) and its balancing design, in-process and in simulated
time: the plant is the HOMEBUILT preset driven by the duty as a fraction of
its 12 V supply, with its friction; the design balances it through the
firmware's sensors where the thesis's pattern lets it fall
(docs/build-a-rig.md, "The balancing design").  The emulator against the real
controller: tests/test_firmware_hil.py."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import pytest

from frictionlab.model.plants.furuta_dc import HOMEBUILT, PRESET_FRICTION

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "firmware" / "hil"))
import homebuilt_loop  # firmware/hil/homebuilt_loop.py
import rig  # firmware/hil/rig.py

# a plant and a controller built and compiled, then seconds of simulated time
pytestmark = pytest.mark.slow


def plant(theta0: float) -> rig.FurutaDCPlant:
    args = argparse.Namespace(friction="classical", set=[], theta0=theta0)
    return rig.PLANTS["furuta-dc"](args)


def test_the_emulated_rig_is_the_home_built_preset_driven_by_the_duty_times_the_supply():
    """A fifth of the duty with the pendulum hanging: the arm runs up to the
    preset's steady speed at 2.4 V less the Coulomb level, k_t/R_m (2.4 V - F_C) /
    (k_t k_m / R_m + D_r) (5.6 rad/s: slower than omega0, so the pendulum stays down,
    swinging; its mean over the third second); a duty whose voltage is under the
    stiction level leaves the arm at rest."""
    p = HOMEBUILT
    fc = PRESET_FRICTION["homebuilt"]["friction.coulomb"]
    fs = PRESET_FRICTION["homebuilt"]["friction.stiction"]
    kv = p.torque_constant / p.resistance
    rig_plant = plant(math.pi)
    assert rig_plant.u_per_duty == p.voltage_limit == 12.0
    for _ in range(2000):  # 2 s: 50 arm time constants
        rig_plant.step(0.2)
    arm0 = rig_plant.angles()[1]
    for _ in range(1000):
        rig_plant.step(0.2)
    steady = kv * (0.2 * p.voltage_limit - fc) / (kv * p.emf_constant + p.arm_damping)
    assert rig_plant.angles()[1] - arm0 == pytest.approx(steady, rel=0.01)

    held = plant(math.pi)
    for _ in range(200):
        held.step(0.9 * fs / p.voltage_limit)
    assert held.angles() == pytest.approx((math.pi, 0.0), abs=1e-12)
    assert abs(held.state.x[3]) < 1e-12


def test_the_home_built_design_balances_through_the_firmware_sensors():
    """The default design (rig.HOMEBUILT_DESIGN) keeps the pendulum in a friction
    limit cycle well inside 0.2 rad, within the supply, reading whole encoder
    counts and the 10 ms velocity window; without friction it settles to the
    counts.  The thesis's fast pattern on the same rig falls."""
    cycle = homebuilt_loop.closed_loop(duration=6.0)
    assert "fell_at" not in cycle, cycle
    assert 0.02 < cycle["amplitude"] < 0.1, cycle
    assert cycle["max_u"] < HOMEBUILT.voltage_limit / 4, cycle
    still = homebuilt_loop.closed_loop(duration=4.0, plant_sets=[
        ("friction.stiction", 0.0), ("friction.coulomb", 0.0)])
    assert still["amplitude"] < 0.01, still

    from frictionlab.model.plants.furuta_dc_design import dc_spec

    spec = dc_spec("fast", HOMEBUILT)
    pattern = {f"design.{k}": getattr(spec, k) for k in (
        "omega1", "zeta1", "omega2", "zeta2", "observer_omega1", "observer_zeta1",
        "observer_omega2", "observer_zeta2")}
    # the pattern as it was, with the full-model predictor at the thesis's ratio
    pattern.update({"design.full_observer": 1,
                    "design.observer_omega1": 20.0 / 6.8 * spec.omega0})
    assert homebuilt_loop.closed_loop(pattern, duration=4.0).get("fell_at", 99) < 2.0


def test_the_documented_rig_toml_is_the_emulated_rigs_configuration(tmp_path):
    """docs/build-a-rig.md's ``rig.toml`` (its indented block from ``[plant]``)
    gives ``run --plant furuta-dc`` what firmware/test-hil gives it: the
    emulated rig's plant, friction and design, and the controller's rig.*
    scales for the firmware with u_DA = u / 12 V."""
    from frictionlab.config import build_config

    sys.path.insert(0, str(Path(rig.__file__).parent))
    import test_hil  # firmware/hil/test_hil.py

    doc = (Path(__file__).resolve().parents[1] / "docs" / "build-a-rig.md").read_text()
    lines = doc[doc.index("\n    [plant]\n") + 1:].splitlines()
    block = []
    for line in lines:
        if line and not line.startswith("    "):
            break
        block.append(line[4:])
    path = tmp_path / "rig.toml"
    path.write_text("\n".join(block))
    documented = build_config(plant="furuta-dc", config_file=path)
    _, ctrl_args = test_hil.plant_sets("furuta-dc", None)
    sets = [*test_hil.RIG_SETS, *(a for a in ctrl_args[3::2])]
    assert ctrl_args[:2] == ["--plant", "furuta-dc"]
    emulated = build_config(plant="furuta-dc", sets=sets)
    for section in ("plant", "friction", "design", "rig"):
        assert getattr(documented, section) == getattr(emulated, section), section
    assert documented.rig.u_scale == pytest.approx(1 / 12)
