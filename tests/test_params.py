"""Parameter validation and configuration keys."""

import dataclasses
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from frictionlab.config import (
    ConfigError,
    ConfigValueError,
    SimParams,
    UnknownKeyError,
    build_config,
    describe_keys,
    key_metadata,
    valid_keys,
)
from frictionlab.model.design import DesignSpec
from frictionlab.model.friction import FrictionParams
from frictionlab.model.params import ParamError, check_range
from frictionlab.model.plants.thesis import PlantParams


@pytest.mark.parametrize(
    "cls, field, value, needle",
    [
        (PlantParams, "omega0", math.nan, "plant.omega0 is NaN"),
        (PlantParams, "omega0", 0.0, "plant.omega0"),
        (PlantParams, "arm_length", -0.2, "plant.arm_length"),
        (PlantParams, "zeta", 1.5, "[0, 1]"),
        (PlantParams, "input_gain", math.inf, "plant.input_gain"),
        (DesignSpec, "h", 0.0, "design.h"),
        (DesignSpec, "h", -0.005, "(0, 1]"),
        (DesignSpec, "zeta1", 0.0, "(0, 1]"),
        (DesignSpec, "zeta2", 2.0, "design.zeta2"),
        (DesignSpec, "observer_zeta1", 1.01, "design.observer_zeta1"),
        (DesignSpec, "omega2", math.nan, "NaN"),
        (FrictionParams, "sigma0", -1.0, "friction.sigma0"),
        (FrictionParams, "sigma0", 0.0, "[1, 1e+07]"),
        (FrictionParams, "sigma0", 1e-300, "friction.sigma0"),
        (DesignSpec, "omega1", 5e-324, "[0.01, 1000]"),
        (DesignSpec, "observer_omega2", 1e-300, "design.observer_omega2"),
        (FrictionParams, "coulomb", -0.1, "friction.coulomb"),
        (FrictionParams, "stribeck_velocity", 0.0, "friction.stribeck_velocity"),
        (FrictionParams, "hysteresis", -0.01, "friction.hysteresis"),
        (FrictionParams, "stiction_negative", -1.0, "friction.stiction_negative"),
        (SimParams, "substeps", 0, "sim.substeps"),
        (SimParams, "substeps", 2.5, "integer"),
        (SimParams, "noise", -1e-3, "sim.noise"),
        (SimParams, "seed", -1, "sim.seed"),
    ],
)
def test_bad_values_name_field_and_range(cls, field, value, needle):
    with pytest.raises(ValueError) as info:
        cls(**{field: value})
    assert needle in str(info.value)
    assert field in str(info.value)


@pytest.mark.parametrize("cls", [PlantParams, DesignSpec, FrictionParams, SimParams])
def test_non_numbers_are_rejected(cls):
    name = next(f.name for f in dataclasses.fields(cls) if "doc" in f.metadata)
    with pytest.raises(ValueError, match="must be a number"):
        cls(**{name: "abc"})


def test_frozen_and_replace():
    p = PlantParams()
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.omega0 = 7.0
    q = dataclasses.replace(p, omega0=7.5)
    assert q.omega0 == 7.5 and p.omega0 == 6.8
    with pytest.raises(ValueError):
        dataclasses.replace(p, omega0=-1)


def test_defaults_are_thesis_values():
    p = PlantParams()
    assert (p.omega0, p.zeta, p.arm_length, p.g) == (6.8, 0.04, 0.21, 9.82)
    f = FrictionParams()
    assert (f.stiction, f.coulomb, f.viscous, f.sigma0, f.sigma1, f.stribeck_velocity) == (
        2.3, 1.5, 0.07, 100.0, 5.0, 1.0)
    assert f.observer_gain == 0.0
    c = FrictionParams.defaults("lugre", "compensation")
    assert (c.coulomb, c.sigma0, c.sigma1, c.observer_gain) == (1.55, 300.0, 6.0, 7.0)
    assert FrictionParams.defaults("coulomb", "compensation").hysteresis == 0.05
    assert FrictionParams.defaults("classical", "compensation").hysteresis == 0.08


def test_set_overrides_apply_in_order_later_wins():
    cfg = build_config("fast", sets=["plant.omega0=7.0", "plant.omega0=7.5", "sim.seed=3"])
    assert cfg.plant.omega0 == 7.5
    assert cfg.sim.seed == 3
    assert cfg.design.omega0 == 6.8


