"""The loop's changeable parameters as one immutable, validated snapshot.

The operator changes the design (Sec. 2.4's Fast/Slow or any ``design.*``
value), the compensation (on/off, the "Friction Type" of Sec. 7.1 and its
"Friction Model" parameters) while the loop runs.  A change is validated
and turned into a new :class:`ControlParams` *outside* the loop (designing
the gains takes far longer than a tick); the loop then swaps the whole
snapshot in between two ticks, so a tick never sees half a change.

Change requests are dicts (the console's and the mailbox's format):

``"design"``
    ``"fast"`` / ``"slow"`` (preset), a :class:`~frictionlab.model.design.DesignSpec`,
    or a dict of ``design.*`` fields (``{"omega1": 5.0}``) applied to the
    current spec.  ``h`` cannot change while the loop exists.
``"compensation"``
    ``"none"`` (off) or ``"coulomb"``/``"classical"``/``"lugre"``/``"adaptive"``
    (selects the model and turns compensation on; ``adaptive`` is the LuGre
    observer with levels adapted online, :mod:`frictionlab.model.adaptive`).
``"compensation_enabled"``
    ``True``/``False``: the thesis's Compensation button (keeps the model).
``"compensation_params"``
    Dict of friction fields for the selected model (``{"sigma0": 250}``;
    a ``compensation.`` prefix is accepted).  Each model keeps its own
    parameters, so switching models and back does not lose edits.
``"set"``
    Dict of ``design.*`` / ``compensation.*`` keys as for ``--set``.
``"error_signal"``
    The LuGre observer's error signal (:data:`frictionlab.model.controller.ERROR_SIGNALS`).

A refused change raises :class:`ChangeError` (a
:class:`~frictionlab.config.ConfigError`) whose ``keys`` name what was
refused, as ``design.<field>``, ``compensation.<field>``, ``compensation``
(the model), ``compensation_enabled`` or ``error_signal``, so that a caller
can point at the fields without reading the message.  Every snapshot
carries :attr:`ControlParams.loop_check`, the model's verdict on it
(:func:`frictionlab.model.loopcheck.check_loop`: stability of the sampled loop,
of the compensator, predicted peak of u); :meth:`ControlParams.refusal`
turns a failing verdict into an :class:`UnsafeChange` that also says what
would be safe.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field

import numpy as np

from ..config import Config, ConfigError, motor_friction_defaults
from ..model.controller import COMPENSATORS, DEFAULT_ERROR_SIGNAL, ERROR_SIGNALS, Controller, Gains
from ..model.design import PRESETS, Design, DesignSpec, design, gain_path, preset
from ..model.friction import FrictionParams, friction_row
from ..model.loopcheck import DEFAULT_DISTURBANCE, DEFAULT_NOISE, LoopCheck, check_loop
from ..model.params import ParamError
from ..model.plants.furuta_dc_design import dc_spec
from ..runs import plant_design, simulate_config

__all__ = [
    "CHANGE_KEYS",
    "COMPENSATOR_MODELS",
    "FALL_CHECK_ANGLE",
    "FALL_CHECK_SECONDS",
    "MIN_DECAY_RATE",
    "ChangeError",
    "ControlParams",
    "UncheckableChange",
    "UnsafeChange",
    "plant_presets",
]

#: Friction models the compensator can use (the thesis's "Friction Type").
COMPENSATOR_MODELS = COMPENSATORS
CHANGE_KEYS = ("design", "compensation", "compensation_enabled", "compensation_params", "set",
               "error_signal")
_FRICTION_FIELDS = tuple(f.name for f in dataclasses.fields(FrictionParams)
                         if "doc" in f.metadata)
_DESIGN_FIELDS = tuple(f.name for f in dataclasses.fields(DesignSpec) if "doc" in f.metadata)
#: Bisection steps of the search for the largest safe part of a refused change.
_SAFE_STEPS = 12
#: Slowest decay (1/s) the loop at rest must have to pass the check: its slowest mode
#: must shrink by e within 1 / MIN_DECAY_RATE = 10 s, i.e. a spectral radius of at most
#: exp(-MIN_DECAY_RATE h) (0.9995 at h = 5 ms; the presets decay at 2.1-2.6 1/s).  An
#: eigenvalue modulus of 1 - 1e-9 is stable on paper and holds nothing up: pole pairs at
#: omega = 1e-300 rad/s give exactly that, and the pendulum falls.
MIN_DECAY_RATE = 0.1
#: Seconds the settings that pass the linear check are simulated (the run's plant model
#: and friction, from DEFAULT_DISTURBANCE rad), and the angle (rad) counted as a fall
#: there: the loop's default angle limit (``Safety.angle_limit``).
FALL_CHECK_SECONDS = 10.0
FALL_CHECK_ANGLE = 0.35


class ChangeError(ConfigError):
    """A refused change; ``keys`` names what was refused (see the module docstring).

    Parameters
    ----------
    message : str
        One line saying what is wrong.
    keys : iterable of str
        ``design.<field>``, ``compensation.<field>``, ``compensation``,
        ``compensation_enabled`` or ``error_signal``.
    """

    def __init__(self, message: str, keys=()):
        super().__init__(message)
        self.keys = tuple(keys)


class UncheckableChange(ChangeError):
    """A change the model's check cannot be computed for (its numbers overflow or the
    linear algebra fails): refused whatever ``confirm`` says, since nothing would say
    whether the loop holds the pendulum."""


class UnsafeChange(ChangeError):
    """A valid change that the model predicts would hurt the motor.

    Attributes
    ----------
    keys : tuple of str
        The changed keys.
    check : LoopCheck
        The model's verdict on the changed settings.
    safe : dict
        What would be safe: ``{"values": {key: value}}``, the changed numeric
        keys scaled back as far as the check still passes (from the current
        values), and/or ``{"error_signals": [...]}``, the LuGre error signals
        that pass with the requested settings (empty dict: nothing found).
    """

    def __init__(self, message: str, keys, check: LoopCheck, safe: dict):
        super().__init__(message, keys)
        self.check = check
        self.safe = safe


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
    gp : Gains
        The controller's gains (:meth:`Controller.record`).
    cp : ndarray
        The compensator's friction record as a float row (read-only;
        :func:`frictionlab.model.friction.friction_row`), what the ``*_rows``
        steps take at every tick.
    """

    cfg: Config
    comp_enabled: bool
    comp_kind: str
    comp_params: dict = field(repr=False)
    error_signal: str
    design: Design = field(repr=False)
    controller: Controller = field(repr=False)
    gp: Gains = field(repr=False)
    cp: np.ndarray = field(repr=False)
    previous_spec: DesignSpec | None = field(default=None, repr=False)

    @classmethod
    def from_config(cls, cfg: Config, error_signal: str = DEFAULT_ERROR_SIGNAL
                    ) -> ControlParams:
        """The initial snapshot of a run (``cfg.compensation_kind`` none: off, LuGre selected)."""
        enabled = cfg.compensation_kind != "none"
        kind = cfg.compensation_kind if enabled else "lugre"
        params = {k: FrictionParams.defaults(k, "compensation") for k in COMPENSATOR_MODELS}
        if cfg.motor:  # every kind's defaults in the plant's units, as the page's schema
            params = {k: motor_friction_defaults(cfg.plant_kind, p, p)[1]
                      for k, p in params.items()}
        params[kind] = cfg.compensation
        return cls._build(cfg, cfg.design, enabled, kind, params, error_signal)

    @classmethod
    def _build(cls, cfg, spec, enabled, kind, params, error_signal,
               previous=None) -> ControlParams:
        cfg = dataclasses.replace(cfg, design=spec,
                                  compensation_kind=kind if enabled else "none",
                                  compensation=params[kind])
        d = plant_design(cfg)
        ctrl = Controller(d, kind if enabled else "none", params[kind],
                          error_signal=error_signal, u_max=cfg.u_limit)
        gp, rec = ctrl.record()
        cp = friction_row(rec)
        cp.flags.writeable = False
        return cls(cfg, enabled, kind, dict(params), error_signal, d, ctrl, gp, cp, previous)

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
            raise ChangeError(f"unknown change {unknown[0]!r}; known: {', '.join(CHANGE_KEYS)}",
                              [unknown[0]])
        spec = self.cfg.design
        enabled, kind = self.comp_enabled, self.comp_kind
        params = dict(self.comp_params)
        error_signal = self.error_signal

        if "design" in changes:
            spec = _design_spec(changes["design"], spec, self.presets)
        if "compensation" in changes:
            c = changes["compensation"]
            if c == "none":
                enabled = False
            elif c in COMPENSATOR_MODELS:
                kind, enabled = c, True
            else:
                raise ChangeError(f"compensation must be one of none, "
                                  f"{', '.join(COMPENSATOR_MODELS)}; got {c!r}", ["compensation"])
        if "compensation_enabled" in changes:
            e = changes["compensation_enabled"]
            if not isinstance(e, bool):
                raise ChangeError(f"compensation_enabled must be true or false, got {e!r}",
                                  ["compensation_enabled"])
            enabled = e
        if "set" in changes:
            items = changes["set"]
            if not isinstance(items, dict):
                raise ChangeError("set must be a dict of KEY: VALUE", ["set"])
            for key in items:
                if not (str(key).startswith("design.") or str(key).startswith("compensation.")):
                    raise ChangeError(f"{key}: only design.* and compensation.* keys can change "
                                      "while the controller runs", [str(key)])
            tmp = dataclasses.replace(self.cfg, design=spec, compensation=params[kind])
            for key, value in items.items():  # one at a time: a refusal names its key
                try:
                    tmp = tmp.with_values({key: value})
                except ValueError as exc:
                    raise ChangeError(str(exc), [str(key)]) from None
            spec = tmp.design
            params[kind] = tmp.compensation
        if "compensation_params" in changes:
            fields = changes["compensation_params"]
            if not isinstance(fields, dict):
                raise ChangeError("compensation_params must be a dict of field: value",
                                  ["compensation_params"])
            new_params = params[kind]
            for key, value in fields.items():
                name = str(key).removeprefix("compensation.")
                if name not in _FRICTION_FIELDS:
                    raise ChangeError(f"unknown compensation parameter {key!r}; known: "
                                      f"{', '.join(_FRICTION_FIELDS)}", [f"compensation.{name}"])
                try:
                    new_params = dataclasses.replace(new_params, **{name: value})
                except ParamError as exc:  # refused as friction.<name>: the compensator's key
                    own = ParamError(f"compensation.{name}", exc.value, exc.allowed)
                    raise ChangeError(str(own), [own.field]) from None
                except (TypeError, ValueError) as exc:
                    raise ChangeError(str(exc), [f"compensation.{name}"]) from None
            params[kind] = new_params
        if "error_signal" in changes:
            error_signal = changes["error_signal"]
            if error_signal not in ERROR_SIGNALS:
                raise ChangeError(f"error_signal must be one of {', '.join(ERROR_SIGNALS)}; "
                                  f"got {error_signal!r}", ["error_signal"])
        if spec.h != self.cfg.design.h:
            raise ChangeError(f"design.h cannot change while the controller exists "
                              f"(it is {self.cfg.design.h} s)", ["design.h"])
        keys = self._keys(spec, enabled, kind, params, error_signal)
        try:
            new = self._build(self.cfg, spec, enabled, kind, params, error_signal,
                              self.cfg.design)
        except (ValueError, ArithmeticError) as exc:
            # a combination the design or the controller refuses (a singular LuGre
            # compensator): the values this change touched, else the model it selected
            field = exc.field if isinstance(exc, ParamError) else ""
            touched = [k for k in keys if k.startswith(("design.", "compensation."))]
            own = [field] if field.startswith(("compensation.", "design.")) else []
            named = touched or own or keys or ["compensation"]
            message = str(exc)
            if not isinstance(exc, ParamError):  # numpy's words: say what was refused
                message = (f"{', '.join(_describe_raw(spec, params[kind], k) for k in named)}"
                           f" refused: the design or the compensator cannot be computed "
                           f"({exc})")
            raise ChangeError(message, named) from None
        new.check_computable(keys)
        return new

    def check_computable(self, keys=()) -> None:
        """Raise :class:`UncheckableChange` (naming ``keys``) unless these settings have
        finite gains and the model's check can be computed with finite numbers."""
        problem = None
        if not (np.all(np.isfinite(self.design.L)) and np.all(np.isfinite(self.design.K))):
            problem = "the design's gains are not finite numbers"
        else:
            try:
                chk = self.loop_check
            except (ValueError, ArithmeticError) as exc:  # numpy's LinAlgError included
                problem = f"the model's check fails ({exc})"
            else:
                # the radii must be numbers; a peak of u is inf for an unstable loop
                radii = (chk.spectral_radius, *(() if chk.compensator_radius is None
                                                 else (chk.compensator_radius,)))
                peaks = (chk.peak_u, chk.peak_u_disturbance, chk.u_noise_std)
                if (not all(math.isfinite(x) for x in radii)
                        or any(math.isnan(x) for x in peaks)):
                    problem = "the model's check gives numbers that are not finite"
        if problem is not None:
            changed = ", ".join(_describe(self, k) for k in keys) or "these settings"
            raise UncheckableChange(
                f"{changed} refused: {problem}, so nothing says whether the loop would hold "
                "the pendulum (the values are outside what the model can compute; "
                "confirm does not apply it)", keys or ["design"])

    def _keys(self, spec, enabled, kind, params, error_signal) -> list[str]:
        """The change keys whose values differ from ``self``'s."""
        keys = [f"design.{n}" for n in _DESIGN_FIELDS
                if getattr(spec, n) != getattr(self.cfg.design, n)]
        if enabled != self.comp_enabled:
            keys.append("compensation_enabled")
        if kind != self.comp_kind:
            keys.append("compensation")
        old_p, new_p = self.comp_params[kind], params[kind]
        keys += [f"compensation.{n}" for n in _FRICTION_FIELDS
                 if getattr(new_p, n) != getattr(old_p, n)]
        if error_signal != self.error_signal:
            keys.append("error_signal")
        return keys

    @functools.cached_property
    def l_path(self) -> np.ndarray | None:
        """The gains a running loop moves L along to these settings' over its gain
        transition (:func:`~frictionlab.model.design.gain_path` from the design these
        settings replace; None: L does not change).  Computed once, outside the loop
        (:meth:`~.api.RealtimeController.submit`)."""
        prev = self.previous_spec
        if prev is None or prev == self.cfg.design or self.cfg.motor:
            # a motor plant's L moves in a straight line (its observer, a predictor
            # on the same model, is switched at once)
            return None
        return gain_path(prev, self.cfg.design, self.cfg.plant)

    @functools.cached_property
    def loop_check(self) -> LoopCheck:
        """The model's verdict on these settings (:func:`~frictionlab.model.loopcheck.check_loop`).

        Against the run's plant model (``cfg.plant``); measurement noise
        ``sim.noise``, or :data:`~frictionlab.model.loopcheck.DEFAULT_NOISE` when
        that is 0 (a real rig's noise is not configured).
        """
        chk = check_loop(self.controller, self.cfg.plant,
                         noise=self.cfg.sim.noise or DEFAULT_NOISE)
        limit = math.exp(-MIN_DECAY_RATE * self.cfg.design.h)
        if chk.verdict != "unstable" and not chk.spectral_radius <= limit:
            # stable on paper, but its slowest mode hardly decays (see MIN_DECAY_RATE)
            r = chk.spectral_radius
            tau = self.cfg.design.h / -math.log(r) if 0 < r < 1 else math.inf
            reason = (f"the loop is not stable with a margin: its slowest mode (eigenvalue "
                      f"modulus {r:.9g}) takes {tau:.3g} s to decay by e, more than "
                      f"{1 / MIN_DECAY_RATE:g} s")
            chk = dataclasses.replace(chk, verdict="unstable", reasons=(reason, *chk.reasons))
        if chk.ok and (t := self.fall_time) is not None:
            # the linear check cannot see friction's limit cycle grow: the simulator can
            chk = dataclasses.replace(chk, verdict="falls", reasons=(
                f"simulated with the run's plant model and friction from a "
                f"{DEFAULT_DISTURBANCE:g} rad start, the pendulum falls (|theta| > "
                f"{self._fall_angle:g} rad) after {t:.2g} s",))
        return chk

    @property
    def _fall_angle(self) -> float:
        return min(self.cfg.sim.fall_angle, FALL_CHECK_ANGLE)

    @functools.cached_property
    def fall_time(self) -> float | None:
        """When the pendulum falls (s) in a :data:`FALL_CHECK_SECONDS` s simulation of
        these settings on the run's plant model and friction (``cfg``: ``plant.*``,
        ``friction.*``, ``sim.noise``), starting :data:`~frictionlab.model.loopcheck.
        DEFAULT_DISTURBANCE` rad from upright; None if it stays within
        :data:`FALL_CHECK_ANGLE` rad.  A design ``omega0`` of 7.5 against the plant's
        6.8 passes the linear check, yet its friction limit cycle grows and the
        pendulum falls after about 3 s: this finds it."""
        cfg = self.cfg.with_values({"sim.initial_angle": DEFAULT_DISTURBANCE,
                                    "sim.fall_angle": self._fall_angle})
        traj = simulate_config(cfg, FALL_CHECK_SECONDS, controller=self.controller)
        return len(traj) * traj.h if traj.status == "fell" else None

    def changed_keys(self, new: ControlParams) -> tuple[str, ...]:
        """The keys whose values differ from ``self`` in ``new`` (see the module docstring)."""
        return tuple(self._keys(new.cfg.design, new.comp_enabled, new.comp_kind,
                                new.comp_params, new.error_signal))

    def refusal(self, new: ControlParams) -> UnsafeChange:
        """The :class:`UnsafeChange` for going from ``self`` to ``new`` (whose check fails).

        Its message says why (the check's reasons) and what would be safe: the
        changed numbers scaled back from the current values (geometrically
        where both are positive) as far as the check still passes, found by
        bisection, and the LuGre error signals that pass.
        """
        check = new.loop_check
        keys = self.changed_keys(new)
        safe: dict = {}
        numeric = [k for k in keys if k.startswith(("design.", "compensation."))]
        # the current numbers with the requested choices (on/off, model, error signal)
        base = self._build(self.cfg, self.cfg.design, new.comp_enabled, new.comp_kind,
                           self.comp_params, new.error_signal)
        if numeric:
            values = base._largest_safe(new, numeric) if _passes(lambda: base) else {}
            if values:
                safe["values"] = values
        if new.comp_enabled and new.comp_kind == "lugre" and (
                "error_signal" in keys or not numeric):
            safe["error_signals"] = [
                e for e in ERROR_SIGNALS
                if _passes(lambda e=e: self._build(self.cfg, new.cfg.design, True, "lugre",
                                                   new.comp_params, e))]
        changed = ", ".join(_describe(new, k) for k in keys) or "the change"
        msg = f"{changed} refused: " + "; ".join(check.reasons)
        if safe.get("values"):
            msg += ". The check passes " + ", ".join(
                f"{'up' if _value(new, k) > _value(base, k) else 'down'} to {k} = {v:g} "
                f"(now {_value(base, k):g})" for k, v in safe["values"].items())
        if "error_signals" in safe:
            msg += (". Error signals that pass: " + ", ".join(safe["error_signals"])
                    if safe["error_signals"] else ". No error signal passes with these values")
        if not safe:
            msg += ". No part of this change passes the check"
        return UnsafeChange(msg + " (confirm to apply anyway)", keys, check, safe)

    def _largest_safe(self, new: ControlParams, keys: list[str]) -> dict[str, float]:
        """The values of ``keys`` at the largest fraction of the way to ``new`` that passes."""

        def at(t: float) -> ControlParams:
            spec_kw, comp_kw = {}, {}
            for k in keys:
                section, name = k.split(".", 1)
                a, b = float(_value(self, k)), float(_value(new, k))
                v = (a * (b / a) ** t if a > 0 and b > 0 else a + (b - a) * t)
                (spec_kw if section == "design" else comp_kw)[name] = v
            spec = dataclasses.replace(new.cfg.design, **spec_kw)
            params = dict(new.comp_params)
            params[new.comp_kind] = dataclasses.replace(params[new.comp_kind], **comp_kw)
            return self._build(self.cfg, spec, new.comp_enabled, new.comp_kind, params,
                               new.error_signal)

        lo, hi = 0.0, 1.0
        for _ in range(_SAFE_STEPS):
            mid = 0.5 * (lo + hi)
            if _passes(lambda mid=mid: at(mid)):
                lo = mid
            else:
                hi = mid
        if lo == 0.0:
            return {}
        best = at(lo)
        values = {k: _round_toward(float(_value(best, k)), float(_value(self, k)))
                  for k in keys}
        return values

    def warm(self) -> None:
        """Do now, off the loop, the one-time work of the first change of each kind.

        Designs both presets (:func:`~frictionlab.model.design.design` caches its
        results) and builds a controller for every compensator model, which
        imports the compensation code on first use.  Done in a request
        thread while the loop runs, this held the GIL for up to 30 ms and
        stalled the loop; afterwards a preset or a model switch costs well
        under 1 ms and a new custom design about 1 ms.
        """
        if not self.cfg.motor:
            for spec in PRESETS.values():
                design(spec, self.cfg.plant)
        for kind in COMPENSATOR_MODELS:
            # also loads the loop check's compiled code for each compensator
            _ = self.apply({"compensation": kind}).loop_check
        _ = self.loop_check

    @functools.cached_property
    def presets(self) -> dict[str, DesignSpec]:
        """The ``fast`` and ``slow`` designs on this plant (:func:`plant_presets`)."""
        return plant_presets(self.cfg)

    @property
    def preset(self) -> str | None:
        """``fast``/``slow`` if the current spec is that preset, else None."""
        for name, spec in self.presets.items():
            if spec == self.cfg.design:
                return name
        return None

    def describe(self) -> dict:
        """JSON-ready summary: design (spec, L, K: the thesis's four observer gains, a
        motor plant's 4 x 3 observer matrix row by row) and compensation, and the plant
        (``plant``: its ``--plant`` name; ``u_unit``: u's and the friction levels'
        unit, ``m/s^2`` or ``V``)."""
        return {
            "plant": self.cfg.plant_kind,
            "u_unit": self.cfg.plant_model.u_unit,
            "design": {"preset": self.preset, "spec": dataclasses.asdict(self.cfg.design),
                       "L": [float(v) for v in self.design.L],
                       "K": np.asarray(self.design.K, dtype=float).tolist()},
            "compensation": {"enabled": self.comp_enabled, "kind": self.comp_kind,
                             "params": dataclasses.asdict(self.comp_params[self.comp_kind]),
                             "error_signal": self.error_signal},
        }


