"""The one sensor model (App. B): the simulator and the emulated rigs read the same."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from frictionlab.config import build_config
from frictionlab.model import sensor as S
from frictionlab.model.rig import RigScaling
from frictionlab.realtime import FakeClock, Safety
from frictionlab.realtime.loop import Loop
from frictionlab.realtime.params import ControlParams
from frictionlab.realtime.rigs import AdcModel, FramedRig, SimRig
from frictionlab.realtime.rigsim import DirectTransport, RigEmulator
from frictionlab.runs import make_sensor, simulate_config

NOISY = ["sim.quantization=1", "sim.noise=0.002", "sim.seed=11", "sim.initial_angle=0.05"]


@pytest.mark.slow
def test_noise_stream_is_standard_normal_and_a_function_of_seed_sample_channel():
    z = np.array([[S.noise(7, n, c) for c in range(3)] for n in range(20000)])
    assert abs(z.mean()) < 0.02 and abs(z.std() - 1.0) < 0.02
    # channels and neighbouring samples uncorrelated
    assert abs(np.corrcoef(z[:, 0], z[:, 1])[0, 1]) < 0.03
    assert abs(np.corrcoef(z[:-1, 2], z[1:, 2])[0, 1]) < 0.03
    # tails of a normal: P(|z| > 3) = 0.27 %
    assert 0.0015 < np.mean(np.abs(z) > 3) < 0.004
    # the same in compiled and plain code; another seed, another stream
    with np.errstate(over="ignore"):  # uint64 arithmetic wraps, as in compiled code
        assert all(S.noise.py_func(7, n, 1) == z[n, 1] for n in range(50))
    assert S.noise(8, 0, 0) != z[0, 0]


def test_conversions_both_ways_with_the_rig_factors():
    r = RigScaling(theta_scale=3.0, theta_bias=0.4, arm_scale=20.0, velocity_scale=30.0,
                   velocity_bias=-0.01)
    sp = S.sensor_params(r, quantization=0)
    y, x, v = S.adc(sp, 0.2, 1.0, 3.0, 0)
    assert y == pytest.approx(0.2 / 3.0 - 0.4) and v == pytest.approx(3.0 / 30.0 + 0.01)
    assert x == pytest.approx(1.0 / 20.0 + S.ARM_START)
    assert S.theta_from_raw(y, 3.0, 0.4) == pytest.approx(0.2)
    assert S.arm_from_raw(x, S.ARM_START, 20.0) == pytest.approx(1.0)
    assert S.velocity_from_raw(v, 30.0, -0.01) == pytest.approx(3.0)
    # the 12-bit grid is in raw units, bias included
    sq = S.sensor_params(r, quantization=1)
    yq, xq, vq = S.adc(sq, 0.2, 1.0, 3.0, 0)
    for raw in (yq, xq, vq):
        assert raw / S.ADC_STEP == round(raw / S.ADC_STEP)
    assert abs(yq - y) <= S.ADC_STEP / 2
    # wrap of the angle channels, clip of the velocity channel at its largest code
    assert S.adc(sq, 3.0 * 1.5, 0.0, 0.0, 0)[0] < 0
    assert S.adc(sq, 0.0, 0.0, 1e3, 0)[2] == 1.0 - S.ADC_STEP


def test_ideal_sensor_reads_the_truth_plus_noise():
    sp = make_sensor(build_config(sets=["sim.noise=0.01", "sim.seed=4"]))
    th, arm, ad, x0 = S.measure(sp, 0.1, 0.0, 2.0, 0, 0.0)
    assert th == 0.1 + 0.01 * S.noise(4, 0, 0) and ad == 2.0 + 0.01 * S.noise(4, 0, 2)
    assert arm == 0.0  # the arm's zero is its first reading
    th, arm, ad, _ = S.measure(sp, 0.1, 0.5, 2.0, 9, x0)
    assert arm == 0.5 + 0.01 * S.noise(4, 9, 1) - x0
    clean = make_sensor(build_config())
    assert S.measure(clean, 0.123, 0.0, -1.5, 0, 0.0)[:3] == (0.123, 0.0, -1.5)


_FINITE = st.floats(-1e3, 1e3, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(_FINITE, _FINITE, _FINITE, st.integers(0, 10**6), _FINITE)
def test_ideal_reading_is_measure_of_a_noise_free_ideal_sensor(theta, arm, arm_dot, n, x0):
    # the simulator's fast path for this sensor (model.simulation._run) reads
    # through ideal_reading instead of measure: the same values, bit for bit
    sp = make_sensor(build_config(sets=["sim.noise=0", "sim.quantization=0"]))
    assert sp.noise == 0.0 and sp.step == 0.0
    assert S.measure(sp, theta, arm, arm_dot, n, x0) == S.ideal_reading(theta, arm, arm_dot,
                                                                      n == 0, x0)


@pytest.mark.parametrize("sets", [NOISY, ["sim.initial_angle=0.05"],
                                  ["sim.quantization=1", "sim.initial_angle=0.05"]],
                         ids=["noisy", "ideal", "converter"])
def test_simulator_measures_through_the_sensor_kernel(sets):
    cfg = build_config("fast", "classical", sets=sets)
    traj = simulate_config(cfg, 1.0)
    sp = make_sensor(cfg)
    x0 = 0.0
    for k in range(len(traj.k)):
        m = S.measure(sp, traj["theta"][k], traj["arm"][k], traj["arm_dot"][k], k, x0)
        x0 = m[3]
        assert m[:3] == (traj["theta_m"][k], traj["arm_m"][k], traj["arm_dot_m"][k])
    # chunked (with progress) and unchunked runs draw the same noise
    chunked = simulate_config(cfg, 1.0, progress=lambda f: None)
    np.testing.assert_array_equal(chunked.data, traj.data)


class _TruthSimRig(SimRig):
    def open(self, *a, **kw):
        super().open(*a, **kw)
        self.truth = []

    def sample(self, k, deadline_ns):
        r = super().sample(k, deadline_ns)
        self.truth.append(self.state.x[[0, 2, 3]].copy())
        return r


class _TruthEmulator(RigEmulator):
    truth: dict

    def _sample(self, seq, t):
        out = super()._sample(seq, t)
        self.truth[seq] = self.state.x[[0, 2, 3]].copy()
        return out


def _loop_readings(cfg, rig, clock, duration=1.0):
    rig.open()
    loop = Loop(rig, clock, ControlParams.from_config(cfg), duration=duration,
                safety=Safety(), realtime=False, manage_gc=False)
    samples = []
    loop.sinks = (samples.append,)
    loop.run()
    assert loop.stop_reason == "duration"
    assert [s.k for s in samples[:-1]] == list(range(len(samples) - 1))
    return np.array([(s.theta_m, s.arm_m, s.arm_dot_m) for s in samples[:-1]])


def _simulator_readings(cfg, truth):
    sp = make_sensor(cfg)
    out, x0 = [], 0.0
    for n, (th, arm, ad) in enumerate(truth):
        *m, x0 = S.measure(sp, th, arm, ad, n, x0)
        out.append(m)
    return np.array(out)


def test_simulator_and_in_process_rig_read_the_same_bit_for_bit():
    cfg = build_config("fast", "classical", sets=NOISY)
    rig = _TruthSimRig(cfg, lockstep=True)
    got = _loop_readings(cfg, rig, FakeClock())
    want = _simulator_readings(cfg, rig.truth[:len(got)])
    np.testing.assert_array_equal(got, want)
    assert np.ptp(got[:, 1]) > 0  # the arm moved: its zero and grid were exercised


def test_simulator_and_rig_sim_read_the_same_bit_for_bit():
    cfg = build_config("fast", "classical", sets=NOISY)
    clock = FakeClock()
    emu = _TruthEmulator(cfg, clock)
    emu.truth = {}
    rig = FramedRig(DirectTransport(emu, clock), "direct", clock=clock)
    got = _loop_readings(cfg, rig, clock)
    # the loop asks for tick k with sequence number k (the probes at open() use others)
    want = _simulator_readings(cfg, [emu.truth[k] for k in range(len(got))])
    np.testing.assert_array_equal(got, want)


def test_adc_model_numbers_its_samples():
    adc = AdcModel(RigScaling(), noise=0.01, seed=3)
    a = adc.read(0.1, 0.0, 0.0)
    assert adc.read(0.1, 0.0, 0.0, count=False) != a  # sample 1
    assert adc.n == 1
    sp = S.sensor_params(RigScaling(), 1.0, 0.01, 3)
    assert a == S.adc(sp, 0.1, 0.0, 0.0, 0)
    assert math.isclose(RigScaling().theta(a[0]), 0.1, abs_tol=0.05)
