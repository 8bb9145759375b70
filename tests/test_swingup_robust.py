"""Swing-up on plants the design does not know (docs/swingup.md, "Plants the design
does not know"): the robust balancing design ``ROBUST_DESIGN`` holds the plants of
the Monte Carlo that the fast preset loses after a catch, on the thesis plant and
the QUBE-Servo 2, and keeps the command after the catch within 80 % of the limit."""

from __future__ import annotations

import math

import numpy as np

from frictionlab.config import build_config
from frictionlab.model.swingup import CAUGHT, SWINGING
from frictionlab.runs import make_controller
from frictionlab.studies.dc_robustness import VARIED
from frictionlab.studies.swingup_sim import ROBUST_DESIGN, simulate_swingup, swingup_outcome

HANGING = ("sim.initial_angle", math.pi)
COMMON = [HANGING, ("sim.noise", 0.002), ("controller.u_max", 10.0)]
#: A thesis plant of benchmarks/swingup.py (seed 1, plant 87): high friction, omega0
#: near the design's 6.2.
THESIS_PLANT = [("design.omega0", 6.2), ("plant.omega0", 6.13), ("friction.coulomb", 2.71),
                ("friction.stiction", 3.03), ("sim.seed", 87)]
#: A QUBE-Servo 2 drawn within +-20 % (seed 1, plant 102): shorter arm, longer
#: pendulum, on which the nominal fast design's linear loop is barely stable (spectral
#: radius 0.9995 per tick; benchmarks/swingup_margin.py counts such plants).
QUBE_PLANT = [("plant.arm_mass", 0.1059), ("plant.arm_length", 0.06986),
              ("plant.pendulum_mass", 0.02137), ("plant.pendulum_length", 0.1458),
              ("plant.resistance", 8.791), ("plant.torque_constant", 0.0422),
              ("plant.emf_constant", 0.0398), ("friction.coulomb", 0.039),
              ("friction.stiction", 0.085), ("sim.seed", 102)]


def after_catch_peaks(res) -> list[float]:
    """Largest |u| in the 0.5 s after each hand-over."""
    traj = res.trajectory
    phase, u = traj.meta["phase"], traj["u"]
    n = round(0.5 / traj.h)
    starts = np.flatnonzero((phase[1:] == CAUGHT) & (phase[:-1] == SWINGING)) + 1
    return [float(np.abs(u[k:k + n]).max()) for k in starts]


def swing(plant: str, design: tuple, values: list, known: bool = True):
    """Swing up from hanging for 20 s; on the motor plant the controller is the
    nominal plant's (it does not know ``values``)."""
    controller = None
    if not known:
        controller = make_controller(build_config("fast", "classical", plant=plant,
                                                  sets=[*COMMON, *design]))
    cfg = build_config("fast", "classical", plant=plant, sets=[*COMMON, *design, *values])
    return simulate_swingup(cfg, 20.0, controller=controller)


def test_the_robust_design_holds_a_thesis_plant_the_fast_preset_loses():
    """High F_C with omega0 near the design's: the fast preset's friction limit cycle
    needs more than 10 m/s^2 and the pendulum falls after its catch; with the robust
    design it is caught, balancing at 20 s, and the command after the catch stays
    below 80 % of the limit."""
    fast = swing("thesis", (), THESIS_PLANT)
    assert fast.balanced and fast.stop_reason == "fell"
    robust = swing("thesis", ROBUST_DESIGN, THESIS_PLANT)
    assert swingup_outcome(robust)[0] in ("limit_cycle", "settled")
    assert robust.stop_reason == ""
    assert max(after_catch_peaks(robust)) < 8.0
    assert np.abs(robust.trajectory["u"]).max() <= 10.0 + 1e-12


def test_the_robust_design_swings_up_a_qube_it_does_not_know():
    """The same drawn QUBE-Servo 2 with the nominal plant's controller: the fast
    preset catches it and then loses it (the arm runs to its travel limit, 0 V);
    the robust design balances it, the command after the catch below 8 V."""
    fast = swing("qube2", (), QUBE_PLANT, known=False)
    assert not fast.balanced and fast.stop_reason == "arm_travel"
    assert fast.catches >= 1 and fast.trajectory["u"][-1] == 0.0
    robust = swing("qube2", ROBUST_DESIGN, QUBE_PLANT, known=False)
    assert swingup_outcome(robust)[0] in ("limit_cycle", "settled")
    assert max(after_catch_peaks(robust)) < 8.0
    assert np.abs(robust.trajectory["u"]).max() <= 10.0 + 1e-12


def test_a_slice_of_the_qube_monte_carlo_with_the_robust_design():
    """Eight QUBE-Servo 2s drawn as benchmarks/swingup.py draws them, the
    controller the nominal plant's robust design: every one caught and balancing
    at 20 s, the command after each catch below 80 % of 10 V."""
    rng = np.random.default_rng(11)
    nominal = build_config(plant="qube2").plant
    for i in range(8):
        fc = rng.uniform(0.0, 0.3)
        values = [(f"plant.{f}", getattr(nominal, f) * rng.uniform(0.8, 1.2)) for f in VARIED]
        values += [("friction.coulomb", fc), ("friction.stiction", fc + rng.uniform(0, 0.1)),
                   ("sim.seed", i)]
        res = swing("qube2", ROBUST_DESIGN, values, known=False)
        assert swingup_outcome(res)[0] in ("limit_cycle", "settled"), values
        assert max(after_catch_peaks(res)) < 8.0, values
