"""Request bodies of the operator console, validated with pydantic.

Every number the page sends is checked twice: by the page itself (with the
ranges :func:`schema` publishes) and here, whatever the page sent.  The
ranges are not repeated: each field is checked by constructing the
project's own validated parameter dataclass with that one value
(:class:`~frictionlab.model.design.DesignSpec` for the State Feedback and Kalman
Filter panels, :class:`~frictionlab.model.friction.FrictionParams` for the
Friction Model panel), whose ``ValueError`` names the field and its allowed
range.  :func:`field_errors` turns any validation failure into the
console's error list ``[{"field": ..., "message": ...}]`` so that the page
can show each message beside its field.
"""

from __future__ import annotations

import dataclasses
import math
import re
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator
from pydantic_core import PydanticCustomError

from ..config import Config, build_config, describe_keys, motor_friction_defaults
from ..model.controller import COMPENSATOR_FIELDS as _MODEL_FIELDS
from ..model.controller import COMPENSATORS, ERROR_SIGNALS
from ..model.design import DesignSpec
from ..model.friction import FrictionParams
from ..model.params import ParamError
from ..realtime.params import plant_presets

__all__ = [
    "COMPENSATOR_FIELDS",
    "FEEDBACK_FIELDS",
    "KICK_RANGE",
    "NAME_PATTERN",
    "OBSERVER_FIELDS",
    "CompensationRequest",
    "DesignRequest",
    "FrictionModelRequest",
    "PushRequest",
    "RecordNameRequest",
    "field_errors",
    "field_units",
    "request_field",
    "schema",
]

#: State Feedback panel (Sec. 2.2): the design's own omega_0 and the two pole pairs.
FEEDBACK_FIELDS = ("omega0", "omega1", "zeta1", "omega2", "zeta2")
#: Kalman Filter panel (Sec. 2.3): the observer pole pairs.
OBSERVER_FIELDS = ("observer_omega1", "observer_zeta1", "observer_omega2", "observer_zeta2")
#: The panel's order of the compensator parameters (Sec. 6.1-6.3).
_PANEL_ORDER = ("stiction", "coulomb", "viscous", "stribeck_velocity", "sigma0", "sigma1",
                "observer_gain", "hysteresis",
                # the adaptive law's (after the LuGre observer's: its starting levels)
                "adaptation_gain", "adaptation_bandwidth", "adaptation_deadband",
                "adaptation_distance", "adaptation_max_innovation", "adaptation_min",
                "adaptation_max")
#: The fields each compensator reads (:data:`~frictionlab.model.controller.COMPENSATOR_FIELDS`)
#: that the panel shows (the symmetric model: no ``*_negative`` levels).
COMPENSATOR_FIELDS = {
    kind: tuple(f for f in _PANEL_ORDER if f in _MODEL_FIELDS[kind]) for kind in COMPENSATORS}
#: Allowed push (rad/s added to the pendulum's angular velocity).
KICK_RANGE = (-3.0, 3.0)
#: Recording names: no path, no extension (``.dat`` and ``.csv`` are added).
NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$"

_ALL_COMP_FIELDS = tuple(dict.fromkeys(f for fs in COMPENSATOR_FIELDS.values() for f in fs))

Number = Annotated[float, Field(strict=True, allow_inf_nan=False)]


def _check(cls, name: str, value: float, prefix: str) -> float:
    """Construct ``cls`` with one field set; re-raise its ValueError with ``prefix``.

    A value out of range is a ``param_range`` error whose context keeps the value and
    the range apart (:func:`field_errors` then names the plant's unit, V or m/s^2)."""
    try:
        cls(**{name: value})
    except ParamError as exc:
        # named as the request names it: the error's field (design.omega0,
        # friction.coulomb) becomes the panel's key (compensation.coulomb)
        msg = str(exc)
        if msg == str(ParamError(exc.field, exc.value, exc.allowed)):
            shown = str(ParamError("", exc.value, exc.allowed)).split(" = ", 1)[1]
            value_text, allowed = shown.split(" is out of range; allowed ", 1)
            raise PydanticCustomError(
                "param_range", "{key} = {value} is out of range; allowed {allowed}",
                {"key": prefix + name, "value": value_text, "allowed": allowed}) from None
        if msg.startswith(exc.field):
            msg = prefix + name + msg[len(exc.field):]
        raise ValueError(msg) from None
    return value