def plant_presets(cfg: Config) -> dict[str, DesignSpec]:
    """The ``fast`` and ``slow`` designs of Sec. 2.4 on the plant of ``cfg``: the
    thesis's, or a motor plant's
    (:func:`~frictionlab.model.plants.furuta_dc_design.dc_spec`: the pattern scaled to
    its unstable rate), at the run's h."""
    if not cfg.motor:
        return PRESETS
    return {name: dc_spec(name, cfg.plant, cfg.design.h) for name in PRESETS}


def _passes(make) -> bool:
    """True if ``make()`` builds settings whose check is computable and passes."""
    try:
        p = make()
        p.check_computable()
        return p.loop_check.ok
    except (ValueError, ArithmeticError):  # a ChangeError or numpy's LinAlgError included
        return False


def _value(p: ControlParams, key: str):
    """The value of ``design.<f>`` / ``compensation.<f>`` (the selected model's) in ``p``."""
    section, name = key.split(".", 1)
    obj = p.cfg.design if section == "design" else p.comp_params[p.comp_kind]
    return getattr(obj, name)


def _describe(p: ControlParams, key: str) -> str:
    """``key = value`` in ``p``, for messages."""
    if key == "compensation_enabled":
        return "compensation " + ("on" if p.comp_enabled else "off")
    if key == "compensation":
        return f"compensation model {p.comp_kind}"
    if key == "error_signal":
        return f"error signal {p.error_signal}"
    return f"{key} = {_value(p, key):g}"


