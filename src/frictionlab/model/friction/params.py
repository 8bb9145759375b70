"""The friction parameters: :class:`FrictionParams` (keys ``friction.*`` and
``compensation.*``), the model codes :data:`KINDS`, and the structured record
:data:`FRICTION_DTYPE` the compiled laws read (:mod:`frictionlab.model.friction`)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from .._jit import jit_inline
from ..params import Validated, param
from ..records import copy_record, float_record_dtype, record_row, row_record

#: Integer codes of the friction models (index = code).
KINDS = ("none", "viscous", "coulomb", "classical", "stribeck", "lugre")
NONE, VISCOUS, COULOMB, CLASSICAL, STRIBECK, LUGRE = range(6)

#: Fields of the friction record :data:`FRICTION_DTYPE`, in storage order, with
#: the :class:`FrictionParams` field each holds (see :meth:`FrictionParams.record`).
FRICTION_FIELDS = (
    "fs",                # stiction
    "fc",                # coulomb
    "fv",                # viscous
    "vs",                # stribeck_velocity
    "sigma0",            # sigma0
    "sigma1",            # sigma1
    "k",                 # observer_gain
    "band",              # zero_velocity_band (0 in a compensator's record)
    "eps",               # hysteresis
    "fs_neg",            # stiction_negative (stiction when None)
    "fc_neg",            # coulomb_negative (coulomb when None)
    "fv_neg",            # viscous_negative (viscous when None)
    "vd",                # sigma1_velocity (inf when None: constant sigma_1)
    "drift",             # drift
    "drift_start",       # drift_start
    "drift_time",        # drift_time (NaN when None: to the end of the run)
    "adapt_gain",        # adaptation_gain
    "adapt_bandwidth",   # adaptation_bandwidth
    "adapt_deadband",    # adaptation_deadband
    "adapt_innovation",  # adaptation_max_innovation
    "adapt_min",         # adaptation_min
    "adapt_max",         # adaptation_max
    "adapt_distance",    # adaptation_distance
)
#: The friction parameters' record type, one float64 per field of
#: :data:`FRICTION_FIELDS`: what the compiled force laws read (``p.fc``).  Its
#: scalar type is ``np.record``, so that in Python too an element of an array
#: of it (a view of a float row) is a record with its fields as attributes.
FRICTION_DTYPE = float_record_dtype(FRICTION_FIELDS)
#: Number of floats in a friction record (its size as a float row).
NP = len(FRICTION_FIELDS)


@dataclass(frozen=True)
class FrictionParams(Validated):
    """Parameters of every friction model (keys ``friction.*`` / ``compensation.*``).

    Each model reads the fields it needs (see the module docstring); the
    defaults are the thesis values (eq. 20, eq. 21, App. E).  Use
    :meth:`defaults` for the per-model defaults of the plant or the
    compensator.
    """

    _prefix = "friction."

    stiction: float = param(2.3, "stiction level [F_S]", "m/s^2", lo=0.0, hi=1e3)
    coulomb: float = param(1.5, "Coulomb friction level [F_C]", "m/s^2", lo=0.0, hi=1e3)
    viscous: float = param(0.07, "viscous coefficient [F_v] (LuGre, viscous)", "m/s^2/(rad/s)",
                           lo=0.0, hi=1e3)
    stribeck_velocity: float = param(1.0, "Stribeck velocity [v_S]", "rad/s", lo=0.0, hi=1e3,
                                     lo_open=True)
    sigma0: float = param(100.0, "LuGre bristle stiffness [sigma_0]; at least 1 (a bristle "
                          "deflection F_S / sigma_0 of radians is no bristle, and 1e-300 breaks "
                          "the numbers)", "1/s^2", lo=1.0, hi=1e7)
    sigma1: float = param(5.0, "LuGre bristle damping [sigma_1]", "1/s", lo=0.0, hi=1e5)
    observer_gain: float = param(0.0, "LuGre observer gain [k] of eq. (19); the plant's "
                                 "error is e = -theta (rad)", "1/s (plant; 1 for a velocity "
                                 "error)", lo=0.0, hi=1e4)
    zero_velocity_band: float = param(0.001, "classical model: |v| below this counts as rest "
                                      "(Sec. 5.2)", "rad/s", lo=0.0, hi=10.0)
    hysteresis: float = param(0.0, "Coulomb/Stribeck-classical hysteresis half-width "
                              "[epsilon] (Sec. 6.1-6.2)", "rad/s", lo=0.0, hi=10.0)
    stiction_negative: float | None = param(None, "F_S for v < 0 (asymmetric variant; None = "
                                            "same as stiction)", "m/s^2", lo=0.0, hi=1e3,
                                            optional=True)
    coulomb_negative: float | None = param(None, "F_C for v < 0 (asymmetric variant)", "m/s^2",
                                           lo=0.0, hi=1e3, optional=True)
    viscous_negative: float | None = param(None, "F_v for v < 0 (asymmetric variant)",
                                           "m/s^2/(rad/s)", lo=0.0, hi=1e3, optional=True)
    sigma1_velocity: float | None = param(None, "v_d of sigma_1(v) = sigma_1 exp(-(v/v_d)^2) "
                                          "(None = constant sigma_1)", "rad/s", lo=0.0,
                                          hi=1e3, lo_open=True, optional=True)
    drift: float = param(0.0, "plant only: relative change of the friction levels F_S, F_C, "
                         "F_v (both directions) over the drift time, linear in time (-0.4 = "
                         "40 % lower at the end; App. E.1: the lubricant warms up)", "1",
                         lo=-1.0, hi=10.0)
    drift_start: float = param(0.0, "plant only: when the drift begins", "s", lo=0.0, hi=1e5)
    drift_time: float | None = param(None, "plant only: how long the drift takes (None = to "
                                     "the end of the run; 0 = a step at drift_start)", "s",
                                     lo=0.0, hi=1e5, optional=True)
    adaptation_gain: float = param(200.0, "adaptive compensator: gradient gain [gamma] of the "
                                   "level estimates (0 = no adaptation); stable for "
                                   "gamma h^2 / L_1 < 4 - 2 lambda h",
                                   "m/(rad s^2)", lo=0.0, hi=1e7)
    adaptation_bandwidth: float = param(20.0, "adaptive compensator: bandwidth [lambda] of its "
                                        "arm-velocity predictor; stable for lambda h < 2",
                                        "1/s", lo=0.0, hi=1e5, lo_open=True)
    adaptation_deadband: float = param(0.1, "adaptive compensator: adaptation frozen while "
                                       "|arm velocity| is below this (stuck arm)", "rad/s",
                                       lo=0.0, hi=100.0)
    adaptation_distance: float = param(0.1, "adaptive compensator: adaptation frozen until "
                                       "the arm has slid this far since it last stopped or "
                                       "reversed (pre-sliding: the bristles settle within a "
                                       "few s(v)/sigma_0)", "rad", lo=0.0, hi=100.0)
    adaptation_max_innovation: float = param(1.0, "adaptive compensator: adaptation frozen "
                                             "while the velocity prediction error exceeds "
                                             "this (a bad signal)", "rad/s", lo=0.0, hi=1e3,
                                             lo_open=True)
    adaptation_min: float = param(0.05, "adaptive compensator: lower bound of the estimated "
                                  "F_C and F_S", "m/s^2", lo=0.0, hi=1e3, lo_open=True)
    adaptation_max: float = param(6.0, "adaptive compensator: upper bound of the estimated "
                                  "F_C and F_S", "m/s^2", lo=0.0, hi=1e3, lo_open=True)

    @staticmethod
    def defaults(kind: str, role: str = "plant") -> FrictionParams:
        """Thesis defaults of ``kind`` for the plant or the compensator.

        Parameters
        ----------
        kind : str
            One of :data:`KINDS`.
        role : {"plant", "compensation"}
            ``compensation`` gives the settings Sec. 6 found best on the rig:
            Coulomb eps 0.05 (F_C 1.5); classical F_S 2.3, F_C 1.55, v_S 1,
            eps 0.08; LuGre F_S 2.3, F_C 1.55, F_v 0.07, sigma0 300, sigma1 6,
            v_S 1, k 7.  ``adaptive`` (compensator only) starts from the
            LuGre settings.
        """
        if kind == "adaptive" and role == "compensation":
            kind = "lugre"
        check_kind(kind)
        base = FrictionParams()
        if role == "plant":
            return base
        if role != "compensation":
            raise ValueError(f"role must be 'plant' or 'compensation', got {role!r}")
        if kind == "coulomb":
            return dataclasses.replace(base, coulomb=1.5, hysteresis=0.05)
        if kind in ("classical", "stribeck"):
            return dataclasses.replace(base, stiction=2.3, coulomb=1.55, stribeck_velocity=1.0,
                                       hysteresis=0.08)
        if kind == "lugre":
            return dataclasses.replace(base, stiction=2.3, coulomb=1.55, viscous=0.07,
                                       sigma0=300.0, sigma1=6.0, stribeck_velocity=1.0,
                                       observer_gain=7.0)
        return base

    def record(self, zero_velocity_band: float | None = None,
               hysteresis: float | None = None) -> np.record:
        """The friction record (:data:`FRICTION_DTYPE`) the compiled force laws
        read, backed by its own array (compiled code may write it).

        ``zero_velocity_band`` and ``hysteresis``, when given, replace the
        field's value without a validated copy (the compensators' band 0,
        :func:`frictionlab.model.controller.compensator_params`; a Coulomb
        plant's hysteresis 0, :func:`plant_record`).
        """
        row = (  # in FRICTION_FIELDS order
            self.stiction, self.coulomb, self.viscous, self.stribeck_velocity, self.sigma0,
            self.sigma1, self.observer_gain,
            self.zero_velocity_band if zero_velocity_band is None else zero_velocity_band,
            self.hysteresis if hysteresis is None else hysteresis,
            self.stiction if self.stiction_negative is None else self.stiction_negative,
            self.coulomb if self.coulomb_negative is None else self.coulomb_negative,
            self.viscous if self.viscous_negative is None else self.viscous_negative,
            math.inf if self.sigma1_velocity is None else self.sigma1_velocity,
            self.drift, self.drift_start,
            math.nan if self.drift_time is None else self.drift_time,
            self.adaptation_gain, self.adaptation_bandwidth, self.adaptation_deadband,
            self.adaptation_max_innovation, self.adaptation_min, self.adaptation_max,
            self.adaptation_distance)
        return friction_record(np.array(row, dtype=np.float64))


def plant_record(kind: str, params: FrictionParams) -> np.record:
    """The friction record a plant's step runs with (law ``kind``, a :data:`KINDS` name).

    That of ``params``, except that a Coulomb plant's relay has no hysteresis:
    the hysteresis is the compensator's device against noise (Sec. 6.1); as a
    plant's friction it would keep pushing the arm along a reversed velocity
    (friction doing positive work), so the plant's relay takes the velocity's
    sign whenever the arm moves and ``friction.hysteresis`` does not change a
    Coulomb plant (docs/model.md, "Coulomb friction as a plant").  The other
    laws read the record as it is (the Stribeck-classical law's hysteresis is
    its band).
    """
    # (not a replaced, re-validated copy: a sweep packs every set)
    return params.record(hysteresis=0.0 if kind == "coulomb" else None)


def friction_row(p) -> np.ndarray:
    """The friction record ``p`` as a float row (:data:`FRICTION_FIELDS` order; a
    copy): what a batch stores per set and a caller in Python passes at every
    tick (:func:`friction_view` reads it back in compiled code)."""
    return record_row(p)


def friction_record(row) -> np.record:
    """The friction record stored in the float64 row ``row`` (:data:`NP`
    contiguous floats), by reference (Python side of :func:`friction_view`)."""
    return row_record(row, FRICTION_DTYPE)


def copy_friction(p) -> np.record:
    """An independent copy of the friction record ``p``."""
    return copy_record(p)


@jit_inline
def friction_view(row):
    """The friction record stored in the float row ``row`` (:func:`friction_row`),
    by reference; compiled code only.  Made once where a kernel starts from
    float rows (a batch's sets, the ``*_rows`` entry points), never per law call."""
    return row.view(FRICTION_DTYPE)[0]


def check_kind(kind: str) -> int:
    if kind not in KINDS:
        raise ValueError(f"friction model must be one of {', '.join(KINDS)}; got {kind!r}")
    return KINDS.index(kind)