class _Request(BaseModel):
    model_config = ConfigDict(extra="forbid")


#: ``"confirm": true`` applies a change the model's check refuses (HTTP 422 with
#: ``confirm_required``); the page sends it after asking the operator.
Confirm = Annotated[bool, Field(strict=True)]


class DesignRequest(_Request):
    """State Feedback / Kalman Filter panels: a preset, or new values of some fields.

    ``h`` is not here: the sampling period is fixed while the controller
    exists.  Fields left out keep their current values.  ``confirm``: apply
    even if the model predicts the loop unstable or u saturating.
    """

    confirm: Confirm = False
    preset: Literal["fast", "slow"] | None = None
    omega0: Number | None = None
    omega1: Number | None = None
    zeta1: Number | None = None
    omega2: Number | None = None
    zeta2: Number | None = None
    observer_omega1: Number | None = None
    observer_zeta1: Number | None = None
    observer_omega2: Number | None = None
    observer_zeta2: Number | None = None

    @field_validator("preset", *FEEDBACK_FIELDS, *OBSERVER_FIELDS, mode="before")
    @classmethod
    def _not_null(cls, v, info):
        # a field sent as null is refused at that field (left out, it keeps its value)
        if v is None:
            raise ValueError(f"{info.field_name} must not be null (leave it out to keep it)")
        return v

    @field_validator(*FEEDBACK_FIELDS, *OBSERVER_FIELDS)
    @classmethod
    def _in_range(cls, v, info):
        if info.data.get("preset") is not None:  # located at the field, not the body
            raise ValueError("give either a preset or field values, not both")
        return _check(DesignSpec, info.field_name, v, "design.")

    @model_validator(mode="after")
    def _one_kind(self):
        fields = self.fields()
        if self.preset is not None and fields:
            raise ValueError("give either a preset or field values, not both")
        if self.preset is None and not fields:
            raise ValueError("nothing to change: give a preset or at least one field")
        return self

    def fields(self) -> dict[str, float]:
        return {k: v for k, v in self.model_dump(exclude={"preset", "confirm"}).items()
                if v is not None}

    def changes(self) -> dict:
        """The controller's mailbox format (:mod:`frictionlab.realtime.params`)."""
        return {"design": self.preset if self.preset is not None else self.fields()}


class FrictionModelRequest(_Request):
    """Friction Model panel: new values of some compensator parameters.

    A field of its own for each parameter, so that a refusal is located at
    ``params.<name>`` (the page shows it beside that field).  A field left
    out keeps its value; ``null`` is refused like any other non-number.
    """

    stiction: Number | None = None
    coulomb: Number | None = None
    viscous: Number | None = None
    stribeck_velocity: Number | None = None
    sigma0: Number | None = None
    sigma1: Number | None = None
    observer_gain: Number | None = None
    hysteresis: Number | None = None
    adaptation_gain: Number | None = None
    adaptation_bandwidth: Number | None = None
    adaptation_deadband: Number | None = None
    adaptation_distance: Number | None = None
    adaptation_max_innovation: Number | None = None
    adaptation_min: Number | None = None
    adaptation_max: Number | None = None

    @field_validator(*_ALL_COMP_FIELDS)
    @classmethod
    def _in_range(cls, v, info):
        if v is None:  # only an explicit null reaches here (defaults are not validated)
            raise ValueError(f"{info.field_name} must be a number")
        return _check(FrictionParams, info.field_name, v, "compensation.")

    def values(self) -> dict[str, float]:
        """The parameters given, by name."""
        return {k: getattr(self, k) for k in type(self).model_fields
                if k in self.model_fields_set}


