"""Figures of the identification results (matplotlib, headless).

Only the command line imports this module.  The style (units on the axes,
line styles as well as colours, titles naming the experiment and its
parameters, the written path on stderr) is :mod:`frictionlab.plotting`'s.
"""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np

from ...model.limit_cycles import FEATURES
from ...plotting import (
    TRACES,
    axis_label,
    config_title,
    parameter_lines,
    save_figure,
    series_style,
)
from .friction_tests import stribeck_model

__all__ = [
    "experiment_title",
    "plot_control_scaling",
    "plot_free_oscillation",
    "plot_limit_cycle_fit",
    "plot_stiction",
    "plot_stribeck",
]

#: Styles of the measured feature levels drawn over the fitted simulation.
_LEVELS = {"peak1": {"color": "C1", "ls": "--"}, "peak2": {"color": "C3", "ls": ":"},
           "valley": {"color": "C2", "ls": "-."}}


def experiment_title(what: str, source: str, cfg=None) -> str:
    """Title of a simple experiment's figure: ``what``, where the data came
    from, and (for a simulated rig, ``cfg``) the friction model and the plant
    and friction parameters it ran with."""
    if cfg is None:
        return f"{what}: {source}"
    head = f"{what}: {source}, {cfg.friction_kind} friction"
    return "\n".join([head, *parameter_lines(cfg, design=False, compensation=False)])


def _finish(fig, title: str | None, estimates: str) -> None:
    fig.suptitle("\n".join(t for t in (title, estimates) if t), fontsize=9)


def plot_limit_cycle_fit(result, trajectories, path: str, window: float | None = None) -> str:
    """Measured vs fitted features, one column per experiment.

    Top: the fitted simulation's measured pendulum angle over its last
    periods (solid), with the measured peak1/peak2/valley as horizontal lines
    (dashed, dotted, dash-dot) and the measured period as a bar.  Bottom:
    every feature, fitted vs measured (as the ratio fitted/measured; 1 is a
    perfect match).  Each column is titled with its experiment's design and
    settings; the figure with the estimates.
    """
    labels = list(result.measured)
    n = len(labels)
    fig, axes = plt.subplots(2, n, figsize=(5.6 * n, 7.6), squeeze=False)
    for j, label in enumerate(labels):
        traj = trajectories[j]
        meas = result.measured[label]
        sim = result.simulated[label]
        ax = axes[0, j]
        t = traj.t
        period = sim.get("period") or meas.get("period") or 1.0
        span = min(t[-1], 3.0 * period) if len(t) else 0.0
        m = t >= t[-1] - span if len(t) else slice(0, 0)
        ax.plot(t[m], traj["theta_m"][m], color="C0", ls="-", lw=1.2,
                label="fitted simulation")
        for name, style in _LEVELS.items():
            if name in meas:
                ax.axhline(meas[name], lw=1.2, label=f"measured {name}", **style)
        if "period" in meas and len(t):
            t0 = t[-1] - span
            ax.plot([t0, t0 + meas["period"]], [0, 0], color="k", lw=3, marker="|", ms=12,
                    label="measured period")
        cfg = traj.config
        head = f"{label}: status {result.status[label]}"
        ax.set_title(config_title(cfg, head, width=int(12 * 5.6)) if cfg is not None else head,
                     fontsize=8)
        ax.set_xlabel(axis_label("time", "s"))
        ax.set_ylabel(axis_label("measured pendulum angle", "rad"))
        ax.legend(loc="lower left", fontsize=7)
        ax.grid(alpha=0.3)
        ax = axes[1, j]
        names = [f for f in FEATURES if f in meas]
        ratio = [(sim[f] / meas[f]) if sim.get(f) is not None else np.nan for f in names]
        xs = np.arange(len(names))
        ax.bar(xs, ratio, color="C0", label="fitted / measured")
        ax.axhline(1.0, color="k", lw=1)
        for x, f, r in zip(xs, names, ratio, strict=True):
            if math.isfinite(r):
                ax.text(x, r, f"{sim[f]:.3g}\n({meas[f]:.3g})", ha="center", va="bottom",
                        fontsize=7)
        ax.set_xticks(xs, names, rotation=30, fontsize=8)
        ax.set_ylabel(axis_label("fitted / measured feature", "1"))
        ax.set_ylim(0, max(1.5, np.nanmax(ratio) * 1.25 if len(ratio) else 1.5))
        ax.grid(alpha=0.3, axis="y")
    est = ", ".join(f"{k} = {v:.4g}" for k, v in result.estimate.items())
    _finish(fig, "identify limit-cycle: fitted simulation vs measured features",
            f"estimate: {est}  (cost {result.cost:.3g})")
    return save_figure(fig, path)


