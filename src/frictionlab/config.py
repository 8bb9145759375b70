"""Run configuration: every parameter of a run, addressable by ``section.field`` keys.

The keys are those ``frictionlab keys`` lists (docs/cli.md; ``plant.omega0``,
``design.h``, ``friction.coulomb``, ``compensation.sigma0``, ``sim.seed``,
``rig.theta_scale``...).
A configuration is built from, in order: the thesis defaults, the design
preset (``fast``/``slow``), the per-model friction defaults, a TOML file, and
``--set KEY=VALUE`` overrides (applied in order, the later winning).
Unknown keys and bad values raise :class:`ConfigError` (a ``ValueError``)
naming the key and what is allowed (an unknown key: :class:`UnknownKeyError`,
with the nearest valid keys); a value out of its range raises the parameter
class's :class:`~frictionlab.model.params.ParamError`.
"""

from __future__ import annotations

import dataclasses
import datetime
import difflib
import functools
import math
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .model.actuator import ActuatorParams
from .model.controller import COMPENSATOR_FIELDS, COMPENSATOR_KINDS
from .model.controller import check_compensator as _check_compensator
from .model.design import DesignSpec, preset
from .model.friction import KINDS, FrictionParams
from .model.params import ParamError, Validated, param
from .model.plants import FURUTA_DC, THESIS, PlantKind
from .model.plants.furuta_dc import PRESET_FRICTION, PRESET_SWINGUP, linearization
from .model.plants.furuta_dc import preset as dc_preset
from .model.plants.furuta_dc_design import dc_spec
from .model.plants.thesis import PlantParams
from .model.rig import RigScaling, motor_rig
from .model.sensor import ADC_STEP, encoder_step
from .model.swingup import SwingUpParams

__all__ = [
    "COMPENSATOR_FIELDS",
    "COMPENSATOR_KINDS",
    "PLANT_FIELDS",
    "PLANT_FRICTION_KINDS",
    "PLANT_NAMES",
    "Config",
    "ConfigError",
    "ConfigValueError",
    "ControllerLimits",
    "SimParams",
    "UnknownKeyError",
    "build_config",
    "check_compensator",
    "inert_keys",
    "parse_assignment",
    "valid_keys",
]

#: Plant friction models selectable with ``--friction``.
PLANT_FRICTION_KINDS = KINDS

#: ``--plant`` names: the thesis's plant (eq. 6) and the DC-motor Furuta
#: pendulum (:mod:`frictionlab.model.plants.furuta_dc`) with its presets
#: (``furuta-dc`` and ``qube2``: the QUBE-Servo 2; ``qube3``: the QUBE-Servo 3).
PLANT_NAMES = ("thesis", "furuta-dc", "qube2", "qube3")


def plant_model(name: str) -> PlantKind:
    """The plant (:data:`frictionlab.model.plants.PLANTS`) behind a ``--plant`` name."""
    if name not in PLANT_NAMES:
        raise ConfigValueError("plant", name, ", ".join(PLANT_NAMES),
                               f"plant must be one of {', '.join(PLANT_NAMES)}; got {name!r}")
    return THESIS if name == "thesis" else FURUTA_DC


class ConfigError(ValueError):
    """A configuration key or value is invalid (CLI exit status 2)."""


class ConfigValueError(ConfigError, ParamError):
    """A key's value of the wrong type or out of its range: a :class:`ConfigError`
    with the :class:`~frictionlab.model.params.ParamError` attributes ``field``
    (the key), ``value`` and ``allowed``."""


class UnknownKeyError(ConfigError):
    """A key that is not a parameter key.

    Attributes
    ----------
    key : str
        The key given.
    suggestions : list of str
        The nearest valid keys (:func:`suggest_keys`), best first; may be empty.
    field : str or None
        The argument that named the key (e.g. ``vary``), if not a ``--set``
        or TOML key; the command line names its option.
    """

    def __init__(self, key: str, where: str = "", field: str | None = None,
                 plant: str = "thesis"):
        self.key = key
        self.field = field
        self.suggestions = suggest_keys(key, plant=plant)
        section = key.split(".", 1)[0]
        if self.suggestions:
            hint = f"did you mean {' or '.join(self.suggestions)}?"
        elif section in _SECTIONS and "." in key:
            hint = (f"the {section} keys are "
                    f"{', '.join(k for k in valid_keys(plant) if k.startswith(section + '.'))}")
        else:
            hint = f"keys are section.field with section one of {', '.join(_SECTIONS)}"
        super().__init__(f"{where}unknown key {_short(key)}; {hint}")


