"""The controller state record (model.controller.STATE_DTYPE): fields by name,
updated in place by the compiled step, copies independent, float views by reference."""

import numpy as np

from frictionlab.config import build_config
from frictionlab.model.controller import (
    NS,
    STATE_DTYPE,
    STATE_FIELDS,
    controller_step,
    copy_state,
    new_state,
    reset_compensator,
    state_index,
    state_record,
    state_vector,
)
from frictionlab.runs import make_controller


def test_layout_is_one_float_per_field_in_order():
    assert STATE_DTYPE.names == STATE_FIELDS and NS == len(STATE_FIELDS) == 14
    assert STATE_DTYPE.itemsize == 8 * NS
    s = new_state(z_hat=2.5, arm=-1.0)
    v = state_vector(s)
    assert v[state_index("z_hat")] == 2.5 and v[state_index("arm")] == -1.0
    assert np.count_nonzero(v) == 2


def test_the_compiled_step_updates_the_record_in_place_and_a_copy_is_independent():
    cfg = build_config("fast", "lugre", "lugre")
    ctrl = make_controller(cfg)
    gp, cp = ctrl.record()
    s = ctrl.init(0.1)
    before = copy_state(s)
    u, _, f_hat = controller_step(s, gp, cp, 0.1, 0.0, 0.5)
    assert s.u == u and s.f_hat == f_hat and s.z_hat != 0.0
    assert before.x1 == 0.1 and before.u == 0.0 and before.z_hat == 0.0


def test_the_step_method_leaves_its_input_alone():
    ctrl = make_controller(build_config("fast", "lugre", "lugre"))
    s = ctrl.init(0.1)
    out, s2 = ctrl.step(s, 0.1, 0.0, 0.5)
    assert s.z_hat == 0.0 and s2.z_hat == out.z_hat != 0.0


def test_state_record_views_a_float_vector_by_reference():
    x = np.zeros(NS + 3)
    s = state_record(x[2:2 + NS])
    cfg = build_config("fast", "classical", "coulomb")
    gp, cp = make_controller(cfg).record()
    controller_step(s, gp, cp, 0.0, 0.0, 1.0)  # written through to x
    assert x[2 + state_index("relay")] == 1.0 == s.relay
    assert x[0] == x[1] == x[-1] == 0.0


def test_reset_compensator_zeroes_only_the_compensator_fields():
    s = new_state(**{name: 1.0 for name in STATE_FIELDS})
    reset_compensator(s)
    assert (s.x1, s.x2, s.arm, s.arm_dot, s.f_hat, s.u) == (1.0,) * 6
    assert (s.relay, s.z_hat, s.v_hat, s.v_prev, s.fc_hat, s.fs_hat, s.adapt, s.slide) == (0.0,) * 8
