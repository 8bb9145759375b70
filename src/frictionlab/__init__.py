"""frictionlab: the rotary (Furuta) inverted pendulum with friction on the arm bearing.

Built from C. F. Abelson, "The Effect of Friction on Stabilization of an
Inverted Pendulum" (Lund, 1996).  The public API:

* parameters: :class:`PlantParams`, :class:`DesignSpec`, :class:`FrictionParams`,
  :class:`SimParams`, :class:`Config`, :func:`build_config`
* physics: :func:`rhs` (eq. 6), :func:`zoh`
* python-control: :func:`to_control` (eq. 6 with the configured friction as a
  ``control.NonlinearIOSystem``), :func:`linearize` (its upright linearisation,
  eq. 7, as a ``control.StateSpace``); :mod:`frictionlab.interop`, loaded on
  first use
* friction: :func:`make_model`, :class:`FrictionModel` (one subclass per model:
  :mod:`frictionlab.model.friction`)
* design: :func:`design`, :func:`preset`
* observers and controller: :class:`PendulumObserver`, :class:`ArmObserver`,
  :class:`Controller`
* simulation and analysis: :func:`simulate`, :func:`simulate_config`,
  :class:`Trajectory`, :func:`features`, :func:`trajectory_features`
* rig conversions: :class:`RigScaling`

The package is layered (docs/architecture.md), inner to outer:
:mod:`frictionlab.model` (numpy, scipy and numba only), :mod:`frictionlab.io`,
:mod:`frictionlab.config`, :mod:`frictionlab.runs`, :mod:`frictionlab.plotting`,
:mod:`frictionlab.realtime`, :mod:`frictionlab.studies`, :mod:`frictionlab.console`
and :mod:`frictionlab.cli`.

The larger capabilities are subpackages with their own curated ``__all__``,
imported on demand so that ``import frictionlab`` stays light:

* :mod:`frictionlab.studies.sweep`: many parameter sets through the process pool or
  Dask (:func:`frictionlab.studies.sweep.evaluate`)
* :mod:`frictionlab.studies.identification`: limit-cycle fits
  (:func:`frictionlab.studies.identification.fit_limit_cycle`) and the simple
  experiments of Appendices A, B.4 and E
* :mod:`frictionlab.studies.compensation`: the compensators of Sec. 6 and their tuning
* :mod:`frictionlab.studies.predict`: the limit cycle predicted by the exact periodic
  orbit (:func:`frictionlab.model.periodic.periodic_orbit`) and by the describing
  function
* :mod:`frictionlab.realtime`: the 200 Hz loop, rig backends and logging
  (:class:`frictionlab.realtime.RealtimeController`)
* :mod:`frictionlab.console`: the operator console (FastAPI)
* :mod:`frictionlab.gym`: the Gymnasium environment ``frictionlab/Furuta-v0``
  (registered on import; needs the ``gym`` extra)
"""

__version__ = "0.1.0"

__all__ = [
    "ArmObserver",
    "Config",
    "ConfigError",
    "Controller",
    "Design",
    "DesignSpec",
    "FrictionModel",
    "FrictionParams",
    "LimitCycleFeatures",
    "PendulumObserver",
    "PlantParams",
    "RigScaling",
    "SimParams",
    "Trajectory",
    "build_config",
    "design",
    "features",
    "linearize",
    "make_model",
    "preset",
    "rhs",
    "simulate",
    "simulate_config",
    "to_control",
    "trajectory_features",
    "zoh",
]

#: Every public name and the module it comes from, imported when first used:
#: ``import frictionlab`` itself imports nothing, so that the ``frictionlab``
#: executable (:mod:`frictionlab.__main__`) installs its stop signals before
#: numpy and the rest load (python-control is imported only by ``to_control``
#: and ``linearize``).
_LAZY = {
    "Config": "config", "ConfigError": "config", "SimParams": "config",
    "build_config": "config", "simulate": "runs", "simulate_config": "runs",
    "Controller": "model.controller",
    "Design": "model.design", "DesignSpec": "model.design", "design": "model.design",
    "preset": "model.design",
    "FrictionModel": "model.friction", "FrictionParams": "model.friction",
    "make_model": "model.friction",
    "LimitCycleFeatures": "model.limit_cycles", "features": "model.limit_cycles",
    "trajectory_features": "model.limit_cycles",
    "ArmObserver": "model.observers", "PendulumObserver": "model.observers",
    "PlantParams": "model.plants.thesis", "rhs": "model.plants.thesis",
    "zoh": "model.plants.thesis",
    "RigScaling": "model.rig",
    "Trajectory": "model.simulation",
    "to_control": "interop", "linearize": "interop",
}


def __getattr__(name: str):
    import importlib

    if name in _LAZY:
        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    try:  # a subpackage or module (frictionlab.config...), as an eager import made it
        return importlib.import_module(f".{name}", __name__)
    except ModuleNotFoundError as exc:
        if exc.name != f"{__name__}.{name}":
            raise
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
