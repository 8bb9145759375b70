"""Limit-cycle features on synthetic signals with known answers."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import find_peaks

from frictionlab.model.limit_cycles import _segment_peaks, features


def half_cycles(shapes, n=400):
    """A signal made of positive half-cycles with the given maxima, each between
    two negative half-sines of height 0.1; each shape is ``(p1,)`` (one
    maximum) or ``(p1, valley, p2)`` (two maxima and the minimum between)."""
    x = np.linspace(0.0, 1.0, n, endpoint=False)[1:]
    env = np.sin(np.pi * x)
    parts = [-0.1 * env]
    for shape in shapes:
        if len(shape) == 1:
            pos = shape[0] * env
        else:
            p1, va, p2 = shape
            # piecewise linear through (0.3, p1), (0.5, valley), (0.7, p2)
            pos = np.interp(x, [0.0, 0.3, 0.5, 0.7, 1.0], [0.0, p1, va, p2, 0.0])
        parts += [[0.0], pos, [0.0], -0.1 * env]
    y = np.concatenate(parts)
    return np.arange(len(y)) * 0.002, y


def test_sine_period_and_single_peak():
    t = np.arange(0, 20, 0.005)
    y = 0.1 * np.sin(2 * np.pi * t / 0.8 + 0.3)
    f = features(t, y, u=5 * np.cos(t), arm_velocity=-3 * np.sin(t))
    assert f.status == "limit_cycle"
    assert f.period == pytest.approx(0.8, rel=1e-3)
    assert f.peak1 == pytest.approx(0.1, rel=1e-3)
    assert f.peak2 is None and f.valley is None
    assert f.peak_to_peak == pytest.approx(0.2, rel=1e-3)
    assert f.max_u == pytest.approx(5, rel=1e-2)
    assert f.max_arm_velocity == pytest.approx(3, rel=1e-2)
    assert f.neg_peak1 == pytest.approx(0.1, rel=1e-3)


def test_two_peaks_and_valley():
    t = np.arange(0, 30, 0.002)
    ph = (t / 1.5) % 1.0
    y = np.where(ph < 0.5, 0.0, -0.1 * np.sin(2 * np.pi * (ph - 0.5)))
    x = (ph % 0.5) / 0.5
    top = (0.12 * np.exp(-((x - 0.3) / 0.1) ** 2) + 0.14 * np.exp(-((x - 0.7) / 0.1) ** 2)
           + 0.1 * np.sin(np.pi * x))
    y = np.where(ph < 0.5, top * np.sin(np.pi * x) ** 0.2, y)
    f = features(t, y)
    seg = y[(t >= 15) & (t < 15.75)]
    pk, _ = find_peaks(seg)
    assert f.peak1 == pytest.approx(seg[pk[0]], rel=1e-3)
    assert f.peak2 == pytest.approx(seg[pk[-1]], rel=1e-3)
    assert f.valley == pytest.approx(seg[pk[0]:pk[-1]].min(), rel=1e-3)
    assert f.peak1 < f.peak2 and f.valley < f.peak1
    assert f.period == pytest.approx(1.5, rel=1e-3)


def test_noise_does_not_create_peaks():
    rng = np.random.default_rng(0)
    t = np.arange(0, 20, 0.005)
    y = 0.1 * np.sin(2 * np.pi * t / 0.9) + rng.normal(0, 0.002, t.size)
    f = features(t, y, noise=0.002)
    assert f.peak2 is None  # one real maximum per half-cycle
    assert f.period == pytest.approx(0.9, rel=0.01)


def test_settled_and_window():
    t = np.arange(0, 20, 0.005)
    y = 0.1 * np.exp(-t) * np.sin(2 * np.pi * t)
    assert features(t, y).status == "settled"
    # the window selects the last seconds only
    y2 = np.where(t < 10, 0.3 * np.sin(2 * np.pi * t), 0.1 * np.sin(2 * np.pi * t))
    assert features(t, y2, window=5).peak1 == pytest.approx(0.1, rel=1e-3)
    assert features(t, y2, window=20).peak_to_peak == pytest.approx(0.6, rel=1e-3)
    with pytest.raises(ValueError):
        features(t, y2, window=-1)


def test_mixed_half_cycles_and_mirrored_figures():
    # half-cycles with two maxima and with one, alternating: peak1 averages
    # over all of them, peak2 and valley over the two-maximum ones only
    shapes = [(0.15, 0.12, 0.17), (0.13,)] * 6
    t, y = half_cycles(shapes)
    f = features(t, y, window=t[-1])
    assert f.status == "limit_cycle"
    assert f.peak1 == pytest.approx(0.14, rel=1e-3)
    assert f.peak2 == pytest.approx(0.17, rel=1e-3)
    assert f.valley == pytest.approx(0.12, rel=1e-3)
    assert f.neg_peak1 == pytest.approx(0.1, rel=1e-3)
    assert f.neg_peak2 is None and f.neg_valley is None
    # the mirrored signal swaps the positive and negative figures
    g = features(t, -y, window=t[-1])
    assert g.neg_peak1 == pytest.approx(f.peak1, rel=1e-6)
    assert g.neg_peak2 == pytest.approx(f.peak2, rel=1e-6)
    assert g.neg_valley == pytest.approx(f.valley, rel=1e-6)
    assert g.peak1 == pytest.approx(0.1, rel=1e-3) and g.peak2 is None


def test_short_window_on_a_large_oscillation_is_not_settled():
    # a window shorter than one period (the slow design's 3.3 s cycle in a 2.5 s
    # window): not enough crossings for a period, but clearly not at rest
    t = np.arange(0, 5, 0.005)
    y = 0.15 * np.sin(2 * np.pi * t / 3.3)
    f = features(t, y)
    assert f.status == "limit_cycle"
    assert f.period is None
    assert f.peak_to_peak > 0.1
    # with measurement noise of 0.002 rad the same is true; but a slow wander of
    # a few noise levels without any cycle (what compensation leaves) is rest
    rng = np.random.default_rng(1)
    noisy = y + rng.normal(0, 0.002, t.size)
    assert features(t, noisy, noise=0.002).status == "limit_cycle"
    wander = 0.006 * np.sin(2 * np.pi * t / 7.0) + rng.normal(0, 0.002, t.size)
    g = features(t, wander, noise=0.002)
    assert g.peak_to_peak > 2e-3 and g.status == "settled"


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(-20, 20), min_size=3, max_size=60), st.floats(0.0, 10.0))
def test_compiled_peaks_match_scipy(values, prom):
    seg = np.array(values, dtype=float)
    ours = _segment_peaks(seg, prom)
    padded = np.concatenate([[0.0], seg, [0.0]])
    ref, _ = find_peaks(padded, prominence=prom)
    assert list(ours) == list(ref - 1)
