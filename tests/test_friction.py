"""Friction models: force laws, steady states, passivity, stiction, hysteresis."""

import dataclasses

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from frictionlab.model.friction import (
    KINDS,
    FrictionParams,
    lugre_dz,
    lugre_force,
    lugre_step_exact,
    make_model,
    stribeck_curve,
)

levels = st.floats(0.1, 5.0)


def stribeck_oracle(v, fs, fc, fv, vs):
    return (fc + (fs - fc) * np.exp(-((v / vs) ** 2))) * np.sign(v) + fv * v


@pytest.mark.parametrize("v", [-8.0, -2.0, -0.5, -0.01, 0.003, 0.2, 1.0, 3.5, 12.0])
def test_lugre_steady_sliding_is_stribeck_curve(v):
    """Integrate dz/dt at constant v to steady state: F equals the Stribeck curve."""
    p = FrictionParams()  # eq. (21) values, k = 0
    pk = p.record()
    z = 0.0
    for _ in range(20000):
        z, _, _ = lugre_step_exact(v, z, 0.0, 0.01, pk)
    F = lugre_force(v, z, lugre_dz(v, z, 0.0, pk), pk)
    assert abs(F - stribeck_oracle(v, 2.3, 1.5, 0.07, 1.0)) < 1e-6
    assert abs(make_model("lugre", p).steady_state(v) - F) < 1e-6


@settings(max_examples=60, deadline=None)
@given(v=st.floats(-20, 20), fs=levels, fc=levels, fv=st.floats(0, 1), vs=st.floats(0.1, 5))
def test_stribeck_curve_closed_form(v, fs, fc, fv, vs):
    p = FrictionParams(stiction=fs, coulomb=fc, viscous=fv, stribeck_velocity=vs).record()
    assert np.isclose(stribeck_curve(v, p), stribeck_oracle(v, fs, fc, fv, vs), atol=1e-12)


@settings(max_examples=200, deadline=None)
@pytest.mark.slow
@given(v=st.floats(-20, 20), fe=st.floats(-20, 20), fs=levels, fc=levels,
       band=st.floats(0, 0.1), kind=st.sampled_from(["viscous", "coulomb", "classical",
                                                     "stribeck"]))
def test_static_models_never_add_energy(v, fe, fs, fc, band, kind):
    """F*v >= 0 whenever the arm moves (|v| beyond the zero-velocity band)."""
    m = make_model(kind, stiction=fs, coulomb=fc, zero_velocity_band=band, hysteresis=0.0)
    F, _ = m.step(float(np.sign(v)), v, fe, 0.005)
    if abs(v) >= band and v != 0.0:
        assert F * v >= 0.0


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(v=st.floats(-20, 20), zr=st.floats(-1, 1), fs=levels, fc=levels,
       s0=st.floats(1, 1000), s1=st.floats(0, 20), fv=st.floats(0, 1))
def test_lugre_passivity(v, zr, fs, fc, s0, s1, fv):
    """Bristle passivity: sigma0 z v >= d/dt(sigma0 z^2 / 2) always, and the full
    dissipation inequality F v >= d/dt(sigma0 z^2/2) where sigma1 |v| <= 4 s(v)
    (the condition for the sigma1 cross term, Olsson 1996)."""
    p = FrictionParams(stiction=fs, coulomb=fc, viscous=fv, sigma0=s0, sigma1=s1).record()
    level = fc + (fs - fc) * np.exp(-(v**2))
    z = zr * level / s0  # inside the invariant set |z| <= s(v)/sigma0
    dz = lugre_dz(v, z, 0.0, p)
    storage_rate = s0 * z * dz
    assert s0 * z * v >= storage_rate - 1e-9 * (1 + abs(storage_rate))
    assume(s1 * abs(v) <= 4 * level)
    F = lugre_force(v, z, dz, p)
    assert F * v >= storage_rate - 1e-9 * (1 + abs(storage_rate))


def test_velocity_dependent_sigma1_restores_passivity():
    p = FrictionParams(sigma1=20.0, sigma1_velocity=0.1).record()
    v, z = 3.0, -0.01
    dz = lugre_dz(v, z, 0.0, p)
    assert lugre_force(v, z, dz, p) * v >= 100.0 * z * dz


def test_asymmetric_lugre_levels():
    p = FrictionParams(coulomb=1.5, coulomb_negative=1.2, stiction=2.3, stiction_negative=2.0,
                       viscous=0.07, viscous_negative=0.05)
    m = make_model("lugre", p)
    assert np.isclose(m.steady_state(50.0), 1.5 + 0.07 * 50)
    assert np.isclose(m.steady_state(-50.0), -1.2 - 0.05 * 50)
    assert np.isclose(m.steady_state(1e-9), 2.3, atol=1e-6)
    assert np.isclose(m.steady_state(-1e-9), -2.0, atol=1e-6)