def _short(text: str, limit: int = 60) -> str:
    r = repr(text)
    return r if len(r) <= limit else r[:limit - 3] + "..."


def suggest_keys(key: str, n: int = 3, plant: str = "thesis") -> list[str]:
    """The valid keys nearest to ``key``, best first (at most ``n``).

    A known section with a misspelt field is matched within its section
    (``plant.omega`` -> ``plant.omega0``); a field under the wrong section
    or without one finds the sections that have it (``design.coulomb``,
    ``coulomb`` -> ``friction.coulomb``, ``compensation.coulomb``); anything
    else is matched against whole keys (:func:`difflib.get_close_matches`).
    """
    keys = valid_keys(plant)
    key = key.strip()[:100]
    section, dot, field = key.rpartition(".") if key.count(".") > 1 else key.partition(".")
    if not dot:
        section, field = "", key
    by_field: dict[str, list[str]] = {}
    for k in keys:
        by_field.setdefault(k.split(".", 1)[1], []).append(k)
    if section in _SECTIONS:
        own = [k.split(".", 1)[1] for k in keys if k.startswith(section + ".")]
        close = difflib.get_close_matches(field, own, n=n, cutoff=0.6)
        if close:
            return [f"{section}.{f}" for f in close]
    if field in by_field:
        return by_field[field][:n]
    if not section:
        close = difflib.get_close_matches(field, list(by_field), n=n, cutoff=0.7)
        return [k for f in close for k in by_field[f]][:n]
    return difflib.get_close_matches(key, keys, n=n, cutoff=0.75)


@dataclass(frozen=True)
class SimParams(Validated):
    """Simulation settings (keys ``sim.*``)."""

    _prefix = "sim."

    initial_angle: float = param(0.05, "initial pendulum angle (pi: hanging down, at rest; "
                                 "rig-sim's pendulum at the start of a session; a start "
                                 "beyond sim.fall_angle needs a swing-up)", "rad",
                                 lo=-math.pi, hi=math.pi)
    substeps: int | None = param(None, "arm and friction integration substeps per sampling "
                                 "period (None = the model's accurate default: 10, LuGre 6)",
                                 "1", lo=1, hi=10000, integer=True, optional=True)
    pendulum_steps: int = param(2, "pendulum integration steps per sampling period (the "
                                "smooth pendulum is driven by the arm's mean acceleration)",
                                "1", lo=1, hi=10000, integer=True)
    noise: float = param(0.0, "std. dev. of measurement noise on each measured signal "
                         "(theta, Omega, Omega_dot) in its SI unit", "rad, rad, rad/s",
                         lo=0.0, hi=1.0)
    seed: int = param(0, "random seed of the measurement noise", "1", lo=0, hi=2**32 - 1,
                      integer=True)
    quantization: float = param(0.0, "1 = measure through the rig's 12-bit converters, a "
                                "motor rig's encoders (the grid in raw units with the rig.* "
                                "factors, wrap and range; frictionlab.model.sensor), 0 = ideal",
                                "1", lo=0.0, hi=1.0)
    fall_angle: float = param(math.pi / 2, "|theta| beyond which the pendulum has fallen",
                              "rad", lo=0.0, hi=math.pi, lo_open=True)
    duration: float = param(40.0, "simulated time", "s", lo=0.0, hi=1e5, lo_open=True)


@dataclass(frozen=True)
class ControllerLimits(Validated):
    """Limits on every controller command for the whole run (keys ``controller.*``)."""

    _prefix = "controller."

    u_max: float | None = param(None, "|u| limit of every controller command (swing-up, "
                                "catch, balancing, compensation), in the simulator and the "
                                "loop (None = only the DAC's range, 1/|rig.u_scale|)",
                                "units of u", lo=0.0, lo_open=True, optional=True)