def test_slow_preset_then_set():
    cfg = build_config("slow", sets=["design.omega2=4"])
    assert cfg.design.omega2 == 4.0
    assert cfg.design.observer_omega2 == 7.5


@pytest.mark.parametrize("key, nearest", [
    ("plant.omega", ["plant.omega0"]),
    ("friction.coloumb", ["friction.coulomb"]),
    ("sim.sed", ["sim.seed"]),
    ("desing.h", ["design.h"]),
    ("coulomb", ["friction.coulomb", "compensation.coulomb"]),
    ("design.stiction", ["friction.stiction", "compensation.stiction"]),
])
def test_unknown_key_suggests_the_nearest_keys(key, nearest):
    with pytest.raises(UnknownKeyError) as info:
        build_config(sets=[f"{key}=1"])
    assert info.value.key == key and info.value.suggestions == nearest
    msg = str(info.value)
    assert key in msg and " or ".join(nearest) in msg
    assert len(msg) < 200 and "\n" not in msg  # not the whole list of keys


@pytest.mark.parametrize("key, home", [
    ("friction.adaptation_gain", "compensation.adaptation_gain"),
    ("friction.adaptation_max", "compensation.adaptation_max"),
    ("compensation.drift", "friction.drift"),
    ("compensation.drift_time", "friction.drift_time"),
])
def test_a_field_only_the_other_section_reads_is_not_a_key_there(key, home):
    # the drift is the plant's, the adaptation law the compensator's: each has one home
    assert key not in valid_keys() and home in valid_keys()
    assert key not in build_config().as_flat_dict()
    assert key not in [row[0] for row in describe_keys()]
    with pytest.raises(UnknownKeyError) as info:
        build_config(sets=[f"{key}=1"])
    assert info.value.suggestions[0] == home


def test_key_metadata_and_descriptions_agree_with_the_keys():
    rows = describe_keys()
    assert [r[0] for r in rows] == valid_keys()
    for key, doc, unit, _rng in rows:
        meta = key_metadata(key)
        assert (meta["doc"], meta["unit"]) == (doc, unit)
    with pytest.raises(UnknownKeyError):
        key_metadata("friction.adaptation_gain")


def test_unknown_key_without_a_near_one_names_its_section_or_the_sections():
    with pytest.raises(UnknownKeyError, match=r"the plant keys are plant\.omega0, "):
        build_config(sets=["plant.nope=1"])
    with pytest.raises(UnknownKeyError, match="section one of plant, design, friction, "
                                               "compensation, sim"):
        build_config(sets=["xyz=1"])


def test_out_of_range_value_is_a_structured_error():
    with pytest.raises(ConfigValueError) as info:
        build_config(sets=["compensation.sigma0=-3"])
    err = info.value
    assert isinstance(err, ParamError) and isinstance(err, ConfigError)
    assert (err.field, err.value, err.allowed) == ("compensation.sigma0", -3, "[1, 1e+07]")
    with pytest.raises(ParamError) as info:
        PlantParams(omega0=10**400)  # beyond float: out of range, not OverflowError
    assert info.value.field == "plant.omega0"


def test_bad_value_text_and_range():
    with pytest.raises(ConfigError, match="not a number"):
        build_config(sets=["plant.omega0=abc"])
    with pytest.raises(ConfigError, match=r"compensation\.sigma0"):
        build_config(sets=["compensation.sigma0=-3"])
    with pytest.raises(ConfigError, match=r"KEY=VALUE"):
        build_config(sets=["plant.omega0"])


def test_toml_config_and_set_override(tmp_path):
    f = tmp_path / "c.toml"
    f.write_text("[plant]\nomega0 = 7.1\nzeta = 0.05\n[friction]\ncoulomb = 1.35\n")
    cfg = build_config(config_file=f, sets=["plant.zeta=0.03"])
    assert cfg.plant.omega0 == 7.1 and cfg.plant.zeta == 0.03 and cfg.friction.coulomb == 1.35
    bad = tmp_path / "bad.toml"
    bad.write_text("[plant]\nfoo = 1\n")
    with pytest.raises(ConfigError, match=r"plant\.foo"):
        build_config(config_file=bad)
    with pytest.raises(ConfigError, match="cannot read"):
        build_config(config_file=tmp_path / "missing.toml")