@settings(max_examples=100, deadline=None)
@given(fe=st.floats(-2.29, 2.29), band=st.floats(0.001, 0.05), frac=st.floats(-0.99, 0.99))
def test_classical_holds_arm_below_stiction(fe, band, frac):
    """Inside the band, |F_e| < F_S: friction balances the force (no acceleration)."""
    m = make_model("classical", zero_velocity_band=band)
    assert m.step(m.init(), frac * band, fe, 0.005)[0] == fe


def test_classical_breaks_away_and_slides():
    m = make_model("classical")
    assert m.step(0.0, 0.0, 3.0, 0.005)[0] == pytest.approx(2.3)
    assert m.step(0.0, 0.0, -3.0, 0.005)[0] == pytest.approx(-2.3)
    assert m.step(0.0, 0.5, 10.0, 0.005)[0] == pytest.approx(1.5)
    assert m.step(0.0, -0.5, 10.0, 0.005)[0] == pytest.approx(-1.5)


def test_stribeck_classical_implementation_form():
    m = make_model("stribeck", hysteresis=0.08, stiction=2.3, coulomb=1.55, stribeck_velocity=1)
    assert m.step(0.0, 0.05, 1.0, 0.005)[0] == 1.0  # inside +-eps: F = u
    assert m.step(0.0, 0.05, 5.0, 0.005)[0] == pytest.approx(2.3)  # limited to F_S
    v = 0.7
    assert m.step(0.0, v, 0.0, 0.005)[0] == pytest.approx(1.55 + 0.75 * np.exp(-(v**2)))


def test_hysteresis_relay_depends_on_history():
    m = make_model("coulomb", coulomb=1.5, hysteresis=0.05)
    # the same velocity inside the band gives different forces after different histories
    _, s_up = m.step(m.init(), 0.2, 0.0, 0.005)
    _, s_down = m.step(m.init(), -0.2, 0.0, 0.005)
    f1, _ = m.step(s_up, 0.01, 0.0, 0.005)
    f2, _ = m.step(s_down, 0.01, 0.0, 0.005)
    assert f1 == 1.5 and f2 == -1.5
    # beyond the band the history no longer matters
    assert m.step(s_down, 0.06, 0.0, 0.005)[0] == 1.5


def test_ideal_relay_without_hysteresis_switches_at_zero():
    m = make_model("coulomb", hysteresis=0.0)
    assert m.step(-1.0, 1e-6, 0.0, 0.005)[0] == 1.5
    assert m.step(1.0, -1e-6, 0.0, 0.005)[0] == -1.5


def test_observer_gain_zero_is_plain_lugre():
    p0 = FrictionParams().record()
    pk = dataclasses.replace(FrictionParams(), observer_gain=3.0).record()
    assert lugre_dz(0.4, 0.01, 0.0, pk) == lugre_dz(0.4, 0.01, 0.0, p0)
    assert lugre_dz(0.4, 0.01, 0.2, pk) == pytest.approx(lugre_dz(0.4, 0.01, 0.0, p0) - 0.6)


def test_exact_bristle_update_is_stable_where_euler_is_not():
    """sigma0 = 1000, h = 5 ms: forward Euler diverges, the exact update does not."""
    p = FrictionParams(sigma0=1000.0).record()
    v, h = 3.0, 0.005
    z_exact, z_euler = 0.0, 0.0
    for _ in range(200):
        z_exact, _, _ = lugre_step_exact(v, z_exact, 0.0, h, p)
        z_euler = z_euler + h * lugre_dz(v, z_euler, 0.0, p)
    z_ss = 1.5 / 1000 * (1 + (2.3 / 1.5 - 1) * np.exp(-9))
    assert abs(z_exact - z_ss) < 1e-9
    assert not abs(z_euler) < 1.0  # blew up (or overflowed to inf/nan)


def test_lugre_object_steps_to_the_stribeck_curve_and_matches_the_force_law():
    m = make_model("lugre", sigma0=300.0)
    assert m.kind == "lugre" and m.has_state
    z = m.init()
    for _ in range(2000):
        f, z = m.step(z, 0.8, 0.0, 0.005)
    assert f == pytest.approx(m.steady_state(0.8), abs=1e-9)
    # at the steady state the bristle rate vanishes and the force law agrees
    p = m.params.record()
    assert abs(lugre_dz(0.8, z, 0.0, p)) < 1e-9
    assert lugre_force(0.8, z, 0.0, p) == pytest.approx(f, abs=1e-9)


def test_each_kind_has_its_own_model_class():
    for kind in ("none", "viscous", "coulomb", "classical", "stribeck", "lugre"):
        m = make_model(kind)
        assert type(m).kind == kind and m.code == KINDS.index(kind)
    assert make_model("viscous", viscous=0.5).step(0.0, -2.0, 0.0, 0.005)[0] == \
        pytest.approx(-1.0)
    assert make_model("none").step(0.0, 3.0, 1.0, 0.005) == (0.0, 0.0)


def test_unknown_kind_rejected():
    with pytest.raises(ValueError, match="friction model must be one of"):
        make_model("dahl")
