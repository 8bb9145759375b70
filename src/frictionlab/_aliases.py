"""Former module paths, kept importable.

The package was reorganised into layers (``model``, ``config``, ``io``,
``studies``, ``realtime``, ``console``, ``cli``; docs/architecture.md).  The
modules' former paths (``frictionlab.simulation``, ``frictionlab.sweep``,
``frictionlab.identification``...) still import: each resolves to the very
module object at the new path, so ``frictionlab.simulation is
frictionlab.model.simulation`` and patching one patches the other.  Nothing
is imported until a former path is.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys

#: Former module path -> current module path.
ALIASES = {
    "frictionlab._jit": "frictionlab.model._jit",
    "frictionlab._numba_cache": "frictionlab.model._numba_cache",
    "frictionlab._validation": "frictionlab.model.params",
    "frictionlab.plant": "frictionlab.model.plant",
    "frictionlab.friction": "frictionlab.model.friction",
    "frictionlab.design": "frictionlab.model.design",
    "frictionlab.observers": "frictionlab.model.observers",
    "frictionlab.controller": "frictionlab.model.controller",
    "frictionlab.simulation": "frictionlab.model.simulation",
    "frictionlab.limit_cycles": "frictionlab.model.limit_cycles",
    "frictionlab.periodic": "frictionlab.model.periodic",
    "frictionlab.loopcheck": "frictionlab.model.loopcheck",
    "frictionlab.rig": "frictionlab.model.rig",
    "frictionlab.sensor": "frictionlab.model.sensor",
    "frictionlab.adaptive": "frictionlab.model.adaptive",
    "frictionlab.swingup": "frictionlab.model.swingup",
    "frictionlab.reference": "frictionlab.studies.reference",
    "frictionlab.predict": "frictionlab.studies.predict",
    "frictionlab.sweep": "frictionlab.studies.sweep",
    "frictionlab.compensation": "frictionlab.studies.compensation",
    "frictionlab.reproduce": "frictionlab.studies.reproduce",
    "frictionlab.batch": "frictionlab.studies.batch",
    "frictionlab.swingup_sim": "frictionlab.studies.swingup_sim",
    "frictionlab.identification": "frictionlab.studies.identification",
    "frictionlab.identification.experiments": "frictionlab.studies.identification.experiments",
    "frictionlab.identification.limit_cycle": "frictionlab.studies.identification.limit_cycle",
    "frictionlab.identification.plots": "frictionlab.studies.identification.plots",
    "frictionlab.identification.onrig": "frictionlab.studies.identification.onrig",
    "frictionlab.identification.runlog": "frictionlab.io.runlog",
    "frictionlab.identification.logs": "frictionlab.io.logs",
    "frictionlab.identification.cli": "frictionlab.cli.identify",
    "frictionlab.sweep_cli": "frictionlab.cli.sweep",
    "frictionlab.compensation_cli": "frictionlab.cli.compensate",
    "frictionlab.realtime_cli": "frictionlab.cli.run",
    "frictionlab.predict_cli": "frictionlab.cli.predict",
    "frictionlab.reproduce_cli": "frictionlab.cli.reproduce",
}


class _AliasLoader(importlib.abc.Loader):
    def __init__(self, target: str):
        self.target = target

    def create_module(self, spec):
        return importlib.import_module(self.target)

    def exec_module(self, module) -> None:
        # the import system stamped the alias's spec on the module; restore its own
        module.__spec__ = self._spec
        module.__loader__ = self._spec.loader

    def _remember(self, module) -> None:
        self._spec = module.__spec__


class _AliasFinder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname, path=None, target=None):
        new = ALIASES.get(fullname)
        if new is None:
            return None
        loader = _AliasLoader(new)
        loader._remember(importlib.import_module(new))
        return importlib.machinery.ModuleSpec(fullname, loader)


def install() -> None:
    """Make the former module paths importable (idempotent)."""
    # the modules already loaded are entered directly: importing a former path
    # then leaves the package's attributes alone (``frictionlab.design`` stays
    # the function, not the module of the same former name)
    for old, new in ALIASES.items():
        if new in sys.modules:
            module = sys.modules.setdefault(old, sys.modules[new])
            parent, _, child = old.rpartition(".")
            if parent in sys.modules and not hasattr(sys.modules[parent], child):
                setattr(sys.modules[parent], child, module)
    if not any(isinstance(f, _AliasFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _AliasFinder())
