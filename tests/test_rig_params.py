"""The App. B conversion factors as ``rig.*`` parameters (controller side and emulated rig)."""

import json
import math
import re
import subprocess
import sys

import numpy as np
import pytest

from frictionlab.config import ConfigError, build_config, valid_keys
from frictionlab.model.rig import RigScaling
from frictionlab.realtime import FakeClock
from frictionlab.realtime.loop import Loop
from frictionlab.realtime.params import ControlParams
from frictionlab.realtime.rigs import FramedRig, SimRig
from frictionlab.realtime.rigsim import DirectTransport, RigEmulator
from frictionlab.runs import make_controller

RIG_KEYS = ["rig.theta_scale", "rig.theta_bias", "rig.arm_scale", "rig.velocity_scale",
            "rig.velocity_bias", "rig.u_scale", "rig.arm_sign", "rig.pendulum_sign"]


def test_rig_keys_exist_with_appendix_b_defaults():
    assert [k for k in valid_keys() if k.startswith("rig.")] == RIG_KEYS
    r = build_config().rig
    assert r == RigScaling()
    assert (r.theta_scale, r.theta_bias, r.arm_scale, r.velocity_scale, r.velocity_bias,
            r.u_scale) == (math.pi, 0.503, 25.8, 28.7, 0.02, -0.022)
    assert (r.arm_sign, r.pendulum_sign) == (1, 1)  # encoder rigs as their maker wires them
    # the controller saturates at the DAC limit the factors give
    assert make_controller(build_config()).u_max == 1.0 / 0.022
    assert make_controller(build_config(sets=["rig.u_scale=0.05"])).u_max == pytest.approx(20.0)


def test_rig_keys_from_set_and_toml(tmp_path):
    f = tmp_path / "rig.toml"
    f.write_text("[rig]\nvelocity_scale = 30.5\nu_scale = -0.025\n")
    cfg = build_config(config_file=f, sets=["rig.u_scale=-0.02", "rig.theta_bias=-0.2"])
    assert cfg.rig.velocity_scale == 30.5
    assert cfg.rig.u_scale == -0.02  # --set wins over the file
    assert cfg.rig.theta_bias == -0.2
    assert cfg.as_flat_dict()["rig.velocity_scale"] == 30.5


@pytest.mark.parametrize("text, field", [("rig.u_scale=0", "rig.u_scale"),
                                         ("rig.theta_scale=-1", "rig.theta_scale"),
                                         ("rig.velocity_bias=2", "rig.velocity_bias")])
def test_bad_rig_values_name_the_key(text, field):
    with pytest.raises(ConfigError, match=re.escape(field)):
        build_config(sets=[text])
    with pytest.raises(ConfigError, match=r"rig\.arm_bias"):
        build_config(sets=["rig.arm_bias=0.1"])  # x_0 is taken at run start, not a key


def test_keys_command_lists_the_rig_factors():
    out = subprocess.run([sys.executable, "-m", "frictionlab", "keys", "--json"],
                         capture_output=True, text=True, check=True).stdout
    rows = {r["key"]: r for r in json.loads(out)["keys"]}
    assert rows["rig.u_scale"]["default"] == -0.022
    assert rows["rig.theta_scale"]["unit"] == "rad"


class _TruthRig(SimRig):
    """The in-process rig, remembering the true state and u at each tick."""

    def open(self, *a, **kw):
        super().open(*a, **kw)
        self.truth, self.u_true = [], []

    def sample(self, k, deadline_ns):
        r = super().sample(k, deadline_ns)
        x = self.state.x
        self.truth.append((float(x[0]), float(x[2]), float(x[3])))
        return r

    def write(self, k, u_da):
        super().write(k, u_da)
        self.u_true.append(self._u)


