"""Figures (matplotlib, headless): the shared style, and the ``simulate --plot`` figure.

Only the command line, its study modules and report scripts import this
module.  Every figure of the package follows the style defined here:

* axis labels carry their unit, ``quantity [unit]`` (:func:`axis_label`,
  :func:`key_label` for a parameter key, :data:`FEATURE_UNITS` for the
  limit-cycle features);
* a title names the design and the parameters of the run
  (:func:`config_title`);
* traces are told apart by line style *and* colour (:data:`TRACES` for the
  roles measured / estimated / true / model / control / reference, and
  :func:`series_style` for the i-th of several similar lines), so they stay
  apart in grey-scale print;
* :func:`save_figure` writes the file and prints its path on stderr.
"""

from __future__ import annotations

import dataclasses
import sys
import textwrap
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from .config import COMPENSATOR_FIELDS, PLANT_FIELDS, ConfigError, key_metadata
from .model.design import PRESETS
from .model.plants.furuta_dc import preset as dc_preset
from .model.plants.furuta_dc_design import dc_spec
from .model.plants.thesis import PlantParams

__all__ = [
    "FEATURE_UNITS",
    "TRACES",
    "axis_label",
    "config_title",
    "feature_label",
    "key_label",
    "parameter_lines",
    "plot_cycle_figure",
    "plot_rig_rows",
    "plot_trajectory",
    "save_figure",
    "series_style",
]

#: Line style of each role a trace can play (matplotlib ``plot`` keywords).
TRACES: dict[str, dict[str, Any]] = {
    # what the sensors read: a wide, light solid band ...
    "measured": {"color": "C0", "ls": "-", "lw": 1.8, "alpha": 0.6},
    # ... with the observers' or compensator's estimate dashed and crisp on top
    "estimated": {"color": "C1", "ls": "--", "lw": 1.1, "zorder": 3},
    # the simulated plant's true signal (not measurable on a rig): dotted black, on top
    "true": {"color": "k", "ls": ":", "lw": 1.6, "zorder": 4},
    # a fitted or model curve: dash-dot
    "model": {"color": "C3", "ls": "-.", "lw": 1.4, "zorder": 3},
    # the control signal
    "control": {"color": "C2", "ls": "-", "lw": 1.0},
    # marks: breakaway times, measured levels
    "reference": {"color": "C4", "ls": ":", "lw": 1.2},
}

_SERIES_LS = ("-", "--", "-.", ":")
_SERIES_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")

#: Units of the limit-cycle features (:data:`frictionlab.model.limit_cycles.FEATURES`).
FEATURE_UNITS = {"peak1": "rad", "peak2": "rad", "valley": "rad", "period": "s",
                 "max_u": "m/s$^2$", "max_arm_velocity": "rad/s", "peak_to_peak": "rad"}


def series_style(i: int) -> dict[str, Any]:
    """Colour, line style and marker of the i-th of several similar lines (all
    three change from one line to the next)."""
    return {"color": f"C{i % 10}", "ls": _SERIES_LS[i % len(_SERIES_LS)],
            "marker": _SERIES_MARKERS[i % len(_SERIES_MARKERS)]}


def _unit_text(unit: str) -> str:
    return unit.replace("m/s^2", "m/s$^2$").replace("1/s^2", "1/s$^2$")


def axis_label(quantity: str, unit: str) -> str:
    """``"quantity [unit]"`` (``1`` for a pure number)."""
    return f"{quantity} [{_unit_text(unit) or '1'}]"


def feature_label(name: str) -> str:
    """Axis label of a limit-cycle feature, e.g. ``period [s]``."""
    return axis_label(name, FEATURE_UNITS.get(name, "1"))


def key_label(key: str) -> str:
    """Axis label of a parameter key with its unit, e.g. ``friction.coulomb [m/s^2]``."""
    try:
        unit = key_metadata(key).get("unit", "")
    except ConfigError:
        unit = ""
    return axis_label(key, unit)


