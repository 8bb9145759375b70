"""Units in the plain-text outputs: every number `simulate` and `features` print without
--json names its unit (the JSON's numbers are SI, as the documents say)."""

from __future__ import annotations

import re

import pytest

from frictionlab.cli.common import FEATURE_UNITS, feature_lines
from frictionlab.model.limit_cycles import FEATURES


def test_every_feature_has_a_unit():
    assert set(FEATURES) <= set(FEATURE_UNITS)
    lines = feature_lines({"peak1": 0.1655, "period": None, "max_u": 6.533})
    assert lines == ["  peak1              0.1655 rad", "  period             - s",
                     "  max_u              6.533 m/s^2"]


@pytest.mark.slow
def test_simulate_prints_units(cli):
    res = cli("simulate", "--duration", "3")
    assert res.returncode == 0, res.stderr
    first, *features = res.stdout.strip().splitlines()
    assert re.fullmatch(r"status: \w+  \(3\.00 s simulated\)", first)
    assert [ln.split()[0] for ln in features] == list(FEATURES)
    for ln in features:
        assert ln.split()[-1] == FEATURE_UNITS[ln.split()[0]], ln


def test_max_u_is_in_the_plant_s_unit_of_u():
    assert feature_lines({"max_u": 0.3512}, "V") == ["  max_u              0.3512 V"]


@pytest.mark.parametrize("plant, friction, unit", [("thesis", "classical", "m/s^2"),
                                                    ("qube2", "coulomb", "V"),
                                                    ("thesis", "lugre", "m/s^2")])
def test_predict_names_the_friction_levels_units(plant, friction, unit):
    """``predict``'s describing-function line (its features are :func:`feature_lines`'s, in
    the plant's unit of u): the friction levels in the units of u."""
    from frictionlab.config import build_config
    from frictionlab.studies.predict import friction_nonlinearity

    _nl, text = friction_nonlinearity(build_config("fast", friction, plant=plant))
    levels = re.findall(r"F_[CS] = [\d.e+-]+ (\S+)", text)
    assert levels and all(u.rstrip(",)") == unit for u in levels), text