class CompensationRequest(_Request):
    """Compensation button, Friction Type and Friction Model panel (Sec. 7.1).

    ``confirm``: apply even if the model predicts the loop unstable or u
    saturating.
    """

    confirm: Confirm = False
    enabled: bool | None = Field(default=None, strict=True)
    kind: Literal[COMPENSATORS] | None = None  # the same as Literal["coulomb", ...]
    params: FrictionModelRequest | None = None
    error_signal: Literal[ERROR_SIGNALS] | None = None  # type: ignore[valid-type]

    @field_validator("enabled", "kind", "params", "error_signal", mode="before")
    @classmethod
    def _not_null(cls, v, info):
        if v is None:  # refused at its field; left out, it keeps its value
            raise ValueError(f"{info.field_name} must not be null (leave it out to keep it)")
        return v

    @model_validator(mode="after")
    def _something(self):
        if all(getattr(self, k) is None for k in ("enabled", "kind", "params", "error_signal")):
            raise ValueError("nothing to change")
        return self

    def changes(self) -> dict:
        """The controller's mailbox format: the kind first, then on/off, then values."""
        out: dict[str, Any] = {}
        if self.kind is not None:
            out["compensation"] = self.kind
            if self.enabled is None:
                out["compensation_enabled"] = True
        if self.enabled is not None:
            out["compensation_enabled"] = self.enabled
        if self.params is not None and self.params.values():
            out["compensation_params"] = self.params.values()
        if self.error_signal is not None:
            out["error_signal"] = self.error_signal
        return out


class PushRequest(_Request):
    """The push button: ``kick`` rad/s added to the pendulum's angular velocity."""

    kick: Number = 0.3

    @field_validator("kick")
    @classmethod
    def _kick_range(cls, v):
        lo, hi = KICK_RANGE
        if not lo <= v <= hi or v == 0.0:
            raise ValueError(f"kick = {v:g} rad/s is out of range; allowed [{lo:g}, {hi:g}], "
                             "not 0")
        return v


#: Experiments the console's Experiments panel runs (``identify experiment`` names).
EXPERIMENT_NAMES = ("stiction", "stribeck", "free-oscillation", "control-scaling",
                    "velocity-scale", "angle-scales")


class ExperimentRequest(_Request):
    """The Experiments panel: run an identification experiment on the connected rig.

    ``options`` are the experiment's own (``step``, ``hold``, ``references``,
    ... as in ``identify experiment``; checked by the experiment), ``limits``
    the fields of :class:`frictionlab.realtime.experiment.Limits`
    (``max_speed``, ``max_travel``, ``max_u_da``).  The motor moves the arm,
    so the request is refused (422, ``confirm_required``) unless ``confirm``.
    """

    name: Literal["stiction", "stribeck", "free-oscillation", "control-scaling",
                  "velocity-scale", "angle-scales"]
    options: dict[str, Number | list[Number]] = Field(default_factory=dict, max_length=20)
    limits: dict[Literal["max_speed", "max_travel", "max_u_da"], Number] = Field(
        default_factory=dict)
    confirm: Confirm = False


class RecordNameRequest(_Request):
    """The ``out>`` prompt: the recording's file name, without extension."""

    name: str = Field(max_length=200)

    @field_validator("name")
    @classmethod
    def _clean_name(cls, v: str):
        # spaces around the name are the prompt's; a newline or any other character is
        # refused (a full match: ``$`` alone would match before a final newline)
        v = re.sub(r"\.(dat|csv)\Z", "", v.strip(" "))
        if not re.fullmatch(NAME_PATTERN, v):
            raise ValueError("use 1-64 letters, digits, '_' or '-' (no extension: .dat and "
                             ".csv are added)")
        return v


# --- errors -----------------------------------------------------------------------------

_OBJECT_TYPES = ("model_attributes_type", "model_type", "dict_type")
#: Request fields of the controller's change keys that are not ``design.*`` /
#: ``compensation.*`` (see :mod:`frictionlab.realtime.params`).
_CHANGE_FIELDS = {"design": "preset", "compensation": "kind",
                  "compensation_enabled": "enabled", "compensation_params": "params",
                  "error_signal": "error_signal"}


def field_units(cfg: Config) -> dict[str, str]:
    """The unit of each numeric request field on the plant of ``cfg`` (the panels' units,
    :func:`schema`): ``omega1`` rad/s, ``params.coulomb`` V on a motor plant."""
    sch = schema(cfg)
    units = {f["name"]: f["unit"] for f in (*sch["feedback"], *sch["observer"])}
    for fields in sch["compensation"]["fields"].values():
        units.update({"params." + f["name"]: f["unit"] for f in fields})
    units["kick"] = "rad/s"
    return units


def request_field(key: str) -> str:
    """The request field of a controller change key: ``design.zeta1`` -> ``zeta1``,
    ``compensation.sigma0`` -> ``params.sigma0``, ``compensation`` -> ``kind``."""
    if key.startswith("design."):
        return key.removeprefix("design.")
    if key.startswith("compensation."):
        return "params." + key.removeprefix("compensation.")
    return _CHANGE_FIELDS.get(key, key)