def _run(ctrl_sets, rig_sets, duration=0.4):
    common = ["sim.quantization=0", "sim.noise=0", "sim.initial_angle=0.05"]
    ctrl_cfg = build_config("fast", "classical", sets=common + ctrl_sets)
    rig = _TruthRig(build_config("fast", "classical", sets=common + rig_sets), lockstep=True)
    rig.open()
    loop = Loop(rig, FakeClock(), ControlParams.from_config(ctrl_cfg), duration=duration,
                realtime=False, manage_gc=False)
    samples = []
    loop.sinks = (samples.append,)
    loop.run()
    n = min(len(rig.truth), len(samples) - 1)
    truth = np.array(rig.truth[:n])
    meas = np.array([(s.theta_m, s.arm_m, s.arm_dot_m) for s in samples[:n]])
    u = np.array([s.u for s in samples[:n]])
    return truth, meas, u, np.array(rig.u_true[:n])


def test_matching_factors_measure_the_truth():
    sets = ["rig.theta_scale=3.0", "rig.theta_bias=0.4", "rig.velocity_scale=31",
            "rig.velocity_bias=-0.01", "rig.arm_scale=22", "rig.u_scale=-0.03"]
    truth, meas, u, u_true = _run(sets, sets)
    np.testing.assert_allclose(meas[:, 0], truth[:, 0], atol=1e-12)
    np.testing.assert_allclose(meas[:, 1], truth[:, 1] - truth[0, 1], atol=1e-9)
    np.testing.assert_allclose(meas[:, 2], truth[:, 2], atol=1e-9)
    np.testing.assert_allclose(u_true, u, rtol=1e-12, atol=1e-12)


def test_mismatched_factors_scale_the_readings_as_app_b_predicts():
    # the rig's true factors differ from the controller's calibration (the defaults)
    true = dict(theta_scale=3.0, theta_bias=0.5, arm_scale=20.0, velocity_scale=30.0,
                velocity_bias=0.0, u_scale=-0.03)
    truth, meas, u, u_true = _run([], [f"rig.{k}={v}" for k, v in true.items()])
    c = RigScaling()
    y = truth[:, 0] / true["theta_scale"] - true["theta_bias"]  # what the rig sends
    np.testing.assert_allclose(meas[:, 0], c.theta_scale * (y + c.theta_bias), atol=1e-12)
    np.testing.assert_allclose(meas[:, 1], c.arm_scale / true["arm_scale"]
                               * (truth[:, 1] - truth[0, 1]), atol=1e-9)
    v = truth[:, 2] / true["velocity_scale"] - true["velocity_bias"]
    np.testing.assert_allclose(meas[:, 2], c.velocity_scale * (v + c.velocity_bias),
                               atol=1e-9)
    # u_DA = k_u(controller) u, and the plant receives u_DA / k_u(rig)
    np.testing.assert_allclose(u_true, u * c.u_scale / true["u_scale"], rtol=1e-12,
                               atol=1e-12)
    assert np.ptp(u) > 0.1  # the loop did act


def test_defaults_read_as_before():
    truth, meas, u, u_true = _run([], [])
    np.testing.assert_allclose(meas[:, 0], truth[:, 0], atol=1e-12)
    np.testing.assert_allclose(meas[:, 2], truth[:, 2], atol=1e-9)
    np.testing.assert_allclose(u_true, u, rtol=1e-12)


def test_rig_sim_uses_its_true_factors():
    # rig-sim's readings come from its own rig.* values; a controller with the defaults
    # then measures the App. B.5 mismatch
    true = build_config(sets=["rig.velocity_scale=35", "sim.quantization=0"])
    clock = FakeClock()
    emu = RigEmulator(true, clock)
    rig = FramedRig(DirectTransport(emu, clock), "direct", clock=clock)
    rig.open()
    ctrl = build_config()
    loop = Loop(rig, clock, ControlParams.from_config(ctrl), duration=0.5, realtime=False,
                manage_gc=False)
    samples, truth = [], []
    loop.sinks = (samples.append, lambda s: truth.append(float(emu.state.x[3])))
    loop.run()
    v = np.array([s.arm_dot_m for s in samples[1:-1]])
    # v_raw = Omega_dot/35 - 0.02 (quantised), read back as 28.7 (v_raw + 0.02)
    np.testing.assert_allclose(v, 28.7 / 35 * np.array(truth[1:-1]), atol=28.7 * 2 / 4096)
    assert np.ptp(v) > 0.05
