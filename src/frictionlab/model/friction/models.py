"""One small frozen Python object per friction model, running the compiled
:func:`~frictionlab.model.friction.friction_step` (:mod:`frictionlab.model.friction`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .laws import friction_step, steady_state
from .params import KINDS, FrictionParams, check_kind

# --------------------------------------------------------------------------
# Python objects: one small frozen object per model
# --------------------------------------------------------------------------


@dataclass(frozen=True)
class FrictionModel:
    """Base of the friction models: a kind and its (validated) parameters.

    Every model has the same interface, ``init() -> state`` and
    ``step(state, v, f_ext, dt, e=0.0) -> (F, state)``, both running the
    compiled :func:`friction_step` that the simulator and the compensators
    run; a model keeps no state inside (the Coulomb relay output and the
    LuGre bristle deflection are the ``state`` passed in and returned; the
    memoryless models return it unchanged).  Build one with
    :func:`make_model`.
    """

    params: FrictionParams = dataclasses.field(default_factory=FrictionParams)
    kind: ClassVar[str] = "none"
    has_state: ClassVar[bool] = False

    @property
    def code(self) -> int:
        """The model's integer code (index in :data:`KINDS`)."""
        return KINDS.index(self.kind)

    def _p(self) -> np.record:
        return self.params.record()

    def init(self) -> float:
        """Initial state: relay undecided (0), bristle relaxed (z = 0)."""
        return 0.0

    def step(self, state: float, v: float, f_ext: float, dt: float,
             e: float = 0.0) -> tuple[float, float]:
        """``(F, next_state)`` over ``dt`` s with ``v``, ``f_ext`` and ``e`` held.

        See :func:`friction_step` for the arguments (``f_ext`` is read by the
        classical models at rest, ``dt`` and ``e`` by LuGre, eq. 19).
        """
        f, state = friction_step(self.code, self._p(), float(state), float(v), float(f_ext),
                                 float(dt), float(e))
        return float(f), float(state)

    def steady_state(self, v: float) -> float:
        """Friction in steady sliding at constant velocity ``v`` with no external
        force (the relay switched to the direction of ``v``)."""
        return float(steady_state(self.code, self._p(), float(v)))


@dataclass(frozen=True)
class NoFriction(FrictionModel):
    """No friction (``none``): F = 0."""


@dataclass(frozen=True)
class Viscous(FrictionModel):
    """Viscous friction :math:`F = F_v v` (``F_v^-`` for v < 0 when given)."""

    kind: ClassVar[str] = "viscous"


@dataclass(frozen=True)
class Coulomb(FrictionModel):
    """Coulomb relay with hysteresis :math:`\\pm\\varepsilon` (Sec. 6.1); state: the relay."""

    kind: ClassVar[str] = "coulomb"
    has_state: ClassVar[bool] = True


@dataclass(frozen=True)
class Classical(FrictionModel):
    """Stiction + Coulomb friction, eq. (17), with a zero-velocity band."""

    kind: ClassVar[str] = "classical"


@dataclass(frozen=True)
class Stribeck(FrictionModel):
    """The classical model's implementation form with Stribeck decay (Sec. 6.2)."""

    kind: ClassVar[str] = "stribeck"


@dataclass(frozen=True)
class LuGre(FrictionModel):
    """The LuGre model, eq. (18), with the observer correction of eq. (19);
    state: the bristle deflection z."""

    kind: ClassVar[str] = "lugre"
    has_state: ClassVar[bool] = True


#: The model class of each kind.
MODELS: dict[str, type[FrictionModel]] = {
    m.kind: m for m in (NoFriction, Viscous, Coulomb, Classical, Stribeck, LuGre)}


def make_model(kind: str, params: FrictionParams | None = None, **overrides) -> FrictionModel:
    """Build a friction model, e.g. ``make_model("lugre", sigma0=300)``.

    Parameters
    ----------
    kind : str
        One of :data:`KINDS`.
    params : FrictionParams, optional
        Base parameters (default: the thesis values).
    **overrides
        Fields of :class:`FrictionParams` to change (validated).
    """
    check_kind(kind)
    base = params if params is not None else FrictionParams()
    if overrides:
        base = dataclasses.replace(base, **overrides)
    return MODELS[kind](base)
