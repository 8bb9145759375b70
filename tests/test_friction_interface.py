"""One friction interface: every model and every compensator, no branching on kind.

Each friction model (``friction.KINDS``) is an object with ``init() -> state``
and ``step(state, v, f_ext, dt, e=0.0) -> (F, state)`` over the one compiled
law :func:`frictionlab.model.friction.friction_step`; each compensator
(``controller.COMPENSATORS``) is ``init() -> state`` and
``step(state, v, ...) -> (F_hat, state)`` over the same law with its own
parameters.  The properties below hold for all of them alike.
"""

import inspect
import math

import numpy as np
import pytest

from frictionlab.model.controller import COMPENSATORS
from frictionlab.model.friction import (
    KINDS,
    MODELS,
    FrictionParams,
    friction_step,
    make_model,
    steady_state,
    stribeck_level,
)
from frictionlab.studies.compensation import make_compensator

H = 0.005
VELOCITIES = (-6.0, -1.3, -0.4, 0.25, 0.9, 4.0)


@pytest.fixture(params=KINDS)
def model(request):
    # a band narrower than the smallest |v| tested, so every v tested slides
    return make_model(request.param, zero_velocity_band=0.01, hysteresis=0.02)


def test_every_kind_has_a_model_with_the_same_interface():
    assert set(MODELS) == set(KINDS)
    sig = {kind: str(inspect.signature(cls.step)) for kind, cls in MODELS.items()}
    assert len(set(sig.values())) == 1, sig
    assert all(not hasattr(cls, "force") for cls in MODELS.values())


def test_init_and_step_return_floats_and_a_finite_force(model):
    state = model.init()
    assert isinstance(state, float)
    for v in VELOCITIES:
        f, state = model.step(state, v, 0.7, H)
        assert isinstance(f, float) and isinstance(state, float)
        assert math.isfinite(f) and math.isfinite(state)


def test_object_step_is_the_compiled_law(model):
    """The object API runs the very function the simulator runs, bit for bit."""
    p = model.params.record()
    s_obj = s_law = model.init()
    for v, fe, e in ((0.3, 0.5, 0.0), (-2.0, 3.0, 0.1), (0.004, -1.0, -0.2)):
        f_obj, s_obj = model.step(s_obj, v, fe, H, e)
        f_law, s_law = friction_step(model.code, p, s_law, v, fe, H, e)
        assert (f_obj, s_obj) == (f_law, s_law)


def test_state_round_trips(model):
    """The state is all the memory: restarting from a returned state continues
    the same trajectory as stepping on."""
    state = model.init()
    for v in (0.5, -0.2, 1.5):
        _, state = model.step(state, v, 0.0, H)
    saved = float(state)
    run_on = [model.step(state, v, 0.3, H) for v in (0.2, 0.1)]
    restarted = [model.step(saved, v, 0.3, H) for v in (0.2, 0.1)]
    assert run_on == restarted


@pytest.mark.parametrize("v", VELOCITIES)
def test_steady_state_is_where_step_settles(model, v):
    state = model.init()
    for _ in range(3000):  # 15 s at constant v: the bristle settles in ms
        f, state = model.step(state, v, 0.0, H)
    assert f == pytest.approx(model.steady_state(v), rel=1e-9, abs=1e-9)


@pytest.mark.parametrize("v", VELOCITIES)
def test_friction_dissipates_in_steady_sliding(model, v):
    """F v >= 0: friction never drives the sliding arm (passivity)."""
    assert model.steady_state(v) * v >= 0.0


def test_stribeck_level_is_the_one_curve():
    """The steady LuGre friction and the classical implementation form both
    follow :func:`stribeck_level` (F_C + (F_S - F_C) exp(-(v/v_S)^2))."""
    p = FrictionParams(viscous=0.0, hysteresis=0.02)
    for v in VELOCITIES:
        level = stribeck_level(v, p.record()) * np.sign(v)
        assert make_model("lugre", p).steady_state(v) == pytest.approx(level, rel=1e-12)
        assert make_model("stribeck", p).steady_state(v) == level


@pytest.fixture(params=COMPENSATORS)
def compensator(request):
    return make_compensator(request.param)


def test_compensators_step_from_init_to_a_finite_estimate(compensator):
    state = compensator.init()
    for v in VELOCITIES:
        f, state = compensator.step(state, v, u_fb=0.4, e=0.01)
        assert math.isfinite(f) and f == state.friction_estimate


@pytest.mark.parametrize("v", VELOCITIES)
def test_compensators_estimate_their_model_in_steady_sliding(compensator, v):
    """In steady sliding at |v| beyond every band, each compensator estimates the
    steady-state friction of the law it reports (:func:`steady_state` of
    ``law(state)``: its model and parameters, the adaptive one's with the levels
    it has adapted to), with the same sign as v.

    Tolerance: after 3000 steps (15 s) at constant v the LuGre observer's
    bristle, integrated exactly over each step, has relaxed towards its steady
    value at the rate sigma0 |v| / s(v) >= 300 * 0.25 / 2.3 = 33 1/s, so its
    initial transient is below e^-490; the adaptive levels have reached their
    bounds or move by less than 1e-8 per tick (the stiction's regressor at
    4 rad/s is exp(-16)), which leaves z behind its steady value by a
    relative 1e-14.  What is left is rounding (about 1e-16 relative): rel 1e-9.
    """
    state = compensator.init()
    for _ in range(3000):
        f, state = compensator.step(state, v, u_fb=0.0, e=0.0)
    code, p, _ = compensator.law(state)
    assert f * v > 0.0
    assert f == pytest.approx(steady_state(code, p, v), rel=1e-9)


def test_compensators_run_the_model_law_with_their_own_parameters(compensator):
    """Bit for bit, a compensator's estimate is ``friction_step`` of the law it
    reports (its model kind with :func:`compensator_params`, the adaptive one's
    with the levels it adapted to in that step)."""
    state = compensator.init()
    for v, u_fb, e in ((0.3, 0.5, 0.02), (0.01, 1.0, 0.0), (-2.0, 0.0, -0.1), (1.4, 0.2, 0.3)):
        f, new = compensator.step(state, v, u_fb=u_fb, e=e)
        code, p, _ = compensator.law(new)
        f_law, law_state = friction_step(code, p, compensator.law(state)[2], v, u_fb, H, e)
        assert f == f_law and law_state == compensator.law(new)[2]
        state = new