def _fmt(v: Any) -> str:
    if isinstance(v, tuple):
        return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def parameter_lines(cfg, exclude=(), width: int = 110, *, design: bool = True,
                    compensation: bool = True) -> list[str]:
    """The parameter values that define a run, one wrapped line per section.

    Every parameter the plant friction model reads (and the compensator's,
    with ``compensation``), and the plant, design (with ``design``) and
    noise settings that differ from the thesis's defaults; ``exclude``: keys
    not to list (e.g. swept ones).
    """
    exclude = set(exclude)
    parts = []

    def add(section: str, values: dict[str, Any]) -> None:
        shown = [f"{k}={_fmt(v)}" for k, v in values.items()
                 if v is not None and f"{section}.{k}" not in exclude]
        if shown:
            parts.append(f"{section}: " + ", ".join(shown))

    fields = PLANT_FIELDS[cfg.friction_kind]
    if not cfg.friction.drift:  # no drift: its start and time say nothing
        fields = fields - {"drift", "drift_start", "drift_time"}
    add("friction", {f: getattr(cfg.friction, f) for f in sorted(fields)})
    comp = cfg.compensation_kind
    if compensation and comp != "none":
        add("compensation", {f: getattr(cfg.compensation, f)
                             for f in sorted(COMPENSATOR_FIELDS[comp])})
    # the plant's values that differ from its defaults (a motor plant's: its preset's)
    ref = dc_preset(cfg.plant_kind) if cfg.motor else PlantParams()
    if cfg.motor:
        parts.append(f"plant {cfg.plant_kind} (u in V)")
    add("plant", {f.name: getattr(cfg.plant, f.name) for f in dataclasses.fields(cfg.plant)
                  if getattr(cfg.plant, f.name) != getattr(ref, f.name)})
    if design:
        base = _presets(cfg)[_design_base(cfg)[1]]
        add("design", {f.name: getattr(cfg.design, f.name)
                       for f in dataclasses.fields(cfg.design)
                       if getattr(cfg.design, f.name) != getattr(base, f.name)})
    add("sim", {k: getattr(cfg.sim, k) for k in ("noise", "quantization") if getattr(cfg.sim, k)})
    lines = []
    for part in parts:
        lines.extend(textwrap.wrap(part, width, subsequent_indent="    "))
    return lines


def _design_base(cfg) -> tuple[str, str]:
    """(name, preset): ``fast``/``slow`` for a preset, else ``modified P`` where
    P is the preset the spec differs least from."""
    presets = _presets(cfg)

    def ndiff(p):
        return sum(getattr(cfg.design, f.name) != getattr(p, f.name)
                   for f in dataclasses.fields(p))

    base = min(presets, key=lambda k: ndiff(presets[k]))
    return (base if ndiff(presets[base]) == 0 else f"modified {base}"), base


def _presets(cfg) -> dict:
    """The design presets of the configured plant (a motor plant's: the Sec. 2.4
    pattern on it, as its ``design.*`` defaults)."""
    if not getattr(cfg, "motor", False):
        return PRESETS
    return {name: dc_spec(name, cfg.plant) for name in PRESETS}


def config_title(cfg, what: str | None = None, exclude=(), width: int = 110) -> str:
    """Title lines naming the design and the parameters of ``cfg``.

    The first line: ``what``, the design (``fast``/``slow``, or ``modified
    fast``/``slow`` whose changed values :func:`parameter_lines` lists), the
    plant friction model and the compensator; then :func:`parameter_lines`.
    """
    comp = cfg.compensation_kind
    head = (f"{_design_base(cfg)[0]} design, {cfg.friction_kind} friction, "
            + ("no compensation" if comp == "none" else f"{comp} compensator"))
    if what:
        head = f"{what}: {head}"
    lines = textwrap.wrap(head, width, subsequent_indent="    ")
    return "\n".join(lines + parameter_lines(cfg, exclude, width))


def save_figure(fig, path: str, dpi: int = 110, rect=None) -> str:
    """Lay out (unless the figure has its own layout engine), write ``path``
    (.png, .pdf, .svg), close, and print the path on stderr."""
    if fig.get_layout_engine() is None:
        fig.tight_layout(**({} if rect is None else {"rect": rect}))
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    print(f"frictionlab: plot written to {path}", file=sys.stderr)
    return path


