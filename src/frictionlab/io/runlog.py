"""Limit-cycle features of a recorded run (``frictionlab features``).

A ``frictionlab run`` leaves ``<run_id>.csv`` (``t`` and every signal by
name), ``<run_id>.dat`` (the ten signals of Sec. 7.1, no time) and the
sidecar ``<run_id>.json`` (configuration, design, stop reason).  The
features are those ``frictionlab simulate`` reports (Sec. 5;
:func:`frictionlab.model.limit_cycles.features`): measured on the logged pendulum
angle ``theta_m`` over the last ``window`` seconds (default: the last half of
the log), with ``max_u`` from ``u`` and ``max_arm_velocity`` from
``arm_dot_m``.  Ticks without a reading (``NaN`` rows) are left out.

The result is an experiment of ``identify limit-cycle --measured``: the
design preset (from the sidecar: the design in use when the run ended), the
design keys when the run's design was not exactly a preset, and the
features; with the plant the run controlled and the unit of its u (the
sidecar's ``plant`` and ``u_unit``: ``max_u`` is in volts on a motor plant),
so that the fit simulates that plant.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..model.design import PRESETS
from ..model.limit_cycles import features
from ..model.params import ParamError
from .logs import log_warnings, read_log

__all__ = ["MAX_SIDECAR_BYTES", "run_log_features"]

#: Largest sidecar read (a run's sidecar is a few tens of kB).
MAX_SIDECAR_BYTES = 16 << 20


def _sidecar(path: Path) -> dict | None:
    side = path.with_suffix(".json")
    if not side.is_file():
        return None
    try:
        with open(side, "rb") as fh:
            raw = fh.read(MAX_SIDECAR_BYTES + 1)
        if len(raw) > MAX_SIDECAR_BYTES:
            return None
        meta = json.loads(raw)
    except (OSError, ValueError, RecursionError):
        return None
    return meta if isinstance(meta, dict) else None


def _design_of(meta: dict | None) -> tuple[str | None, dict[str, Any]]:
    """(preset, extra design keys) of the run's last design, from the sidecar."""
    if meta is None:
        return None, {}
    for when in ("current", "initial"):
        part = meta.get(when)
        d = part.get("design") if isinstance(part, dict) else None
        if isinstance(d, dict):
            preset = d.get("preset")
            if preset in PRESETS:
                return preset, {}
            spec = d.get("spec")
            if isinstance(spec, dict):
                # not a preset: the fast one with every design key set explicitly
                keys = {f"design.{k}": v for k, v in spec.items()
                        if isinstance(v, int | float) and not isinstance(v, bool)}
                return "fast", keys
    return None, {}


def _text(meta: dict | None, key: str) -> str | None:
    value = meta.get(key) if meta is not None else None
    return value if isinstance(value, str) and value else None


def run_log_features(path: str | Path, *, window: float | None = None,
                     h: float | None = None, design: str | None = None) -> dict[str, Any]:
    """Features of a run log, as an experiment of ``identify limit-cycle --measured``.

    Parameters
    ----------
    path : path
        The run's ``.csv`` or ``.dat``; the sidecar ``.json`` beside it is read
        when present.
    window : float, optional
        Analyse the last ``window`` seconds (default: the last half).
    h : float, optional
        Sampling period of a ``.dat`` (``design.h``); default: the sidecar's.
    design : {"fast", "slow"}, optional
        The design preset, when the log has no sidecar (else the sidecar's).

    Returns
    -------
    dict
        ``{"design", "status", "features", "set", "name", "log", "window",
        "stop_reason", "plant", "u_unit", "notes"}``: ``plant`` the sidecar's
        plant name (``thesis``, ``qube2``...) and ``u_unit`` the unit of u and
        ``max_u`` (``m/s^2``, ``V``), None when no sidecar says.

    Raises
    ------
    ParamError
        No design (``field`` ``design``), or a ``.dat`` without a period (``h``).
    ValueError
        Unreadable or malformed log.
    """
    p = Path(path)
    if p.suffix not in (".csv", ".dat"):
        raise ValueError(f"{p}: a run log is a .csv or a .dat")
    meta = _sidecar(p)
    preset, sets = _design_of(meta)
    notes: list[str] = []
    if design is not None:
        if preset is not None and design != preset:
            notes.append(f"the sidecar says the run ended with the {preset} design; "
                         f"using {design} as asked")
        preset, sets = design, {}
    if preset is None:
        raise ParamError("design", None, "fast or slow",
                         f"{p}: no sidecar ({p.with_suffix('.json').name}) names the run's "
                         "design; give its design, fast or slow")
    if h is None and meta is not None and isinstance(meta.get("h"), int | float):
        h = float(meta["h"])
    if h is None:
        if p.suffix == ".dat":
            raise ParamError("h", None, "(0, inf) s",
                             f"{p}: a .dat has no time column and no sidecar gives the "
                             "sampling period; give its sampling period h")
        h = 0.005
    if not (h > 0 and math.isfinite(h)):
        raise ParamError("h", h, "(0, inf) s", f"{p}: design.h must be > 0, got {h}")
    if h != PRESETS[preset].h and "design.h" not in sets:
        sets["design.h"] = h
    sig = read_log(p, h)
    for name in ("theta_m", "u", "arm_dot_m"):
        if name not in sig:
            raise ValueError(f"{p}: the log has no {name} column")
    t, theta = sig["t"], sig["theta_m"]
    ok = np.isfinite(theta) & np.isfinite(sig["u"]) & np.isfinite(sig["arm_dot_m"])
    if ok.sum() < 3:
        raise ValueError(f"{p}: fewer than 3 ticks with a reading")
    t, theta, u, v = t[ok], theta[ok], sig["u"][ok], sig["arm_dot_m"][ok]
    span = float(t[-1] - t[0])
    if window is not None and window > span:
        notes.append(f"the window ({window:g} s) is longer than the log ({span:g} s): "
                     "using all of it")
        window = span
    stop = meta.get("stop_reason") if meta is not None else None
    fell = stop == "angle_limit"
    noise = 0.0
    cfg = meta.get("config") if meta is not None else None
    if meta is not None and meta.get("backend") == "sim" and isinstance(cfg, dict):
        n = cfg.get("sim.noise")
        noise = float(n) if isinstance(n, int | float) and n > 0 else 0.0
    feats = features(t, theta, u, v, window=window, fell=fell, noise=noise)
    if meta is not None:
        comp = (meta.get("current") or {}).get("compensation")
        if isinstance(comp, dict) and comp.get("enabled"):
            notes.append(f"the run ended with the {comp.get('kind')} compensator on: its "
                         "features are of the compensated loop")
    notes.extend(log_warnings(p))
    return {
        "design": preset,
        "status": feats.status,
        "features": feats.interface_dict(),
        "set": sets,
        "name": (meta.get("run_id") if meta is not None and isinstance(meta.get("run_id"), str)
                 else p.stem),
        "log": str(p),
        "window": window if window is not None else 0.5 * span,
        "stop_reason": stop,
        "plant": _text(meta, "plant"),
        "u_unit": _text(meta, "u_unit"),
        "notes": notes,
    }
