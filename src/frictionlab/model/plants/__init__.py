r"""Plants: each plant is one module behind one interface, chosen by ``--plant NAME``.

A plant module provides

``Params``
    A frozen dataclass of its physical parameters (keys ``plant.*``), each
    field with its doc, unit and range; ``record()`` gives the float row the
    compiled code reads.
``tick(x, u, mem, substeps, ratio, h, pp, fkind, fp) -> (mean friction, mem)``
    The compiled step: advance the state ``x = [theta, theta_dot, arm,
    arm_dot, z]`` (theta the pendulum angle from upright) in place over one
    sampling period h with u held, the arm's friction
    (:func:`frictionlab.model.friction.friction_step`, code ``fkind``, record
    ``fp``) in the units of u; ``mem`` is the friction model's memory.
``rhs(t, x, u, params)``
    The continuous dynamics in python-control's order.
``linearization(params) -> (A, B)``
    The continuous linearisation at upright, states (theta, theta_dot, arm,
    arm_dot), input u.
``SUBSTEPS``
    The step's default substeps per sample by friction law (``sim.substeps``
    unset).

Every plant is measured the same way (the pendulum angle, the arm angle and
the arm velocity: :mod:`frictionlab.model.sensor`).  :func:`plant_step` is the
one dispatch the compiled closed loop (:mod:`frictionlab.model.closedloop`)
calls; :data:`PLANTS` names the plants and their codes.

Adding a plant: write its module to the interface above, add it to
:data:`PLANTS` and one branch to :func:`plant_step_called`, and give it a preset in
the configuration (docs/architecture.md, "Add a plant").
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from .._jit import jit_inline
from . import furuta_dc, thesis

__all__ = ["FURUTA_DC", "PLANTS", "THESIS", "PlantKind", "inlined_params", "inlined_step",
           "inlines_step", "plant_of", "plant_step", "plant_step_called"]


@dataclass(frozen=True)
class PlantKind:
    """One plant: its name, the code :func:`plant_step` dispatches on, its
    parameter class, the unit of its input u, and its step's default substeps
    per sample by friction law (its module's ``SUBSTEPS``)."""

    name: str
    code: int
    params: type
    u_unit: str
    description: str
    substeps: Mapping[str, int]


#: The thesis's plant, eq. (6): an ideal arm-tip acceleration input.
THESIS = PlantKind("thesis", 0, thesis.PlantParams, "m/s^2",
                   "the thesis's rig, eq. (6): u is the arm tip's acceleration",
                   thesis.SUBSTEPS)

#: The full Furuta pendulum driven by a DC motor (the QUBE-Servo 2 and 3):
#: u is the motor voltage.
FURUTA_DC = PlantKind("furuta-dc", 1, furuta_dc.FurutaDCParams, "V",
                      "the Furuta pendulum driven by a DC motor: u is the motor voltage",
                      furuta_dc.SUBSTEPS)

#: Every plant by name.
PLANTS = {THESIS.name: THESIS, FURUTA_DC.name: FURUTA_DC}


def plant_of(params) -> PlantKind:
    """The plant whose parameter class ``params`` is an instance of."""
    for kind in PLANTS.values():
        if isinstance(params, kind.params):
            return kind
    raise TypeError(f"no plant takes {type(params).__name__} parameters")


#: The thesis plant's step without the actuator's back-EMF, inlined where the
#: closed loop advances the plant (a call every tick cost about 10 % of a run):
#: the same Python function, compiled in place, on the plant's record.
inlined_step = jit_inline(thesis.step_without_back_emf.py_func)


@jit_inline
def inlines_step(pcode, pp):
    """Whether :func:`plant_step` inlines the step of the plant ``pcode`` with the
    parameter row ``pp`` (:func:`inlined_step` on :func:`inlined_params`): the
    thesis plant whose actuator has no back-EMF."""
    return pcode == 0 and not thesis.plant_record(pp).act_back_emf != 0.0


@jit_inline
def inlined_params(pp):
    """The record :func:`inlined_step` takes, of the row ``pp`` (read once by a
    loop, before its ticks)."""
    return thesis.plant_record(pp)


@jit_inline
def plant_step(pcode, x, u, mem, substeps, ratio, h, pp, fkind, fp):
    """Advance the plant of code ``pcode`` over one sample (its module's ``tick``):
    the thesis plant's step without the back-EMF inlined (:func:`inlines_step`),
    any other step called (:func:`plant_step_called`)."""
    if inlines_step(pcode, pp):
        return inlined_step(x, u, mem, substeps, ratio, h, inlined_params(pp), fkind, fp)
    return plant_step_called(pcode, x, u, mem, substeps, ratio, h, pp, fkind, fp)


@jit_inline
def plant_step_called(pcode, x, u, mem, substeps, ratio, h, pp, fkind, fp):
    """:func:`plant_step` with every plant's step called, none inlined: the form
    of a loop compiled for the plants whose step :func:`plant_step` does not
    inline (its compile time is then the loop's alone)."""
    if pcode == 1:
        # the DC plant's RK4 and mass matrix would double a loop's compile time,
        # for a step that costs far more than a call
        return furuta_dc.tick(x, u, mem, substeps, ratio, h, pp, fkind, fp)
    # the thesis plant with the back-EMF in every substep: the general step
    return thesis.tick(x, u, mem, substeps, ratio, h, pp, fkind, fp)