@dataclass(frozen=True)
class Config:
    """Everything a closed-loop run needs.

    ``plant_kind`` is the ``--plant`` name (:data:`PLANT_NAMES`); ``plant`` its
    parameters (keys ``plant.*``: the class of :func:`plant_model`).
    """

    plant: Any = dataclasses.field(default_factory=PlantParams)
    design: DesignSpec = dataclasses.field(default_factory=DesignSpec)
    friction_kind: str = "classical"
    friction: FrictionParams = dataclasses.field(default_factory=FrictionParams)
    compensation_kind: str = "none"
    compensation: FrictionParams = dataclasses.field(
        default_factory=lambda: FrictionParams.defaults("lugre", "compensation"))
    sim: SimParams = dataclasses.field(default_factory=SimParams)
    rig: RigScaling = dataclasses.field(default_factory=RigScaling)
    swingup: SwingUpParams = dataclasses.field(default_factory=SwingUpParams)
    actuator: ActuatorParams = dataclasses.field(default_factory=ActuatorParams)
    controller: ControllerLimits = dataclasses.field(default_factory=ControllerLimits)
    plant_kind: str = "thesis"

    def __post_init__(self) -> None:
        kind = plant_model(self.plant_kind)
        if not isinstance(self.plant, kind.params):
            raise ConfigError(f"plant {self.plant_kind!r} takes {kind.params.__name__} "
                              f"parameters, got {type(self.plant).__name__}")
        for field, kind, kinds in (("friction", self.friction_kind, PLANT_FRICTION_KINDS),
                                   ("compensation", self.compensation_kind, COMPENSATOR_KINDS)):
            if kind not in kinds:
                raise ConfigValueError(field, kind, ", ".join(kinds),
                                       f"{field} must be one of {', '.join(kinds)}; "
                                       f"got {kind!r}")
        if self.compensation_kind != "none":
            check_compensator(self.compensation_kind, self.compensation, h=self.design.h,
                              arm_length=self.input_length)

    @property
    def plant_model(self) -> PlantKind:
        """The plant (:data:`frictionlab.model.plants.PLANTS`) of ``plant_kind``."""
        return plant_model(self.plant_kind)

    @property
    def motor(self) -> bool:
        """True for a plant driven by a motor voltage (u in volts)."""
        return self.plant_kind != "thesis"

    @property
    def input_length(self) -> float:
        """The length L (m) with arm acceleration = (u - F)/L at rest (eq. 6's
        L_1 for the thesis plant); for a motor plant 1/B[3] of its
        linearisation at upright (V s^2/rad), the adaptive compensator's
        velocity predictor's gain (docs/model.md)."""
        if not self.motor:
            return self.plant.arm_length
        return 1.0 / float(linearization(self.plant)[1][3, 0])

    def plant_row(self) -> Any:
        """The float row the compiled plant reads: ``plant.*`` with the actuator's
        ``actuator.*`` (:mod:`frictionlab.model.actuator`); a motor plant's
        :meth:`~frictionlab.model.plants.furuta_dc.FurutaDCParams.record`."""
        if self.motor:
            return self.plant.record()
        return self.plant.record(self.actuator.record())

    @property
    def u_limit(self) -> float:
        """The bound on every controller command (units of u): ``controller.u_max``
        within the DAC's range (``rig.u_max``, the harder bound the loop applies to
        u_DA as well; for a motor plant also ``plant.voltage_limit``)."""
        # a motor plant's: its amplifier's voltage limit, within the DAC's range too
        dac = min(self.plant.voltage_limit, self.rig.u_max) if self.motor else self.rig.u_max
        return dac if self.controller.u_max is None else min(self.controller.u_max, dac)

    @property
    def sensor_step(self) -> float:
        """The raw grid of the rig's converters with ``sim.quantization`` = 1 (and of
        the emulated rig): the thesis rig's 12 bits (App. B), a motor rig's pendulum
        encoder, one count of ``plant.pendulum_counts`` per turn
        (:func:`frictionlab.model.sensor.encoder_step`)."""
        if self.motor:
            return encoder_step(self.plant.pendulum_counts, self.rig.theta_scale)
        return ADC_STEP

    @property
    def substeps(self) -> int:
        """Arm/friction substeps per sampling period: ``sim.substeps``, or the
        plant's default for its friction model (``PlantKind.substeps``: the
        cheapest counts that keep the limit-cycle features within 0.3 % of a
        run with 20 times as many, docs/model.md "Integration";
        :data:`frictionlab.model.plants.thesis.SUBSTEPS`,
        :data:`frictionlab.model.plants.furuta_dc.SUBSTEPS`)."""
        if self.sim.substeps is not None:
            return self.sim.substeps
        return self.plant_model.substeps[self.friction_kind]

    @property
    def pendulum_ratio(self) -> int:
        """Arm substeps per pendulum step: ``substeps / sim.pendulum_steps``,
        rounded up (at least 1)."""
        return max(1, -(-self.substeps // self.sim.pendulum_steps))

    def get(self, key: str) -> Any:
        section, field = _split(key, self.plant_kind)
        return getattr(getattr(self, section), field)

    def with_values(self, values: Mapping[str, Any]) -> Config:
        """A copy with ``{key: value}`` applied (validated)."""
        return _apply(self, list(values.items()))

    def as_flat_dict(self) -> dict[str, Any]:
        """All keys and their values (for logs and sidecars)."""
        out: dict[str, Any] = {"friction_kind": self.friction_kind,
                               "compensation_kind": self.compensation_kind}
        if self.plant_kind != "thesis":
            out["plant_kind"] = self.plant_kind
        for section in _SECTIONS:
            obj = getattr(self, section)
            for f in dataclasses.fields(obj):
                if "doc" in f.metadata and f.name not in _NOT_IN_SECTION.get(section, ()):
                    out[f"{section}.{f.name}"] = getattr(obj, f.name)
        return out


_SECTIONS = ("plant", "design", "friction", "compensation", "sim", "rig", "swingup",
             "actuator", "controller")
_CLASSES = {"plant": PlantParams, "design": DesignSpec, "friction": FrictionParams,
            "compensation": FrictionParams, "sim": SimParams, "rig": RigScaling,
            "swingup": SwingUpParams, "actuator": ActuatorParams,
            "controller": ControllerLimits}


_NEG = {"stiction_negative", "coulomb_negative", "viscous_negative"}
#: The drift of the plant's levels (every model with a level).
_DRIFT = {"drift", "drift_start", "drift_time"}
#: Friction fields each *plant* model reads (LuGre's ``observer_gain`` is the k
#: of eq. (19) with e = -theta, docs/model.md "The observer gain k in the plant").
PLANT_FIELDS = {
    "none": set(),
    "viscous": {"viscous", "viscous_negative"},
    "coulomb": {"coulomb", "coulomb_negative", "hysteresis"},
    "classical": {"stiction", "coulomb", "zero_velocity_band"} | _NEG - {"viscous_negative"},
    "stribeck": {"stiction", "coulomb", "stribeck_velocity", "hysteresis",
                 "zero_velocity_band"} | _NEG - {"viscous_negative"},
    "lugre": {"stiction", "coulomb", "viscous", "stribeck_velocity", "sigma0", "sigma1",
              "sigma1_velocity", "observer_gain"} | _NEG,
}
for _kind in PLANT_FIELDS:
    if _kind != "none":
        PLANT_FIELDS[_kind] |= _DRIFT


def check_compensator(kind: str, params: FrictionParams, *, h: float | None = None,
                      arm_length: float | None = None) -> None:
    """:func:`frictionlab.model.controller.check_compensator`, its refusal a
    :class:`ConfigValueError` (a :class:`ConfigError` naming the key)."""
    try:
        _check_compensator(kind, params, h=h, arm_length=arm_length)
    except ParamError as exc:
        raise ConfigValueError(exc.field, exc.value, exc.allowed, str(exc)) from None


def inert_keys(cfg: Config, keys: Iterable[str]) -> list[str]:
    """Those of ``keys`` that the configured plant friction / compensator ignore."""
    out = []
    for key in keys:
        section, _, field = key.partition(".")
        if section == "friction" and field not in PLANT_FIELDS[cfg.friction_kind]:
            out.append(key)
        elif section == "compensation" and field not in COMPENSATOR_FIELDS[
                cfg.compensation_kind]:
            out.append(key)
    return out


#: Fields of :class:`FrictionParams` that only one of its two sections reads, so the
#: other section has no such key: the drift is the plant's (``friction.drift*``), the
#: adaptation law the compensator's (``compensation.adaptation_*``).
_NOT_IN_SECTION = {
    "friction": frozenset(f.name for f in dataclasses.fields(FrictionParams)
                          if f.name.startswith("adaptation_")),
    "compensation": frozenset(_DRIFT),
}


def _class(section: str, plant: str = "thesis") -> type:
    """The parameter class of a section (``plant``: that of the plant ``plant``)."""
    if section == "plant":
        return plant_model(plant).params
    return _CLASSES[section]


@functools.cache
def _key_tuple(plant: str = "thesis") -> tuple[str, ...]:
    keys = []
    for section in _SECTIONS:
        for f in dataclasses.fields(_class(section, plant)):
            if "doc" in f.metadata and f.name not in _NOT_IN_SECTION.get(section, ()):
                keys.append(f"{section}.{f.name}")
    return tuple(keys)


@functools.cache
def _key_set(plant: str = "thesis") -> frozenset[str]:
    return frozenset(_key_tuple(plant))


def valid_keys(plant: str = "thesis") -> list[str]:
    """Every accepted ``section.field`` key with the plant ``plant`` (a
    ``--plant`` name: its ``plant.*`` keys)."""
    return list(_key_tuple(plant))


def key_metadata(key: str, plant: str = "thesis") -> Mapping[str, Any]:
    """The field metadata of a parameter key: ``doc``, ``unit``, the range
    (``lo``, ``hi``...), ``integer`` (:func:`frictionlab.model.params.param`).

    Raises
    ------
    UnknownKeyError
        ``key`` is not a parameter key (with the plant ``plant``).
    """
    section, field = _split(key, plant)
    return _class(section, plant).__dataclass_fields__[field].metadata


def describe_keys(plant: str = "thesis") -> list[tuple[str, str, str, str]]:
    """``(key, doc, unit, allowed range)`` of every parameter key, in
    ``frictionlab keys`` order, with the plant ``plant``.  For a motor plant
    the friction and compensation levels are in volts, the units of u: their
    acceleration units read as volts."""
    keys = _key_set(plant)
    motor = plant_model(plant) is not THESIS
    out = []
    for section in _SECTIONS:
        for name, doc, unit, rng in _class(section, plant).describe():
            if f"{section}.{name}" not in keys:
                continue
            if motor and section in ("friction", "compensation", "rig"):
                unit = _VOLT_UNITS.get((name, unit), _VOLT_UNITS.get(("", unit), unit))
            out.append((f"{section}.{name}", doc, unit, rng))
    return out


#: A friction field's unit for a motor plant, by (field, unit in the thesis's
#: units; field "" for any): levels in volts (docs/model.md).
_VOLT_UNITS = {
    ("", "m/s^2"): "V",
    ("", "m/s^2/(rad/s)"): "V/(rad/s)",
    ("sigma0", "1/s^2"): "V/rad",
    ("sigma1", "1/s"): "V/(rad/s)",
    # the adaptive law's gain: a level's rate per arm-velocity error, (V/s)/(rad/s)
    ("adaptation_gain", "m/(rad s^2)"): "V/rad",
    ("u_scale", "1/(m/s^2)"): "1/V",
}


def _split(key: str, plant: str = "thesis") -> tuple[str, str]:
    if not isinstance(key, str) or key not in _key_set(plant):
        where = f"(with --plant {plant}) " if plant != "thesis" else ""
        raise UnknownKeyError(str(key), where, plant=plant)
    section, field = key.split(".")
    return section, field


def _vector_length(key: str, plant: str = "thesis") -> int | None:
    """Length of a vector-valued key (``design.gains``), None for a number."""
    section, field = key.split(".")
    f = _class(section, plant).__dataclass_fields__.get(field)
    return None if f is None else f.metadata.get("length")


def _coerce(key: str, value: Any) -> Any:
    if _vector_length(key):
        # "l1,l2,l3,l4" on the command line; a TOML array or a sequence as it is
        # (the dataclass checks length and values)
        if not isinstance(value, str):
            return value
        text = value.strip().strip("[]()")
        if text.strip().lower() in ("none", "null", ""):
            return None
        parts = [p.strip() for p in text.split(",")]
        if any(p.lower() in ("none", "null", "") for p in parts):
            raise ConfigError(f"{key}: {value!r} is not a comma-separated list of numbers")
        return tuple(_coerce_number(key, p) for p in parts)
    return _coerce_number(key, value)


def _coerce_number(key: str, value: Any) -> Any:
    if isinstance(value, str):
        text = value.strip()
        if text.lower() in ("none", "null", ""):
            return None
        try:
            return float(text) if any(c in text.lower() for c in ".einf") else int(text)
        except ValueError:
            try:
                return float(text)
            except ValueError:
                raise ConfigError(f"{key}: {_short(value)} is not a number") from None
    if isinstance(value, bool) or not (value is None or isinstance(value, int | float)):
        raise ConfigError(f"{key}: {_short(repr(value))} is not a number")
    return value


def _apply(cfg: Config, items: list[tuple[str, Any]]) -> Config:
    changes: dict[str, dict[str, Any]] = {}
    for key, value in items:
        section, field = _split(key, cfg.plant_kind)
        changes.setdefault(section, {})[field] = _coerce(key, value)
    kwargs = {}
    for section, fields in changes.items():
        obj = getattr(cfg, section)
        try:
            new = dataclasses.replace(obj, **fields)
        except ParamError as exc:
            # the compensator's model is a FrictionParams too: name its own keys
            fix = ((lambda t: t.replace("friction.", "compensation."))
                   if section == "compensation" else (lambda t: t))
            raise ConfigValueError(fix(exc.field), exc.value, exc.allowed,
                                   fix(str(exc))) from None
        except ValueError as exc:
            msg = str(exc)
            if section == "compensation":
                msg = msg.replace("friction.", "compensation.")
            raise ConfigError(msg) from None
        kwargs[section] = new
    return dataclasses.replace(cfg, **kwargs)


def parse_assignment(text: str) -> tuple[str, str]:
    """Split ``KEY=VALUE`` (the ``--set`` syntax)."""
    if "=" not in text:
        raise ConfigError(f"expected KEY=VALUE, got {_short(text)}")
    key, value = text.split("=", 1)
    return key.strip(), value.strip()


#: Largest configuration file read (bytes); a parameter file is a few hundred.
MAX_CONFIG_BYTES = 1 << 20


def _toml_value(where: str, key: str, value: Any) -> Any:
    """A TOML value where a number belongs: a TOML integer or float, nothing else
    (a quoted "7.0" is a string, a typing mistake the file should not hide); for
    a vector key (``design.gains``) an array of such numbers."""
    n = _vector_length(key)
    if n:
        if not (isinstance(value, list) and len(value) == n and all(
                isinstance(v, int | float) and not isinstance(v, bool) for v in value)):
            raise ConfigError(f"{where}: {key} must be an array of {n} numbers, "
                              f"got {_short(repr(value))}")
        return value
    if isinstance(value, bool) or not isinstance(value, int | float):
        kind = ("a string" if isinstance(value, str) else "a boolean"
                if isinstance(value, bool) else "an array" if isinstance(value, list)
                else "a date/time" if isinstance(value, datetime.date | datetime.time)
                else type(value).__name__)
        shown = f" {_short(value)}" if isinstance(value, str) else ""
        raise ConfigError(f"{where}: {key} is {kind}{shown}; it must be a number "
                          "(write it without quotes)")
    return value


def load_toml(path: str | Path, plant: str = "thesis") -> list[tuple[str, Any]]:
    """Read ``[section] field = number`` (or dotted keys) from a TOML file
    (keys of the plant ``plant``, a ``--plant`` name).

    Raises
    ------
    ConfigError
        Unreadable or too large file, invalid TOML (including nesting too
        deep to parse), a key that is not ``section.field``, a value that is
        not a TOML number.
    """
    try:
        with open(path, "rb") as fh:
            raw = fh.read(MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"cannot read config file {path}: "
                          f"{exc.strerror or exc}") from None
    if len(raw) > MAX_CONFIG_BYTES:
        raise ConfigError(f"config file {path} is larger than {MAX_CONFIG_BYTES >> 20} MB; "
                          "it is not a parameter file")
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise ConfigError(f"config file {path} is not UTF-8 text ({exc.reason})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"config file {path} is not valid TOML: {exc}") from None
    except RecursionError:
        raise ConfigError(f"config file {path} is not valid TOML: nested too deeply") from None
    where = f"config file {path}"
    items: list[tuple[str, Any]] = []
    for section, table in data.items():
        if not isinstance(table, Mapping):
            raise ConfigError(f"{where}: {_short(section)} must be a table [{section}] of "
                              "field = number lines" if section in _SECTIONS else
                              f"{where}: " + str(UnknownKeyError(section)))
        for field, value in table.items():
            key = f"{section}.{field}"
            if isinstance(value, Mapping):
                raise UnknownKeyError(f"{key}.{next(iter(value), '')}", f"{where}: ")
            _split_in(where, key, plant)
            items.append((key, _toml_value(where, key, value)))
    return items


def _split_in(where: str, key: str, plant: str = "thesis") -> None:
    try:
        _split(key, plant)
    except UnknownKeyError as exc:
        raise UnknownKeyError(key, f"{where}: ", plant=plant) from exc


def build_config(
    design: str | None = "fast",
    friction: str = "classical",
    compensation: str = "none",
    config_file: str | Path | None = None,
    sets: Iterable[str | tuple[str, Any]] = (),
    plant: str = "thesis",
) -> Config:
    """Assemble a :class:`Config` the way the command line does.

    Parameters
    ----------
    design : {"fast", "slow"} or None
        Design preset (Sec. 2.4) applied before the file and the overrides.
    friction, compensation : str
        Plant friction model and compensator.
    config_file : path, optional
        TOML file with ``[plant]``, ``[design]``, ``[friction]``,
        ``[compensation]``, ``[sim]``, ``[rig]`` tables.
    sets : iterable of ``"KEY=VALUE"`` or ``(key, value)``
        Overrides, applied in order.
    plant : str
        The plant (:data:`PLANT_NAMES`): its preset's parameters, and for a
        motor plant its friction levels (volts) as the ``friction.*`` defaults
        and the compensators' defaults scaled to them
        (:func:`motor_friction_defaults`), and a motor rig's ``rig.*``
        (:func:`frictionlab.model.rig.motor_rig`: u in volts, encoders).
    """
    try:
        spec = preset(design) if design else DesignSpec()
        kind = plant_model(plant)
        fr = FrictionParams.defaults(friction, "plant")
        comp = FrictionParams.defaults(compensation if compensation != "none" else "lugre",
                                       "compensation")
        params = kind.params()
        if kind is not THESIS:
            params = dc_preset(plant)
            fr, comp = motor_friction_defaults(plant, fr, comp)
            # the Sec. 2.4 pattern on this plant (omega0 and the pendulum's
            # frequencies scaled to its unstable rate): the design.* defaults
            spec = dc_spec(design or "fast", params)
        # a motor rig's converters: u in volts, encoders (model.rig.motor_rig)
        rig = motor_rig(params.voltage_limit) if kind is not THESIS else RigScaling()
        # a motor plant's swing-up defaults (its friction margin in volts, its arm travel)
        swing = (SwingUpParams() if kind is THESIS else SwingUpParams(
            **{k.split(".", 1)[1]: v for k, v in PRESET_SWINGUP.items()}))
        cfg = Config(plant=params, design=spec, friction_kind=friction, friction=fr,
                     compensation_kind=compensation, compensation=comp, plant_kind=plant,
                     rig=rig, swingup=swing)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    items: list[tuple[str, Any]] = []
    if config_file is not None:
        items.extend(load_toml(config_file, plant))
    for s in sets:
        items.append(parse_assignment(s) if isinstance(s, str) else tuple(s))
    for key, _ in items:
        _split(key, plant)
    return _apply(cfg, items) if items else cfg


#: A motor plant's LuGre compensator (eq. 19): the share of a friction level
#: error its innovation corrects per tick through the bristle (lambda h; 1:
#: the whole error in one tick, the fastest without overshoot) and the share
#: the damping term sigma_1 kicks in at once (kappa; small, as it would
#: overshoot at 1).  :func:`motor_friction_defaults` turns them into
#: ``compensation.observer_gain`` and ``compensation.sigma1``.
MOTOR_CORRECTION = 1.0
MOTOR_KICK = 0.1

#: The friction fields in units of u (levels, and coefficients per rad or
#: rad/s): scaled with the level from the thesis plant to a motor plant.
_LEVEL_FIELDS = ("stiction", "coulomb", "viscous", "sigma0", "sigma1", "stiction_negative",
                 "coulomb_negative", "viscous_negative", "adaptation_min", "adaptation_max")


def motor_friction_defaults(plant: str, friction: FrictionParams,
                            compensation: FrictionParams) -> tuple[FrictionParams,
                                                                   FrictionParams]:
    """The ``friction.*`` and ``compensation.*`` defaults of a motor plant.

    The plant's friction: its preset's levels in volts
    (:data:`frictionlab.model.plants.furuta_dc.PRESET_FRICTION`), the LuGre
    bristle's sigma_0 and sigma_1 scaled by r = the preset's F_C over the
    thesis plant's (so the bristle deflects as many radians).  The
    compensators': the thesis's Sec. 6 settings with every level-like field
    (:data:`_LEVEL_FIELDS`) scaled by the same r, and the adaptive law's gain
    by the ratio of the input lengths (:attr:`Config.input_length`), so its
    stability margin (gamma h^2/L) is the thesis's.  Velocities (v_S,
    epsilon, the bands) are unchanged.

    The LuGre observer's gain k and damping sigma_1 (eq. 19; the ``lugre``
    and ``adaptive`` compensators) are set for the motor plant's
    innovation, the measured arm rate minus the model's one-tick
    prediction (:func:`frictionlab.model.controller.arm_prediction`), which
    is -h (F - F_hat)/L for a friction error: k = lambda L / (sigma_0 h)
    corrects a level error at the rate lambda = :data:`MOTOR_CORRECTION` / h
    (all of it in one tick), and sigma_1 = kappa sigma_0 / lambda makes the
    one-tick kick of the damping term, sigma_1 k h / L, the fraction kappa =
    :data:`MOTOR_KICK` of the error (kappa near 1 flips the error's sign each
    tick).  h is the design's default 5 ms (docs/model.md, "The controller
    on a motor plant").
    """
    pf = PRESET_FRICTION[plant]
    r = pf["friction.coulomb"] / FrictionParams().coulomb

    def scaled(p: FrictionParams, **fixed: float) -> FrictionParams:
        vals = {f: float(f"{getattr(p, f) * r:.12g}") for f in _LEVEL_FIELDS
                if getattr(p, f) is not None}
        vals.update(fixed)
        return dataclasses.replace(p, **vals)

    fixed = {k.split(".", 1)[1]: v for k, v in pf.items()}
    length = 1.0 / float(linearization(dc_preset(plant))[1][3, 0])
    comp = scaled(compensation)
    gain = compensation.adaptation_gain * length / PlantParams().arm_length
    h = DesignSpec().h
    rate = MOTOR_CORRECTION / h
    k = rate * length / (comp.sigma0 * h)
    sigma1 = MOTOR_KICK * comp.sigma0 / rate
    comp = dataclasses.replace(comp, adaptation_gain=float(f"{gain:.12g}"),
                               observer_gain=float(f"{k:.4g}"),
                               sigma1=float(f"{sigma1:.4g}"))
    return scaled(friction, **fixed), comp

