"""Limit-cycle features on synthetic signals with known answers."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import find_peaks

from frictionlab.limit_cycles import _segment_peaks, features


def double_hump(t, period=1.0, p1=0.15, p2=0.17, dip=0.02):
    """A cycle whose positive half has two maxima (heights ~p1, ~p2) and a valley."""
    ph = (t / period) % 1.0
    y = np.sin(2 * np.pi * ph)
    pos = ph < 0.5
    x = ph[pos] / 0.5  # 0..1 over the positive half
    hump1 = p1 * np.exp(-((x - 0.3) / 0.12) ** 2)
    hump2 = p2 * np.exp(-((x - 0.7) / 0.12) ** 2)
    base = (p1 - dip) * np.sin(np.pi * x) ** 0.5
    y[pos] = np.maximum(np.maximum(hump1, hump2), base * (x > 0) * (x < 1))
    y[~pos] = -y[pos][: (~pos).sum()] if (~pos).sum() <= pos.sum() else y[~pos]
    return y


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


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(-20, 20), min_size=3, max_size=60), st.floats(0.0, 10.0))
def test_compiled_peaks_match_scipy(values, prom):
    seg = np.array(values, dtype=float)
    ours = _segment_peaks(seg, prom)
    padded = np.concatenate([[0.0], seg, [0.0]])
    ref, _ = find_peaks(padded, prominence=prom)
    assert list(ours) == list(ref - 1)
