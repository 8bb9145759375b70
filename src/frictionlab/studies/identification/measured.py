"""The measured side of a limit-cycle fit (:mod:`frictionlab.studies.identification.limit_cycle`):
the experiments (``--measured``), the keys that may be fitted and their search
bounds, and the refusals of bad ones."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from ...config import ConfigError, ConfigValueError, key_metadata, valid_keys
from ...model.limit_cycles import FEATURES

__all__ = [
    "DEFAULT_BOUNDS",
    "PENALTY",
    "STICTION_PAIRS",
    "Experiment",
    "check_bounds",
    "check_fit_keys",
    "default_bounds",
    "parse_experiments",
    "refusal",
]


def refusal(field: str, value: Any, allowed: str, message: str,
             *hints: str) -> ConfigValueError:
    """A :class:`ConfigValueError` naming ``field`` and, as ``hints``, the other
    arguments that would lift it (the command line names their options)."""
    err = ConfigValueError(field, value, allowed, message)
    err.hints = hints
    return err


#: Residual given to a feature of a run that fell, settled, or lacks the feature.
PENALTY = 10.0
#: (Coulomb, stiction) key pairs searched with F_S >= F_C when both are fitted.
STICTION_PAIRS = (("friction.coulomb", "friction.stiction"),
                  ("friction.coulomb_negative", "friction.stiction_negative"))

#: Default search bounds of the usual keys (the thesis's values lie well inside).
DEFAULT_BOUNDS: dict[str, tuple[float, float]] = {
    "friction.coulomb": (0.2, 4.0),
    "friction.stiction": (0.2, 6.0),
    "friction.coulomb_negative": (0.2, 4.0),
    "friction.stiction_negative": (0.2, 6.0),
    "friction.viscous": (0.0, 0.5),
    "friction.stribeck_velocity": (0.05, 5.0),
    "friction.sigma0": (10.0, 3000.0),
    "friction.sigma1": (0.0, 50.0),
    "friction.observer_gain": (0.0, 20.0),
    "friction.zero_velocity_band": (0.001, 0.1),
    "friction.hysteresis": (0.0, 0.2),
    "plant.omega0": (5.0, 9.0),
    "plant.input_gain": (0.5, 2.0),
    "plant.zeta": (0.0, 0.2),
    "plant.pivot_friction": (0.0, 2.0),
    "actuator.curvature": (0.0, 0.5),
    "actuator.back_emf": (0.0, 20.0),
}

_FITTABLE_SECTIONS = ("plant", "design", "friction", "compensation", "actuator")


# ---------------------------------------------------------------------------
# problem specification
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Experiment:
    """One measured limit cycle.

    Attributes
    ----------
    design : {"fast", "slow"}
        Design preset the rig ran (Sec. 2.4).
    sets : dict
        Further parameter keys of this experiment (``{key: value}``).
    features : dict
        Measured features (names of :data:`frictionlab.model.limit_cycles.FEATURES`);
        unknown features are left out.
    label : str
        Name used in the residual report.
    """

    design: str
    sets: Mapping[str, float]
    features: Mapping[str, float]
    label: str

    def __post_init__(self) -> None:
        if self.design not in ("fast", "slow"):
            raise ConfigError(f"experiment {self.label!r}: design must be 'fast' or 'slow', "
                              f"got {self.design!r}")
        for name, value in self.features.items():
            if name not in FEATURES:
                raise ConfigError(f"experiment {self.label!r}: unknown feature {name!r}; "
                                  f"known features: {', '.join(FEATURES)}")
            if not (isinstance(value, float) and math.isfinite(value) and value > 0):
                raise ConfigError(f"experiment {self.label!r}: feature {name} must be a "
                                  f"positive number (relative errors need it), got {value!r}")
        if not self.features:
            raise ConfigError(f"experiment {self.label!r} has no known feature")


def _number(where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{where}: {value!r} is not a number")
    return float(value)


def parse_experiments(obj: Any) -> list[Experiment]:
    """Validate the ``--measured`` JSON object and return its experiments.

    The object is ``{"experiments": [{"design": "fast"|"slow", "set": {KEY:
    VALUE}, "features": {"peak1": ..., ...}}, ...]}``; an optional ``"name"``
    labels an experiment (default: its design, numbered when repeated).  A
    feature given as ``null`` is unknown.

    Raises
    ------
    ConfigError
        Empty list, unknown feature, non-positive value, bad design.
    """
    if not isinstance(obj, Mapping) or "experiments" not in obj:
        raise ConfigError('measured features must be a JSON object {"experiments": [...]}')
    items = obj["experiments"]
    if not isinstance(items, list) or not items:
        raise ConfigError("measured features: 'experiments' must be a non-empty list")
    labels: list[str] = []
    out = []
    for i, item in enumerate(items):
        where = f"experiment {i + 1}"
        if not isinstance(item, Mapping):
            raise ConfigError(f"{where}: must be a JSON object")
        unknown = set(item) - {"design", "set", "features", "name"}
        if unknown:
            raise ConfigError(f"{where}: unknown field(s) {', '.join(sorted(unknown))}; "
                              "allowed: design, set, features, name")
        design = item.get("design", "fast")
        sets = item.get("set") or {}
        feats = item.get("features")
        if not isinstance(sets, Mapping):
            raise ConfigError(f"{where}: 'set' must be an object {{KEY: VALUE}}")
        if not isinstance(feats, Mapping):
            raise ConfigError(f"{where}: 'features' must be an object {{FEATURE: VALUE}}")
        known = {}
        for name, value in feats.items():
            if name not in FEATURES:
                raise ConfigError(f"{where}: unknown feature {name!r}; known features: "
                                  f"{', '.join(FEATURES)}")
            if value is not None:
                known[name] = _number(f"{where}: feature {name}", value)
        for key in sets:
            if key not in valid_keys():
                raise ConfigError(f"{where}: unknown key {key!r} in 'set'")
        label = str(item.get("name") or design)
        if label in labels:
            label = f"{label}#{labels.count(label) + 1}" if item.get("name") is None else label
        if label in labels:
            raise ConfigError(f"{where}: duplicate experiment name {label!r}")
        labels.append(label)
        out.append(Experiment(str(design), dict(sets), known, label))
    return out




def check_fit_keys(keys: Sequence[str], plant: str = "thesis") -> list[str]:
    """Validate the keys to fit: known (with the plant ``plant``), real-valued
    parameters, no repeats."""
    if not keys:
        raise ConfigValueError("fit", "", "one or more parameter keys", "needs at least one key")
    out: list[str] = []
    for key in keys:
        if key not in valid_keys(plant):
            raise ConfigValueError("fit", key, "parameter keys", f"{key!r} is not a parameter key; "
                              "see 'frictionlab keys'")
        section = key.split(".")[0]
        if section not in _FITTABLE_SECTIONS or key_metadata(key, plant)["integer"]:
            raise ConfigValueError("fit", key, "real-valued model parameters",
                                   f"{key!r} is not a real-valued model parameter "
                              f"(fittable sections: {', '.join(_FITTABLE_SECTIONS)})")
        if key in out:
            raise ConfigValueError("fit", key, "each key once", f"{key!r} given twice")
        out.append(key)
    return out


def default_bounds(key: str, current: float | None, plant: str = "thesis") -> tuple[float, float]:
    """Search bounds of ``key``: :data:`DEFAULT_BOUNDS` (the thesis plant's), else
    [v/2, 2v] around the current value v, clipped to the key's allowed range
    (a motor plant's levels are in volts: always [v/2, 2v])."""
    if key in DEFAULT_BOUNDS and plant == "thesis":
        return DEFAULT_BOUNDS[key]
    if current is None or current <= 0:
        raise ConfigValueError("bounds", key, "LO:HI of each fitted key without default "
                               "bounds", f"no default search bounds for {key} (current value "
                               f"{current}); give its bounds")
    meta = key_metadata(key, plant)
    lo, hi = 0.5 * current, 2.0 * current
    if meta["lo"] is not None:
        lo = max(lo, meta["lo"])
    if meta["hi"] is not None:
        hi = min(hi, meta["hi"])
    return lo, hi


def check_bounds(key: str, lo: float, hi: float, plant: str = "thesis") -> None:
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ConfigError(f"bounds of {key}: {lo}:{hi} must be finite")
    if not lo < hi:
        raise ConfigError(f"bounds of {key}: lower {lo:g} must be below upper {hi:g}")
    meta = key_metadata(key, plant)
    if meta["lo"] is not None and (lo < meta["lo"] or (meta["lo_open"] and lo == meta["lo"])):
        raise ConfigError(f"bounds of {key}: lower {lo:g} is outside the key's allowed "
                          f"range (minimum {meta['lo']:g})")
    if meta["hi"] is not None and (hi > meta["hi"] or (meta["hi_open"] and hi == meta["hi"])):
        raise ConfigError(f"bounds of {key}: upper {hi:g} is outside the key's allowed "
                          f"range (maximum {meta['hi']:g})")