def plot_stiction(log, result: dict, path: str, title: str | None = None) -> str:
    """App. E.1: the applied u and the arm velocity, with the breakaways and
    the sliding runs used for the Coulomb level."""
    t = np.asarray(log["t"])
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 6.4), sharex=True)
    a1.plot(t, log["u"], label="applied u", **TRACES["control"])
    a2.plot(t, log["arm_dot_m"], label="measured arm velocity", **TRACES["measured"])
    first = True
    for name in ("positive", "negative"):
        tb = result.get(f"breakaway_time_{name}")
        if tb is not None:
            for a in (a1, a2):
                a.axvline(tb, label="breakaway" if first else None, **TRACES["reference"])
            first = False
    for i, s in enumerate(result.get("segments", [])):
        a2.axvspan(s["t0"], s["t1"], color="C1", alpha=0.15,
                   label="sliding run (Coulomb level)" if i == 0 else None)
    a1.set_ylabel(axis_label("u", "m/s^2"))
    a2.set_ylabel(axis_label("arm velocity", "rad/s"))
    a2.set_xlabel(axis_label("time", "s"))
    for a in (a1, a2):
        a.grid(alpha=0.3)
        a.legend(loc="upper left", fontsize=8)
    _finish(fig, title,
            f"stiction {result['stiction']:.3g} (+{result['stiction_positive']:.3g} / "
            f"-{result['stiction_negative']:.3g}), Coulomb {result['coulomb']:.3g} m/s$^2$")
    return save_figure(fig, path)


def plot_stribeck(result: dict, path: str, title: str | None = None) -> str:
    """App. E.2 / Figure 38: steady friction vs arm velocity with the fitted curve."""
    pts = np.array(result["points"])
    fig, ax = plt.subplots(figsize=(8, 5.4))
    ax.plot(pts[:, 0], pts[:, 1], ls="none", marker="o", ms=5, color="C0",
            label="steady points (measured)")
    vmax = float(np.max(np.abs(pts[:, 0])))
    fs, vs = result["stiction"], result["stribeck_velocity"]
    fc = result["coulomb"]
    for d in (1.0, -1.0):
        v = d * np.linspace(0.02, vmax, 300)
        f = d * stribeck_model(v, fc, fc if fs is None else fs, result["viscous"],
                               1.0 if vs is None else vs)
        ax.plot(v, f, label="fitted Stribeck curve" if d > 0 else None, **TRACES["model"])
    ax.axhline(0, color="k", lw=0.6)
    ax.axvline(0, color="k", lw=0.6)
    ax.set_xlabel(axis_label("arm velocity", "rad/s"))
    ax.set_ylabel(axis_label("friction = k_u u", "m/s^2"))

    def fmt(x):
        return "-" if x is None else f"{x:.3g}"

    ax.legend()
    ax.grid(alpha=0.3)
    _finish(fig, title, f"Stribeck curve: F_C {fmt(fc)}, F_v {fmt(result['viscous'])}, "
                        f"v_S {fmt(vs)}, F_S {fmt(fs)}")
    return save_figure(fig, path)


def plot_free_oscillation(log, result: dict, path: str, title: str | None = None) -> str:
    """App. A / Figure 33: the damped oscillation with the used peaks and the
    fitted envelope."""
    t = np.asarray(log["t"])
    y = np.asarray(log["theta_m"])
    pk = np.array(result["peaks"])
    th0 = result["rest_angle"]
    fig, ax = plt.subplots(figsize=(9, 5))
    ax.plot(t, y, label="measured angle", **TRACES["measured"])
    ax.plot(pk[:, 0], th0 + pk[:, 1], ls="none", marker="o", color="C3", label="peaks used")
    for i, (tp, yp) in enumerate(pk, start=1):
        ax.annotate(str(i), (tp, th0 + yp), textcoords="offset points", xytext=(0, 5),
                    ha="center", fontsize=8)
    s = result["zeta"] * result["omega0"]
    tt = np.linspace(pk[0, 0], pk[-1, 0], 200)
    ax.plot(tt, th0 + pk[0, 1] * np.exp(-s * (tt - pk[0, 0])),
            label="fitted envelope $A e^{-\\zeta\\omega_0 t}$", **TRACES["model"])
    ax.axhline(th0, color="k", lw=0.6)
    ax.set_xlabel(axis_label("time", "s"))
    ax.set_ylabel(axis_label("pendulum angle", "rad"))
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    _finish(fig, title, f"free oscillation: omega0 {result['omega0']:.4g} rad/s, "
                        f"zeta {result['zeta']:.3g}")
    return save_figure(fig, path)


def plot_control_scaling(log, result: dict, path: str, title: str | None = None) -> str:
    """App. B.4 / Figure 37: arm velocity vs time for each constant u (solid,
    its own colour and marker), with the fitted acceleration lines (dashed)."""
    t = np.asarray(log["t"])
    u = np.asarray(log["u"])
    v = np.asarray(log["arm_dot_m"])
    fig, ax = plt.subplots(figsize=(8, 5.4))
    for i, row in enumerate(result["levels"]):
        sel = np.flatnonzero(u == row["u"])
        if len(sel) == 0:
            continue
        t0 = t[sel[0]]
        tt = t[sel] - t0
        st = series_style(i)
        every = max(1, len(tt) // 8)
        ax.plot(tt, v[sel], color=st["color"], ls="-", marker=st["marker"], ms=4,
                markevery=every, lw=1.0, label=f"u = {row['u']:g} m/s$^2$, measured")
        ax.plot(tt, np.sign(row["u"]) * row["acceleration"] * tt, color=st["color"], ls="--",
                marker=st["marker"], mfc="none", ms=4, markevery=(every // 2, every), lw=0.9,
                label=f"u = {row['u']:g} m/s$^2$, fitted")
    ax.set_xlabel(axis_label("time since u applied", "s"))
    ax.set_ylabel(axis_label("arm velocity", "rad/s"))
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    _finish(fig, title, f"control scaling: k_u = {result['input_gain']:.4g} "
                        f"(DAC scaling {result['u_scale']:.4g})")
    return save_figure(fig, path)