def _describe_raw(spec: DesignSpec, comp: FrictionParams, key: str) -> str:
    """``key = value`` from a spec and compensator parameters (before they are built)."""
    section, _, name = key.partition(".")
    if section == "design" and name:
        return f"{key} = {getattr(spec, name):g}"
    if section == "compensation" and name:
        return f"{key} = {getattr(comp, name):g}"
    return key


def _round_toward(value: float, toward: float) -> float:
    """``value`` to 3 significant digits, rounded toward ``toward`` (the safe side)."""
    if value == 0 or not math.isfinite(value):
        return value
    scale = 10.0 ** (math.floor(math.log10(abs(value))) - 2)
    rounded = (math.floor if toward < value else math.ceil)(value / scale) * scale
    return float(f"{rounded:.3g}")


def _design_spec(value, current: DesignSpec, presets: dict[str, DesignSpec]) -> DesignSpec:
    if isinstance(value, DesignSpec):
        return value
    if isinstance(value, str):
        if value in presets:
            return presets[value]
        try:
            return preset(value)  # its error names the presets
        except ValueError as exc:
            raise ChangeError(str(exc), ["design"]) from None
    if isinstance(value, dict):
        spec = current
        for key, v in value.items():
            name = str(key).removeprefix("design.")
            if name not in _DESIGN_FIELDS:
                raise ChangeError(f"unknown design field {key!r}; known: "
                                  f"{', '.join(_DESIGN_FIELDS)}", [f"design.{name}"])
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise ChangeError(f"design.{name}: {v!r} is not a number", [f"design.{name}"])
            try:
                spec = dataclasses.replace(spec, **{name: v})
            except ValueError as exc:
                raise ChangeError(str(exc), [f"design.{name}"]) from None
        return spec
    raise ChangeError(f"design must be 'fast', 'slow', a DesignSpec or a dict; got {value!r}",
                      ["design"])
