"""One schedule per identification experiment: the simulated experiment and the rig run
drive the same :class:`~frictionlab.realtime.experiment.RigExperiment` and send the
motor the same u_DA in every tick.

The rig run is the real-time loop (``run_on_rig``) against the in-process simulated rig
(``SimRig``, lockstep) on a fake clock; the simulated run steps the same schedule against
the simulator's plant (``studies.identification.simulated``).  With the rig's 12-bit
converters and measurement noise both read the same values, so the command sequences
must be equal, not close.  Short schedules keep each pair to a few simulated seconds.
"""

import math

import numpy as np
import pytest

from frictionlab.config import build_config
from frictionlab.model.sensor import dac
from frictionlab.realtime import FakeClock
from frictionlab.realtime.experiment import ControlScaling, Limits
from frictionlab.realtime.rigs import SimRig
from frictionlab.studies.identification.onrig import make_rig_experiment, run_on_rig
from frictionlab.studies.identification.simulated import run_simulated

#: A rig whose values differ from the defaults, with noise and the 12-bit converters.
RIG = {"friction.stiction": 1.9, "friction.coulomb": 1.25, "plant.omega0": 6.25,
       "plant.input_gain": 0.82, "sim.initial_angle": math.pi, "sim.seed": 3,
       "sim.noise": 0.002, "sim.quantization": 1.0}
#: Short schedules (each run ends with its schedule, or at a limit: angle-scales
#: without a hand waits for the operator until ``wait``).
SHORT = {
    "stiction": {"step": 0.4, "hold": 0.05, "coulomb_levels": (0.6,), "slide": 0.2},
    "stribeck": {"references": (1.0, 4.0), "hold": 0.3},
    "free-oscillation": {"duration": 0.5, "amplitude": 0.02},
    "control-scaling": {"levels": (4.0, 8.0), "limit": 0.4},
    "velocity-scale": {"references": (2.0,), "hold": 0.3},
    "angle-scales": {"wait": 1.0, "settle": 0.2},
}


class RecordingRig(SimRig):
    """The in-process simulated rig, keeping every u_DA the loop writes."""

    def __init__(self, cfg):
        super().__init__(cfg, lockstep=True)
        self.written: list[float] = []

    def write(self, k, u_da):
        self.written.append(u_da)
        super().write(k, u_da)


def _rig_commands(name, cfg, tmp_path):
    exp = make_rig_experiment(name, cfg, **SHORT[name])
    rig = RecordingRig(cfg)
    st = run_on_rig(exp, cfg, rig, log_dir=tmp_path, clock=FakeClock())
    return np.array(rig.written), st["stop_reason"], exp.marks


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SHORT))
def test_simulated_and_rig_runs_issue_identical_commands(name, tmp_path):
    cfg = build_config("fast", "classical", sets=RIG.items())
    sim = run_simulated(make_rig_experiment(name, cfg, **SHORT[name]), cfg)
    u_da_rig, reason, marks = _rig_commands(name, cfg, tmp_path)
    assert sim.reason == reason
    n = len(sim.commands)
    assert n > 20
    u_da_sim = [dac.py_func(u, cfg.rig.u_scale) for u in sim.commands]
    np.testing.assert_array_equal(u_da_sim, u_da_rig[:n])
    assert np.all(u_da_rig[n:] == 0.0)  # the stop: the motor off
    assert sim.marks == marks
    if name != "angle-scales":
        assert reason == "finished"
        assert np.any(sim.commands != 0.0)  # the schedule drove the motor


def test_control_scaling_alternates_its_levels():
    """Both sides run the rig's schedule: +u, -u, +u... (the arm's travel stays
    bounded, and both directions are measured)."""
    cfg = build_config("fast", "classical", sets=RIG.items())
    exp = ControlScaling(cfg.design.h, cfg.rig.u_scale, levels=(4.0, 6.0, 8.0), limit=0.3)
    run = run_simulated(exp, cfg)
    u = run.commands
    driven = [float(v) for i, v in enumerate(u) if v != 0.0 and (i == 0 or u[i - 1] != v)]
    assert driven == [4.0, -6.0, 8.0]


def test_simulated_run_stops_at_the_experiments_limit():
    """A limit ends the simulated run as it ends the rig's: u clipped to max_u_da, and
    a staircase that finds no breakaway under it stops with experiment_limit."""
    cfg = build_config("fast", "classical", sets=[*RIG.items(), ("friction.stiction", 30.0),
                                                  ("friction.coulomb", 20.0)])
    exp = make_rig_experiment("stiction", cfg, Limits(max_u_da=0.05), step=0.5, hold=0.02)
    run = run_simulated(exp, cfg)
    assert run.reason == "experiment_limit"
    assert "no breakaway" in run.detail
    u_max = 0.05 / abs(cfg.rig.u_scale)
    assert np.max(np.abs(run.commands)) <= u_max
