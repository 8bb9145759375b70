"""The loop's changeable parameters as one immutable, validated snapshot.

The operator changes the design (Sec. 2.4's Fast/Slow or any ``design.*``
value), the compensation (on/off, the "Friction Type" of Sec. 7.1 and its
"Friction Model" parameters) while the loop runs.  A change is validated
and turned into a new :class:`ControlParams` *outside* the loop (designing
the gains takes far longer than a tick); the loop then swaps the whole
snapshot in between two ticks, so a tick never sees half a change.

Change requests are dicts (the console's and the mailbox's format):

``"design"``
    ``"fast"`` / ``"slow"`` (preset), a :class:`~frictionlab.design.DesignSpec`,
    or a dict of ``design.*`` fields (``{"omega1": 5.0}``) applied to the
    current spec.  ``h`` cannot change while the loop exists.
``"compensation"``
    ``"none"`` (off) or ``"coulomb"``/``"classical"``/``"lugre"`` (selects
    the model and turns compensation on).
``"compensation_enabled"``
    ``True``/``False``: the thesis's Compensation button (keeps the model).
``"compensation_params"``
    Dict of friction fields for the selected model (``{"sigma0": 250}``;
    a ``compensation.`` prefix is accepted).  Each model keeps its own
    parameters, so switching models and back does not lose edits.
``"set"``
    Dict of ``design.*`` / ``compensation.*`` keys as for ``--set``.
``"error_signal"``
    The LuGre observer's error signal (:data:`frictionlab.controller.ERROR_SIGNALS`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..config import Config, ConfigError
from ..controller import DEFAULT_ERROR_SIGNAL, ERROR_SIGNALS, Controller
from ..design import PRESETS, Design, DesignSpec, design, preset
from ..friction import FrictionParams

__all__ = ["CHANGE_KEYS", "COMPENSATOR_MODELS", "ControlParams"]

#: Friction models the compensator can use (the thesis's "Friction Type").
COMPENSATOR_MODELS = ("coulomb", "classical", "lugre")
CHANGE_KEYS = ("design", "compensation", "compensation_enabled", "compensation_params", "set",
               "error_signal")
_FRICTION_FIELDS = tuple(f.name for f in dataclasses.fields(FrictionParams)
                         if "doc" in f.metadata)
_DESIGN_FIELDS = tuple(f.name for f in dataclasses.fields(DesignSpec) if "doc" in f.metadata)


@dataclass(frozen=True, eq=False)
class ControlParams:
    """Everything the tick needs from the operator, packed for the compiled step.

    Attributes
    ----------
    cfg : Config
        The run's configuration with the current design and compensation.
    comp_enabled : bool
        Compensation on.
    comp_kind : str
        Selected compensator model (kept while compensation is off).
    comp_params : dict
        Parameters of every compensator model.
    error_signal : str
        LuGre observer error signal.
    design : Design
        Gains L, K of the current spec.
    controller : Controller
    gp, cp : ndarray
        :meth:`Controller.pack` output (read-only).
    """

    cfg: Config
    comp_enabled: bool
    comp_kind: str
    comp_params: dict = field(repr=False)
    error_signal: str
    design: Design = field(repr=False)
    controller: Controller = field(repr=False)
    gp: np.ndarray = field(repr=False)
    cp: np.ndarray = field(repr=False)

    @classmethod
    def from_config(cls, cfg: Config, error_signal: str = DEFAULT_ERROR_SIGNAL
                    ) -> ControlParams:
        """The initial snapshot of a run (``cfg.compensation_kind`` none: off, LuGre selected)."""
        enabled = cfg.compensation_kind != "none"
        kind = cfg.compensation_kind if enabled else "lugre"
        params = {k: FrictionParams.defaults(k, "compensation") for k in COMPENSATOR_MODELS}
        params[kind] = cfg.compensation
        return cls._build(cfg, cfg.design, enabled, kind, params, error_signal)

    @classmethod
    def _build(cls, cfg, spec, enabled, kind, params, error_signal) -> ControlParams:
        cfg = dataclasses.replace(cfg, design=spec,
                                  compensation_kind=kind if enabled else "none",
                                  compensation=params[kind])
        d = design(spec, cfg.plant)
        ctrl = Controller(d, kind if enabled else "none", params[kind],
                          error_signal=error_signal)
        gp, cp = ctrl.pack()
        gp.flags.writeable = False
        cp.flags.writeable = False
        return cls(cfg, enabled, kind, dict(params), error_signal, d, ctrl, gp, cp)

    def apply(self, changes: dict) -> ControlParams:
        """A new snapshot with ``changes`` applied (see the module docstring).

        Raises
        ------
        ValueError
            (:class:`~frictionlab.config.ConfigError`) naming the bad key or value.
        """
        if not isinstance(changes, dict):
            raise ConfigError(f"changes must be a dict, got {type(changes).__name__}")
        unknown = sorted(set(changes) - set(CHANGE_KEYS))
        if unknown:
            raise ConfigError(f"unknown change {unknown[0]!r}; known: {', '.join(CHANGE_KEYS)}")
        spec = self.cfg.design
        enabled, kind = self.comp_enabled, self.comp_kind
        params = dict(self.comp_params)
        error_signal = self.error_signal

        if "design" in changes:
            spec = _design_spec(changes["design"], spec)
        if "compensation" in changes:
            c = changes["compensation"]
            if c == "none":
                enabled = False
            elif c in COMPENSATOR_MODELS:
                kind, enabled = c, True
            else:
                raise ConfigError(f"compensation must be one of none, "
                                  f"{', '.join(COMPENSATOR_MODELS)}; got {c!r}")
        if "compensation_enabled" in changes:
            e = changes["compensation_enabled"]
            if not isinstance(e, bool):
                raise ConfigError(f"compensation_enabled must be true or false, got {e!r}")
            enabled = e
        if "set" in changes:
            items = changes["set"]
            if not isinstance(items, dict):
                raise ConfigError("set must be a dict of KEY: VALUE")
            for key in items:
                if not (str(key).startswith("design.") or str(key).startswith("compensation.")):
                    raise ConfigError(f"{key}: only design.* and compensation.* keys can change "
                                      "while the controller runs")
            tmp = dataclasses.replace(self.cfg, design=spec, compensation=params[kind])
            tmp = tmp.with_values(items)
            spec = tmp.design
            params[kind] = tmp.compensation
        if "compensation_params" in changes:
            fields = changes["compensation_params"]
            if not isinstance(fields, dict):
                raise ConfigError("compensation_params must be a dict of field: value")
            clean = {}
            for key, value in fields.items():
                name = str(key).removeprefix("compensation.")
                if name not in _FRICTION_FIELDS:
                    raise ConfigError(f"unknown compensation parameter {key!r}; known: "
                                      f"{', '.join(_FRICTION_FIELDS)}")
                clean[name] = value
            try:
                params[kind] = dataclasses.replace(params[kind], **clean)
            except (TypeError, ValueError) as exc:
                raise ConfigError(str(exc).replace("friction.", "compensation.")) from None
        if "error_signal" in changes:
            error_signal = changes["error_signal"]
            if error_signal not in ERROR_SIGNALS:
                raise ConfigError(f"error_signal must be one of {', '.join(ERROR_SIGNALS)}; "
                                  f"got {error_signal!r}")
        if spec.h != self.cfg.design.h:
            raise ConfigError(f"design.h cannot change while the controller exists "
                              f"(it is {self.cfg.design.h} s)")
        return self._build(self.cfg, spec, enabled, kind, params, error_signal)

    def warm(self) -> None:
        """Do now, off the loop, the one-time work of the first change of each kind.

        Designs both presets (:func:`~frictionlab.design.design` caches its
        results) and builds a controller for every compensator model, which
        imports the compensation code on first use.  Done in a request
        thread while the loop runs, this held the GIL for up to 30 ms and
        stalled the loop; afterwards a preset or a model switch costs well
        under 1 ms and a new custom design about 1 ms.
        """
        for spec in PRESETS.values():
            design(spec, self.cfg.plant)
        for kind in COMPENSATOR_MODELS:
            self.apply({"compensation": kind})

    @property
    def preset(self) -> str | None:
        """``fast``/``slow`` if the current spec is that preset, else None."""
        for name, spec in PRESETS.items():
            if spec == self.cfg.design:
                return name
        return None

    def describe(self) -> dict:
        """JSON-ready summary: design (spec, L, K) and compensation."""
        return {
            "design": {"preset": self.preset, "spec": dataclasses.asdict(self.cfg.design),
                       "L": [float(v) for v in self.design.L],
                       "K": [float(v) for v in self.design.K]},
            "compensation": {"enabled": self.comp_enabled, "kind": self.comp_kind,
                             "params": dataclasses.asdict(self.comp_params[self.comp_kind]),
                             "error_signal": self.error_signal},
        }


def _design_spec(value, current: DesignSpec) -> DesignSpec:
    if isinstance(value, DesignSpec):
        return value
    if isinstance(value, str):
        try:
            return preset(value)
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
    if isinstance(value, dict):
        clean = {}
        for key, v in value.items():
            name = str(key).removeprefix("design.")
            if name not in _DESIGN_FIELDS:
                raise ConfigError(f"unknown design field {key!r}; known: "
                                  f"{', '.join(_DESIGN_FIELDS)}")
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise ConfigError(f"design.{name}: {v!r} is not a number")
            clean[name] = v
        try:
            return dataclasses.replace(current, **clean)
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
    raise ConfigError(f"design must be 'fast', 'slow', a DesignSpec or a dict; got {value!r}")
