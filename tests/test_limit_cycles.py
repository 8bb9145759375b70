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


# ---------------------------------------------------------------------------
# shallow dips and shoulders (the thesis's reading of its plots, Table 1)
# ---------------------------------------------------------------------------


def _bumps(x, c, sep):
    """A positive half-cycle on x in (0, 1): a sine lobe with a second bump of
    relative size ``c`` at ``0.5 + sep``, and its derivative."""
    w = 0.08
    g = np.exp(-((x - 0.5 - sep) / w) ** 2)
    f = np.sin(np.pi * x) ** 2 * (1.0 + c * g)
    df = (2 * np.pi * np.sin(np.pi * x) * np.cos(np.pi * x) * (1.0 + c * g)
          + np.sin(np.pi * x) ** 2 * c * g * (-2 * (x - 0.5 - sep) / w**2))
    return f, df


def _truth(x, f, df):
    """(peak2, valley) of one lobe from its analytic derivative: two maxima (a sign
    change of f' from - to + after the first maximum), a shoulder (a local minimum
    of |f'| after the first maximum, f' < 0 around it), or neither."""
    i_max = int(np.argmax(df < 0))  # first descent: the first maximum
    tail = df[i_max:]
    up = np.flatnonzero((tail[:-1] < 0) & (tail[1:] >= 0))
    if len(up):
        j = i_max + up[0] + 1
        k = j + int(np.argmax(df[j:] < 0))  # the second maximum
        return f[k], f[i_max:k].min()
    a = np.abs(tail)
    mins = np.flatnonzero((a[1:-1] < a[:-2]) & (a[1:-1] < a[2:])) + 1
    if len(mins):
        return f[i_max + mins[0]], None
    return None, None


def _signal(shapes, n=2000):
    x = np.linspace(0.0, 1.0, n, endpoint=False)[1:]
    parts = [-0.1 * np.sin(np.pi * x)]
    for c, sep in shapes:
        f, _ = _bumps(x, c, sep)
        parts += [[0.0], 0.1 * f, [0.0], -0.1 * np.sin(np.pi * x)]
    y = np.concatenate(parts)
    return np.arange(len(y)) * 1e-3, y


@pytest.mark.slow
@settings(max_examples=20, deadline=None)
@given(st.floats(0.0, 0.6), st.floats(0.1, 0.3))
def test_dips_and_shoulders_of_known_waveforms(c, sep):
    """A lobe with a second bump: whatever the dip's depth (down to none), two
    maxima give peak2 and valley, a shoulder gives peak2 alone, a plain lobe
    neither, at the analytic waveform's values."""
    x = np.linspace(0.0, 1.0, 50_001)[1:-1]
    f, df = _bumps(x, c, sep)
    p2, va = _truth(x, 0.1 * f, df)
    t, y = _signal([(c, sep)] * 3)
    feats = features(t, y, window=t[-1])
    assert feats.peak1 == pytest.approx(0.1 * f[np.argmax(df < 0)], abs=1e-4)
    if p2 is None:
        assert feats.peak2 is None and feats.valley is None
    else:
        assert feats.peak2 == pytest.approx(p2, abs=1e-4)
        if va is None:
            assert feats.valley is None
        else:
            assert feats.valley == pytest.approx(va, abs=1e-4)


def test_a_one_percent_dip_counts_and_noise_does_not():
    # a dip of 1 % of the height (the thesis's LuGre rows) counts; the same lobe
    # under measurement noise keeps it only when the dip stands above 3 sigma
    t, y = _signal([(0.35, 0.18)] * 12)
    f = features(t, y, window=t[-1])
    assert f.peak2 is not None and f.valley is not None
    assert 0.0 < (f.peak2 - f.valley) / f.peak1 < 0.1
    rng = np.random.default_rng(4)
    dip = f.peak2 - f.valley
    noisy = features(t, y + rng.normal(0, dip, t.size), window=t[-1], noise=dip)
    assert noisy.valley is None  # a dip of one sigma is not a dip


def test_shoulder_is_peak2_without_valley():
    t, y = _signal([(0.25, 0.25)] * 6)
    x = np.linspace(0.0, 1.0, 200_001)[1:-1]
    f, df = _bumps(x, 0.25, 0.25)
    p2, va = _truth(x, 0.1 * f, df)
    assert p2 is not None and va is None  # the waveform has a shoulder
    feats = features(t, y, window=t[-1])
    assert feats.peak2 == pytest.approx(p2, abs=1e-4)
    assert feats.valley is None and feats.peak1 > feats.peak2


def _reference_half_cycle(seg, rel, slope_noise=0.0, noise=0.0):
    """peak1, peak2, valley of one half-cycle in plain numpy/scipy: the definition
    of docs/cli.md ("Features") written independently of the compiled kernel."""
    height = seg.max()
    pk, _ = find_peaks(np.concatenate([[0.0], seg, [0.0]]),
                       prominence=max(rel * height, 3 * noise, 1e-12))
    pk = pk - 1
    if len(pk) == 0:
        return None, None, None
    if len(pk) >= 2:
        return seg[pk[0]], seg[pk[-1]], seg[pk[0]:pk[-1] + 1].min()
    p = pk[0]
    d = np.diff(seg[p:])
    if len(d) < 3:
        return seg[p], None, None
    w = -np.abs(d)
    floor = max(rel * max(0.0, -d.min()), 3 * slope_noise, 1e-15)
    cand, _ = find_peaks(w, prominence=floor)
    best = None
    for c in cand:
        q, value = c + 1, seg[p + c] + seg[p + c + 1]
        while q < len(w) and w[q] >= w[c] - floor:
            value = max(value, seg[p + q] + seg[p + q + 1])
            q += 1
        best = value if best is None else max(best, value)
    return seg[p], (None if best is None else 0.5 * best), None


@pytest.mark.slow
@settings(max_examples=100, deadline=None)
@given(st.lists(st.integers(0, 40), min_size=4, max_size=80), st.sampled_from([1e-6, 0.02, 0.2]))
def test_compiled_half_cycle_matches_the_reference(values, rel):
    """The compiled half-cycle kernel and the plain-Python definition agree on
    arbitrary (quantised, plateau-ridden) positive segments."""
    from frictionlab.model.limit_cycles import _half_cycle_kernel

    seg = np.array(values, dtype=float) + 1.0
    p1, p2, va = _half_cycle_kernel(seg, np.array([0]), np.array([len(seg)]), 0.0, rel, 0.0)
    ref = _reference_half_cycle(seg, rel)
    for got, want in zip((p1[0], p2[0], va[0]), ref, strict=True):
        if want is None:
            assert np.isnan(got)
        else:
            assert got == want