def plot_trajectory(traj, path: str, window: float | None = None, title: str | None = None,
                    period: float | None = None):
    """The figure a reader of Sec. 5 expects (cf. Figs. 17-18).

    Four panels over the end of the run: measured (solid) and estimated
    (dashed) pendulum angle, measured and estimated arm velocity, control
    signal, and the arm friction (the plant's true friction dotted and, when
    compensating, the estimate dashed).

    Parameters
    ----------
    traj : Trajectory
    path : str
        Output file (.png, .pdf, .svg).
    window : float, optional
        Longest span shown (s); default the last half of the run.
    title : str, optional
        Default :func:`config_title`: design, friction, compensation and the
        parameter values.
    period : float, optional
        The limit cycle's period: when given, the figure shows about six cycles
        (at least 5 s) so that the cycle's shape is readable, as in the thesis.
    """
    t = traj.t
    cfg = traj.config
    u_unit = cfg.plant_model.u_unit if hasattr(cfg, "plant_model") else "m/s^2"
    if len(t) == 0:
        raise ValueError("empty trajectory: nothing to plot")
    span = window if window is not None else 0.5 * t[-1]
    if period is not None and period > 0:
        span = min(span, max(6.0 * period, 5.0))
    span = max(span, min(5.0, t[-1]))
    m = t >= t[-1] - span
    fig, axes = plt.subplots(4, 1, figsize=(9, 9.4), sharex=True)
    ax = axes[0]
    ax.plot(t[m], traj["theta_m"][m], label=r"measured $\theta$", **TRACES["measured"])
    ax.plot(t[m], traj["theta_hat"][m], label=r"estimated $\hat\theta$",
            **TRACES["estimated"])
    ax.set_ylabel(axis_label("pendulum angle", "rad"))
    ax = axes[1]
    ax.plot(t[m], traj["arm_dot_m"][m], label=r"measured $\dot\Omega$", **TRACES["measured"])
    ax.plot(t[m], traj["arm_dot_hat"][m], label=r"estimated $\hat{\dot\Omega}$",
            **TRACES["estimated"])
    ax.set_ylabel(axis_label("arm velocity", "rad/s"))
    ax = axes[2]
    ax.plot(t[m], traj["u"][m], label="control $u$", **TRACES["control"])
    ax.set_ylabel(axis_label("control u", u_unit))
    ax = axes[3]
    ax.plot(t[m], traj["friction"][m], label="friction (plant, true)", **TRACES["true"])
    if np.any(traj["friction_hat"][m] != 0):
        ax.plot(t[m], traj["friction_hat"][m], label="estimate (compensator)",
                **TRACES["estimated"])
    ax.set_ylabel(axis_label("friction", u_unit))
    ax.set_xlabel(axis_label("time", "s"))
    for a in axes:
        a.grid(alpha=0.3)
        a.legend(loc="upper right", fontsize=8)
    cfg = traj.config
    if title is None and cfg is not None:
        title = config_title(cfg, "simulate") + ("" if traj.status == "ok" else "  [FELL]")
    if title:
        fig.suptitle(title, fontsize=9)
    return save_figure(fig, path)