@pytest.mark.parametrize("text, match", [
    ('[plant]\nomega0 = "7.0"\n', r"plant\.omega0 is a string '7\.0'; it must be a number"),
    ("[plant]\nomega0 = true\n", "is a boolean"),
    ("[plant]\nomega0 = [7.0]\n", "is an array"),
    ("[plant]\nomega0 = 1979-05-27\n", "is a date/time"),
    ("[plant]\nomega0 = {x = 1}\n", r"unknown key 'plant\.omega0\.x'"),
    ("omega0 = 7.0\n", r"did you mean plant\.omega0 or design\.omega0"),
    ("plant = 7.0\n", r"'plant' must be a table"),
    ("[plant]\nomega0 = " + "[" * 5000 + "]" * 5000 + "\n", "nested too deeply"),
    ("[plant\nomega0 = 7\n", "not valid TOML"),
    ("[plant]\nomega0 = 7\n", None),
])
def test_toml_values_must_be_numbers(tmp_path, text, match):
    f = tmp_path / "c.toml"
    f.write_text(text)
    if match is None:
        assert build_config(config_file=f).plant.omega0 == 7.0  # a TOML integer is fine
        return
    with pytest.raises(ConfigError, match=match) as info:
        build_config(config_file=f)
    assert "\n" not in str(info.value) and str(f) in str(info.value)


def test_toml_file_not_text_or_too_large(tmp_path):
    f = tmp_path / "c.toml"
    f.write_bytes(b"\xff\xfe[plant]")
    with pytest.raises(ConfigError, match="not UTF-8"):
        build_config(config_file=f)
    f.write_bytes(b"# " + b"x" * (2 << 20))
    with pytest.raises(ConfigError, match="larger than"):
        build_config(config_file=f)
    with pytest.raises(ConfigError, match="cannot read"):
        build_config(config_file=tmp_path)  # a directory


def test_interface_keys_exist():
    keys = set(valid_keys())
    for k in [
        "plant.omega0", "plant.zeta", "plant.arm_length", "plant.g", "plant.input_gain",
        "design.omega0", "design.h", "design.omega1", "design.zeta1", "design.omega2",
        "design.zeta2", "design.observer_omega1", "design.observer_zeta1",
        "design.observer_omega2", "design.observer_zeta2", "friction.stiction",
        "friction.coulomb", "friction.viscous", "friction.stribeck_velocity",
        "friction.sigma0", "friction.sigma1", "friction.observer_gain",
        "friction.zero_velocity_band", "friction.hysteresis", "compensation.sigma0",
        "compensation.observer_gain", "compensation.hysteresis", "sim.initial_angle",
        "sim.substeps", "sim.noise", "sim.seed",
    ]:
        assert k in keys, k


_BOUND = st.one_of(st.none(), st.sampled_from([-1.0, 0.0, 0.5, 2.0]))


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from(
    [-1.0, 0.0, 0.5, 2.0, math.inf, -math.inf])), _BOUND, _BOUND, st.booleans(), st.booleans())
def test_check_range_accepts_exactly_the_values_in_the_range(value, lo, hi, lo_open, hi_open):
    """check_range (with its fast path for floats) returns a float exactly when it
    lies in the range, ends open or closed as asked (an infinite value only on an
    unbounded side), and otherwise raises naming the field."""
    inside = (not math.isnan(value)
              and (lo is None or value > lo or (value == lo and not lo_open))
              and (hi is None or value < hi or (value == hi and not hi_open))
              and not (math.isinf(value) and ((value < 0 and lo is not None)
                                              or (value > 0 and hi is not None))))
    if inside:
        got = check_range("x", value, lo, hi, lo_open=lo_open, hi_open=hi_open)
        assert type(got) is float and got == value
    else:
        with pytest.raises(ParamError) as err:
            check_range("x", value, lo, hi, lo_open=lo_open, hi_open=hi_open)
        assert err.value.field == "x"


@pytest.mark.parametrize("kw, field", [({"friction_kind": "sand"}, "friction"),
                                       ({"compensation_kind": "prayer"}, "compensation")])
def test_a_bad_model_kind_is_refused_by_its_field(kw, field):
    from frictionlab.config import Config, ConfigValueError

    with pytest.raises(ConfigValueError) as info:
        Config(**kw)
    assert info.value.field == field and f"{field} must be one of" in str(info.value)