def field_errors(exc: ValidationError | Any, units: dict[str, str] | None = None) -> list[dict]:
    """``[{"field", "message"}]`` from a pydantic error list (``exc.errors()``); a value
    out of range is shown with ``units[field]`` (the run's plant's: :func:`field_units`)."""
    errors = exc.errors() if hasattr(exc, "errors") else exc
    out = []
    for err in errors:
        loc = [str(p) for p in err.get("loc", ()) if p not in ("body",)]
        field = ".".join(loc) if loc else None
        kind = err.get("type", "")
        name = loc[-1] if loc else "value"
        if kind == "param_range":
            ctx = err.get("ctx") or {}
            unit = (units or {}).get(field or "", "")
            unit = "" if unit in ("", "1") else " " + unit
            message = (f"{ctx.get('key', name)} = {ctx.get('value')}{unit} is out of range; "
                       f"allowed {ctx.get('allowed')}{unit}")
        elif kind == "value_error":
            ctx = err.get("ctx") or {}
            message = str(ctx.get("error", err.get("msg", "")))
        elif kind in ("float_type", "float_parsing", "int_type", "int_parsing"):
            message = f"{name} must be a number"
        elif kind == "finite_number":
            message = f"{name} must be a finite number"
        elif kind == "bool_type":
            message = f"{name} must be true or false"
        elif kind == "extra_forbidden":
            message = f"unknown field {name!r}"
        elif kind == "missing":
            message = f"{name} is required"
        elif kind == "json_invalid" or (not loc and kind in _OBJECT_TYPES):
            message = "the request body must be a JSON object"
            field = None
        elif kind in _OBJECT_TYPES:  # a nested object: the friction model's parameters
            message = f"{name} must be a JSON object"
        else:
            message = f"{name}: {err.get('msg', 'invalid')}"
        out.append({"field": field, "message": message})
    return out


# --- schema for the page ----------------------------------------------------------------


def _field_info(cls, name: str) -> dict:
    f = {fl.name: fl for fl in dataclasses.fields(cls)}[name]
    m = f.metadata

    def num(x):
        return None if x is None or (isinstance(x, float) and math.isinf(x)) else x

    return {"name": name, "doc": m["doc"], "unit": m["unit"], "lo": num(m["lo"]),
            "hi": num(m["hi"]), "lo_open": m["lo_open"], "hi_open": m["hi_open"]}


def schema(cfg: Config | None = None) -> dict:
    """Fields, units and allowed ranges the page validates against (``GET /api/schema``),
    for the run's plant (``cfg``; default the thesis's): ``plant`` its ``--plant`` name,
    ``u_unit`` the unit of u and of the friction levels (``m/s^2``, or ``V`` for a motor
    plant, whose compensator fields' units and defaults are then in volts), its
    ``presets``."""
    cfg = cfg or build_config()
    units = {key.removeprefix("compensation."): unit
             for key, _doc, unit, _rng in describe_keys(cfg.plant_kind)
             if key.startswith("compensation.")}
    comp = {k: FrictionParams.defaults(k, "compensation") for k in COMPENSATOR_FIELDS}
    if cfg.motor:  # the thesis's settings scaled to the plant's levels (config)
        comp = {k: motor_friction_defaults(cfg.plant_kind, p, p)[1] for k, p in comp.items()}

    def field_info(name: str) -> dict:
        return {**_field_info(FrictionParams, name), "unit": units.get(name, "")}

    return {
        "plant": cfg.plant_kind,
        "u_unit": cfg.plant_model.u_unit,
        "feedback": [_field_info(DesignSpec, n) for n in FEEDBACK_FIELDS],
        "observer": [_field_info(DesignSpec, n) for n in OBSERVER_FIELDS],
        "presets": {k: dataclasses.asdict(v) for k, v in plant_presets(cfg).items()},
        "compensation": {
            "kinds": list(COMPENSATOR_FIELDS),
            "fields": {k: [field_info(n) for n in v] for k, v in COMPENSATOR_FIELDS.items()},
            "defaults": {k: dataclasses.asdict(p) for k, p in comp.items()},
            "error_signals": list(ERROR_SIGNALS),
        },
        "push": {"lo": KICK_RANGE[0], "hi": KICK_RANGE[1], "default": 0.3},
        "record": {"pattern": NAME_PATTERN},
    }