def plot_cycle_figure(trace, path: str, kind: str, title: str, dpi: int = 100) -> str:
    """One simulated figure of Sec. 5.2-5.3 (Figs. 17-24) from a run's last cycles.

    Parameters
    ----------
    trace : mapping
        Arrays ``t`` (s), ``theta_m`` (rad), ``arm_dot_m`` (rad/s), ``u`` and
        ``friction`` (m/s^2) over the cycles to draw.
    path : str
        Output file (.png, .pdf, .svg).
    kind : {"angle_velocity", "control_friction"}
        ``angle_velocity``: the measured pendulum angle and the measured arm
        velocity, one panel each (Figs. 17, 19, 21, 23); ``control_friction``:
        the control signal and the plant's friction force, both in m/s^2, on
        one panel (Figs. 18, 20, 22, 24).
    title : str
        The figure's title: its number, the design and the parameters.
    """
    t = np.asarray(trace["t"])
    if len(t) == 0:
        raise ValueError("empty trace: nothing to plot")
    if kind == "angle_velocity":
        fig, axes = plt.subplots(2, 1, figsize=(9, 5.8), sharex=True, layout="constrained")
        axes[0].plot(t, trace["theta_m"], label=r"measured pendulum angle $\theta$",
                     **TRACES["measured"])
        axes[0].set_ylabel(axis_label(r"$\theta$", "rad"))
        axes[1].plot(t, trace["arm_dot_m"], label=r"measured arm velocity $\dot\Omega$",
                     **TRACES["measured"])
        axes[1].set_ylabel(axis_label(r"$\dot\Omega$", "rad/s"))
    elif kind == "control_friction":
        fig, ax = plt.subplots(1, 1, figsize=(9, 4.2), layout="constrained")
        axes = [ax]
        ax.plot(t, trace["u"], label="control signal $u$", **TRACES["control"])
        ax.plot(t, trace["friction"], label=r"friction force $F_{fr}/m$ (plant, true)",
                **TRACES["true"])
        ax.set_ylabel(axis_label("u, friction", "m/s^2"))
    else:
        raise ValueError(f"kind must be 'angle_velocity' or 'control_friction', got {kind!r}")
    for ax in axes:
        ax.axhline(0.0, color="0.5", lw=0.6)
        ax.grid(alpha=0.3)
        # above the panel, clear of the periodic curves
        ax.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), ncol=2, frameon=False,
                  fontsize=8, borderaxespad=0.1)
    axes[-1].set_xlabel(axis_label("time", "s"))
    axes[-1].set_xlim(t[0], t[-1])
    fig.suptitle(title, fontsize=9)
    return save_figure(fig, path, dpi=dpi)


def plot_rig_rows(traces, rows, reference, path: str, title: str, dpi: int = 100) -> str:
    """Simulated limit cycles against the rig's Table 1, one panel per row.

    Parameters
    ----------
    traces : mapping
        Row name (``fast``, ``slow``) -> arrays ``t``, ``theta_m`` of the run's
        last cycles.
    rows : mapping
        Row name -> the run's features (Table 1's names).
    reference : mapping
        Row name -> Table 1's six features (peak1, peak2, valley, period,
        max_u, max_arm_velocity).
    """
    names = list(traces)
    fig, axes = plt.subplots(len(names), 1, figsize=(9, 3.0 * len(names)),
                             layout="constrained")
    for ax, name in zip(np.atleast_1d(axes), names, strict=True):
        tr, f, ref = traces[name], rows[name], reference[name]
        t = np.asarray(tr["t"])
        ax.plot(t - t[0], tr["theta_m"], label=r"simulated $\theta_m$", **TRACES["measured"])
        for i, (feat, color) in enumerate((("peak1", "C1"), ("peak2", "C3"), ("valley", "C2"))):
            ax.axhline(ref[i], color=color, ls="--", lw=1.0, label=f"rig's {feat} {ref[i]:.3g}")
            if f.get(feat) is not None:
                ax.axhline(f[feat], color=color, ls=":", lw=1.0,
                           label=f"simulated {feat} {f[feat]:.3g}")
        cols = ("period", "max_u", "max_arm_velocity")
        units = ("s", "m/s²", "rad/s")
        text = "\n".join(
            f"{c}: {f[c]:.3g} {u} (rig {r:g})" if f.get(c) is not None else f"{c}: - (rig {r:g})"
            for c, u, r in zip(cols, units, ref[3:], strict=True))
        ax.text(0.01, 0.03, text, transform=ax.transAxes, fontsize=8, va="bottom",
                bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "0.7"})
        ax.set_title(f"{name} design", fontsize=9)
        ax.set_ylabel(axis_label(r"$\theta_m$", "rad"))
        ax.grid(alpha=0.3)
        ax.legend(loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=7, frameon=False)
    np.atleast_1d(axes)[-1].set_xlabel(axis_label("time", "s"))
    fig.suptitle(title, fontsize=9)
    return save_figure(fig, path, dpi=dpi)
