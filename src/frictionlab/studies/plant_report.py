"""The report of the thesis's study on a motor plant: ``report.md``, ``report.json``
and the figures (``frictionlab reproduce --plant NAME``).

The runs are :mod:`frictionlab.studies.plant_study`'s; this module turns them
into tables, checked findings and four figures, each named after the plant
(``qube2_cycle.png``, ``qube2_tables.png``, ``qube2_predictions.png``,
``qube2_compensators.png``).
"""

from __future__ import annotations

import itertools
import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from ..io.jsonsafe import json_safe
from ..plotting import axis_label, plt, save_figure, series_style
from .plant_study import TABLE_COLUMNS, PlantResults, count_runs

__all__ = ["FIGURES", "counts", "degrees", "findings", "write_report"]

#: The figures, by file-name suffix, in the order written.
FIGURES = ("cycle", "tables", "predictions", "compensators")


def degrees(rad: float | None) -> float | None:
    """Radians to degrees (None stays None)."""
    return None if rad is None else math.degrees(rad)


def counts(rad: float | None, per_rev: int) -> float | None:
    """Radians to encoder counts at ``per_rev`` counts per revolution."""
    return None if rad is None else rad * per_rev / (2.0 * math.pi)


def _f(v: float | None, spec: str = "#.3g") -> str:
    return "-" if v is None else format(v, spec)


def _rel(a: float | None, b: float | None) -> float | None:
    if a is None or b is None or b == 0:
        return None
    return (a - b) / abs(b)


def _pct(r: float | None) -> str:
    return "-" if r is None else f"{100 * r:+.1f} %"


def _encoder(results: PlantResults) -> int:
    st = results.study
    return int(st.tables[0].setting.config().plant.pendulum_counts)


def _cycle_rows(rows: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    return [r for r in rows if r["status"] == "limit_cycle"]


def findings(results: PlantResults) -> list[tuple[str, str, bool | None]]:
    """The study's statements with their numbers: (statement, numbers, holds).

    ``holds`` is None where the statement only reports numbers.
    """
    out: list[tuple[str, str, bool | None]] = []
    per = _encoder(results)
    tabs = results.tables
    if "2" in tabs:
        rows = _cycle_rows(tabs["2"])
        p1 = [r["peak1"] for r in rows]
        grows = len(p1) > 1 and all(b > a for a, b in itertools.pairwise(p1))
        out.append(("fast design, classical friction: peak1 grows with F_C (Table 2)",
                    "peak1 " + " / ".join(_f(v) for v in p1) + " rad over F_C "
                    + " / ".join(f"{r['value']:g}" for r in rows) + " V", grows))
        per_s = [r["period"] for r in rows]
        if per_s:
            span = (max(per_s) - min(per_s)) / float(np.mean(per_s))
            out.append(("fast design, classical friction: the period hardly moves with F_C",
                        f"period {_f(min(per_s))} .. {_f(max(per_s))} s "
                        f"({100 * span:.0f} % of its mean)", span < 0.25))
        fc0 = results.study.figure_fc
        nom = next((r for r in rows if r["value"] == fc0), None)
        if nom is not None:
            ptp = nom["peak_to_peak"]
            out.append(("the cycle at the preset's levels in degrees and encoder counts",
                        f"pendulum peak-to-peak {_f(ptp)} rad = {_f(degrees(ptp))} deg = "
                        f"{_f(counts(ptp, per))} counts ({per}/rev); arm peak-to-peak "
                        f"{_f(degrees(nom.get('arm_peak_to_peak')))} deg; max |u| "
                        f"{_f(nom['max_u'])} V", None))
    if "3" in tabs:
        rows = _cycle_rows(tabs["3"])
        p1 = [r["peak1"] for r in rows]
        if p1:
            span = (max(p1) - min(p1)) / float(np.mean(p1))
            out.append(("fast design, classical friction: F_S hardly changes the cycle "
                        "(Table 3)", f"peak1 {_f(min(p1))} .. {_f(max(p1))} rad over F_S "
                        f"{rows[0]['value']:g} .. {rows[-1]['value']:g} V", span < 0.1))
    for number in ("4", "5", "8", "9"):
        if number not in tabs:
            continue
        rows = tabs[number]
        fell = [r["value"] for r in rows if r["status"] == "fell"]
        ok = [r["value"] for r in rows if r["status"] == "limit_cycle"]
        key = rows[0]["key"].split(".")[1] if rows else ""
        name = "F_C" if key == "coulomb" else "F_S"
        out.append((f"Table {number}: where the slow design still balances",
                    (f"limit cycle up to {name} = {max(ok):g} V" if ok else "no limit cycle")
                    + (f", falls from {min(fell):g} V" if fell else ", never falls"), None))
    if results.study.predict:
        for design, numbers in (("fast", ("2", "3", "6", "7")), ("slow", ("4", "5", "8", "9"))):
            cyc = [r for n in numbers if n in tabs for r in _cycle_rows(tabs[n])]
            if not cyc:
                continue
            stable = [r for r in cyc if r["orbit"]["found"] and r["orbit"]["stable"]]
            errs = [abs(_rel(r["orbit"]["period"], r["period"])) for r in stable]
            close = sum(e <= 0.02 for e in errs)
            text = (f"{len(cyc)} simulated cycles: a stable orbit found for {len(stable)}, "
                    f"its period within 2 % of the simulation's for {close}")
            if errs:
                text += (f" (median error {100 * float(np.median(errs)):.1f} %, largest "
                         f"{100 * max(errs):.0f} %)")
            out.append((f"the periodic orbit predicts the period, {design} design", text,
                        bool(stable) and close == len(stable) if design == "fast" else None))
            e = [_rel(r["describing_function"]["period"], r["period"]) for r in cyc]
            e = [x for x in e if x is not None]
            if e:
                out.append((f"the describing function's period, {design} design",
                            f"off by {_pct(min(e))} .. {_pct(max(e))} over {len(e)} cycles",
                            None))
    comp = [r for r in results.compensators if r["design"] == "fast"
            and r["coulomb"] == results.study.figure_fc and r["compensation"] != "none"]
    for friction in results.study.compensator_frictions:
        rs = [r for r in comp if r["friction"] == friction]
        if rs:
            best = max(rs, key=lambda r: r["reduction"] or 0.0)
            out.append((f"compensators at the preset's levels, {friction} plant friction: "
                        "shrink factors", ", ".join(f"{r['compensation']} {_f(r['reduction'])}"
                                                    for r in rs)
                        + f"; best {best['compensation']}", None))
    return out


def _table_md(rows: Sequence[Mapping[str, Any]], per: int, predict: bool) -> list[str]:
    heads = ["value (V)", "status", "peak1 (rad)", "peak2 (rad)", "valley (rad)", "T (s)",
             "max \\|u\\| (V)", "max \\|Ω̇\\| (rad/s)", "peak-to-peak (deg, counts)"]
    if predict:
        heads += ["orbit T (s)", "orbit peak1 (rad)", "DF T (s)", "DF 1st harm. (rad)",
                  "sim. 1st harm. (rad)"]
    lines = ["| " + " | ".join(heads) + " |", "|---" * len(heads) + "|"]
    for r in rows:
        ptp = r.get("peak_to_peak") if r["status"] == "limit_cycle" else None
        cells = [f"{r['value']:g}", r["status"] + (f": {r['error']}" if r.get("error") else "")]
        cells += [_f(r.get(c)) for c in TABLE_COLUMNS[:-1]]
        cells.append("-" if ptp is None else f"{_f(degrees(ptp))}, {counts(ptp, per):.0f}")
        if predict:
            o = r.get("orbit") or {}
            d = r.get("describing_function") or {}
            orbit_t = _f(o.get("period")) + ("" if o.get("stable") in (None, True)
                                              else " (unstable)")
            cells += [orbit_t if o.get("found") else "not found", _f(o.get("peak1")),
                      _f(d.get("period")), _f(d.get("pendulum_amplitude")),
                      _f(r.get("fundamental"))]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _comp_md(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    lines = ["| design | plant friction | F_C (V) | compensator | status | peak-to-peak (rad) | "
             "shrink factor | max \\|u\\| (V) | estimate's sign reversals per s |",
             "|---" * 9 + "|"]
    for r in rows:
        lines.append(f"| {r['design']} | {r['friction']} | {r['coulomb']:g} | "
                     f"{r['compensation']} | {r['status']} | {_f(r.get('peak_to_peak'))} | "
                     f"{_f(r.get('reduction'))} | {_f(r.get('max_u'))} | "
                     f"{_f(r.get('reversals_per_s'))} |")
    return lines


def _report_md(results: PlantResults, seconds: float, figures: Sequence[str]) -> str:
    st = results.study
    per = _encoder(results)
    lines = [
        f"# The thesis's limit-cycle study on the plant {st.plant}",
        "",
        f"`frictionlab reproduce --plant {st.plant}`: {count_runs(st)} closed-loop runs on "
        f"{results.workers} worker(s) in {seconds:.1f} s.  Each run lasts {st.duration:g} s; "
        "the features are measured on the measured pendulum angle over the last half.  "
        "u is the motor voltage and every friction level is in volts.  Peak-to-peak "
        f"angles are also given in degrees and in pendulum encoder counts ({per}/rev).  "
        "`report.json` holds every row with the `frictionlab simulate` command that "
        "repeats it.",
        "",
        "## Findings",
        "",
        "| statement | numbers | holds |",
        "|---|---|---|",
    ]
    for text, found, holds in findings(results):
        mark = "-" if holds is None else ("yes" if holds else "**no**")
        lines.append(f"| {text} | {found} | {mark} |")
    for table in st.tables:
        lines += ["", f"## Table {table.number}: {table.title}", "",
                  f"Base: `{table.setting.command()}`.", ""]
        lines += _table_md(results.tables[table.number], per, st.predict)
    lines += ["", "## Compensators", "",
              "Each compensator's levels are the plant's (`compensation.coulomb`, "
              "`compensation.stiction` = the plant's F_C, F_S); the shrink factor is the "
              "uncompensated peak-to-peak over the compensated one.", ""]
    lines += _comp_md([r for r in results.compensators if r["compensation"] != "none"])
    lines += ["", "## Figures", ""]
    for path in figures:
        lines += [f"![{os.path.basename(path)}]({os.path.basename(path)})", ""]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------
# figures
# ---------------------------------------------------------------------------


def _plot_limit_cycle(results: PlantResults, path: str) -> str | None:
    st = results.study
    runs = {r["friction"]: r for r in results.compensators
            if r["design"] == "fast" and r["coulomb"] == st.figure_fc
            and r["compensation"] == "none" and "trace" in r}
    if not runs:
        return None
    per = _encoder(results)
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.2), layout="constrained")
    for i, (friction, r) in enumerate(sorted(runs.items())):
        tr = r["trace"]
        t = np.asarray(tr["t"]) - tr["t"][0]
        style = {**series_style(i), "marker": None, "lw": 1.3}
        label = f"{friction} friction (T {_f(r['period'])} s)"
        axes[0, 0].plot(t, tr["theta_m"], label=label, **style)
        axes[1, 0].plot(t, tr["u"], label=label, **style)
        axes[0, 1].plot(tr["theta"], tr["theta_dot"], label=label, **style)
        axes[1, 1].plot(t, np.degrees(np.asarray(tr["arm"]) - np.mean(tr["arm"])),
                        label=label, **style)
    axes[0, 0].set_ylabel(axis_label(r"measured pendulum angle $\theta$", "rad"))
    sec = axes[0, 0].secondary_yaxis(
        "right", functions=(lambda x: x * per / (2 * np.pi), lambda c: c * 2 * np.pi / per))
    sec.set_ylabel(axis_label("encoder", "counts"))
    axes[1, 0].set_ylabel(axis_label("motor voltage u", "V"))
    axes[0, 1].set_xlabel(axis_label(r"pendulum angle $\theta$ (true)", "rad"))
    axes[0, 1].set_ylabel(axis_label(r"$\dot\theta$", "rad/s"))
    axes[0, 1].set_title("phase portrait", fontsize=10)
    axes[1, 1].set_ylabel(axis_label("arm angle about its mean", "deg"))
    for ax in (axes[0, 0], axes[1, 0], axes[1, 1]):
        ax.set_xlabel(axis_label("time", "s"))
    for ax in axes.flat:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
    fs = next(iter(runs.values()))["stiction"]
    fig.suptitle(f"{st.plant}: the friction limit cycle, fast design, F_S {fs:g} V, "
                 f"F_C {st.figure_fc:g} V, the last cycles of a {st.duration:g} s run",
                 fontsize=10)
    return save_figure(fig, path)


def _plot_tables(results: PlantResults, path: str) -> str:
    st = results.study
    per = _encoder(results)
    fig, axes = plt.subplots(2, 3, figsize=(14, 7.6), layout="constrained")
    cols = (("peak_to_peak", "pendulum peak-to-peak", "rad"), ("period", "period", "s"),
            ("max_u", "max |u|", "V"))
    for row_i, key in enumerate(("friction.coulomb", "friction.stiction")):
        tabs = [t for t in st.tables if t.varies[0][0] == key]
        for i, table in enumerate(tabs):
            rows = results.tables[table.number]
            x = [r["value"] for r in rows]
            fixed = dict(table.setting.sets)
            other = "friction.stiction" if key == "friction.coulomb" else "friction.coulomb"
            name = "F_S" if other == "friction.stiction" else "F_C"
            label = (f"T{table.number}: {table.setting.design}, {table.setting.friction} "
                     f"({name} {fixed[other]:g} V)")
            for col_i, (c, _q, _u) in enumerate(cols):
                y = [r.get(c) if r["status"] == "limit_cycle" else None for r in rows]
                y = [np.nan if v is None else v for v in y]
                axes[row_i, col_i].plot(x, y, label=label, mfc="none", **series_style(i))
                fell = [xv for xv, r in zip(x, rows, strict=True) if r["status"] == "fell"]
                if fell:
                    axes[row_i, col_i].plot(fell, [0.0] * len(fell), "x",
                                            color=series_style(i)["color"], ms=8)
        for col_i, (_c, q, u) in enumerate(cols):
            ax = axes[row_i, col_i]
            ax.set_xlabel(axis_label("F_C" if key == "friction.coulomb" else "F_S", "V"))
            ax.set_ylabel(axis_label(q, u))
            ax.grid(alpha=0.3)
        axes[row_i, 0].secondary_yaxis(
            "right", functions=(lambda x: x * per / (2 * np.pi), lambda c: c * 2 * np.pi / per)
        ).set_ylabel(axis_label("encoder", "counts"))
        if tabs:
            axes[row_i, 2].legend(fontsize=7, loc="upper left")
    fig.suptitle(f"{st.plant}: the limit cycle against the friction levels (Tables 2-9; "
                 "x on the axis: the pendulum fell)", fontsize=10)
    return save_figure(fig, path)


def _plot_predictions(results: PlantResults, path: str) -> str:
    from matplotlib.lines import Line2D

    st = results.study
    fig, axes = plt.subplots(2, 2, figsize=(12, 7.6), layout="constrained")

    def pick(rows, f):
        return [np.nan if f(r) is None else f(r) for r in rows]

    def orbit(r, name):
        return r["orbit"][name] if r["orbit"]["found"] else None

    for col, key in enumerate(("friction.coulomb", "friction.stiction")):
        tabs = [t for t in st.tables if t.varies[0][0] == key]
        for i, table in enumerate(tabs):
            rows = [r for r in results.tables[table.number] if r["status"] == "limit_cycle"]
            if not rows:
                continue
            x = [r["value"] for r in rows]
            s = series_style(i)
            name = f"T{table.number}: {table.setting.design}, {table.setting.friction}"
            ax = axes[0, col]
            ax.plot(x, pick(rows, lambda r: r["period"]), s["marker"], color=s["color"],
                    mfc="none", ls="none", label=name)
            ax.plot(x, pick(rows, lambda r: orbit(r, "period")), color=s["color"], ls="-",
                    lw=1.0)
            ax.plot(x, pick(rows, lambda r: r["describing_function"]["period"]),
                    color=s["color"], ls="-.", lw=1.0)
            ax = axes[1, col]
            ax.plot(x, pick(rows, lambda r: r["fundamental"]), s["marker"], color=s["color"],
                    mfc="none", ls="none")
            ax.plot(x, pick(rows, lambda r: r["describing_function"]["pendulum_amplitude"]),
                    color=s["color"], ls="-.", lw=1.0)
            ax.plot(x, pick(rows, lambda r: r["peak1"]), s["marker"], color=s["color"],
                    ls="none", ms=3)
            ax.plot(x, pick(rows, lambda r: orbit(r, "peak1")), color=s["color"], ls="-",
                    lw=1.0)
        sym = "F_C" if key == "friction.coulomb" else "F_S"
        axes[0, col].set_ylabel(axis_label("period", "s"))
        axes[1, col].set_ylabel(axis_label("pendulum amplitude", "rad"))
        for ax in axes[:, col]:
            ax.set_xlabel(axis_label(sym, "V"))
            ax.grid(alpha=0.3)
        if axes[0, col].get_legend_handles_labels()[0]:
            axes[0, col].legend(fontsize=7, loc="upper right")
    k = {"color": "k", "lw": 1.0}
    axes[0, 0].legend(handles=[
        *axes[0, 0].get_legend_handles_labels()[0],
        Line2D([], [], marker="o", mfc="none", ls="none", color="k", label="simulated"),
        Line2D([], [], ls="-", label="periodic orbit", **k),
        Line2D([], [], ls="-.", label="describing function", **k)], fontsize=7,
        loc="upper right")
    axes[1, 0].legend(handles=[
        Line2D([], [], marker="o", mfc="none", ls="none", color="k",
               label="simulated 1st harmonic"),
        Line2D([], [], ls="-.", label="describing function (1st harmonic)", **k),
        Line2D([], [], marker="o", ms=3, ls="none", color="k", label="simulated peak1"),
        Line2D([], [], ls="-", label="periodic orbit peak1", **k)], fontsize=7,
        loc="upper left")
    fig.suptitle(f"{st.plant}: the predictions against the simulation: period (top) and "
                 "pendulum amplitude (bottom)", fontsize=10)
    return save_figure(fig, path)


def _plot_compensators(results: PlantResults, path: str) -> str:
    st = results.study
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13, 4.8), layout="constrained")
    runs = [r for r in results.compensators
            if r["design"] == "fast" and r["friction"] == st.compensator_frictions[0]
            and r["coulomb"] == st.figure_fc and "trace" in r]
    for i, r in enumerate(runs):
        tr = r["trace"]
        t = np.asarray(tr["t"]) - tr["t"][0]
        m = t <= 4.0
        style = {**series_style(i), "marker": None}
        ax.plot(t[m], np.asarray(tr["theta_m"])[m], lw=1.4 if i == 0 else 1.1,
                label=f"{r['compensation']}: peak-to-peak {_f(r['peak_to_peak'])} rad", **style)
    ax.set_xlabel(axis_label("time", "s"))
    ax.set_ylabel(axis_label(r"measured pendulum angle $\theta$", "rad"))
    ax.set_title(f"fast design, {st.compensator_frictions[0]} plant friction, "
                 f"F_C {st.figure_fc:g} V", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")
    for j, friction in enumerate(st.compensator_frictions):
        for i, comp in enumerate(st.compensators):
            rs = [r for r in results.compensators if r["design"] == "fast"
                  and r["friction"] == friction and r["compensation"] == comp]
            x = [r["coulomb"] for r in rs]
            y = [np.nan if r["reduction"] is None else r["reduction"] for r in rs]
            s = series_style(i + 1)
            bx.semilogy(x, y, color=s["color"], marker=s["marker"], mfc="none",
                        ls="-" if j == 0 else "--", label=f"{comp}, {friction} plant")
    bx.axhline(1.0, color="k", lw=0.8)
    bx.set_xlabel(axis_label("plant F_C (F_S fixed, compensator matched)", "V"))
    bx.set_ylabel(axis_label("shrink factor: peak-to-peak without / with", "1"))
    bx.set_title("shrink factor (fast design; missing: the pendulum fell)", fontsize=10)
    bx.grid(alpha=0.3, which="both")
    bx.legend(fontsize=7, ncol=2)
    fig.suptitle(f"{st.plant}: the compensators of Sec. 6 on the motor plant", fontsize=10)
    return save_figure(fig, path)


def write_report(results: PlantResults, out: str, seconds: float,
                 progress: Callable[[int, int], None] | None = None) -> list[str]:
    """Write ``report.md``, ``report.json`` and the figures into the folder ``out``.

    Parameters
    ----------
    results : PlantResults
    out : str
        An existing folder; files of the same names are replaced.
    seconds : float
        Time the runs took (stated in the report).
    progress : callable, optional
        ``progress(done, total)`` in figures.

    Returns
    -------
    list of str
        The figure paths, in the order of :data:`FIGURES`.
    """
    plant = results.study.plant
    plots = {"cycle": _plot_limit_cycle, "tables": _plot_tables,
             "predictions": _plot_predictions, "compensators": _plot_compensators}
    if not results.study.predict:
        del plots["predictions"]
    figures = []
    for i, (name, plot) in enumerate(plots.items()):
        path = plot(results, os.path.join(out, f"{plant}_{name}.png"))
        if path is not None:
            figures.append(path)
        if progress is not None:
            progress(i + 1, len(plots))
    with open(os.path.join(out, "report.md"), "w", encoding="utf-8") as fh:
        fh.write(_report_md(results, seconds, figures))
    data = {
        "plant": plant,
        "duration": results.study.duration,
        "tables": {t.number: {"title": t.title, "base": t.setting.command(),
                              "rows": results.tables[t.number]}
                   for t in results.study.tables},
        "compensators": [{k: v for k, v in r.items() if k != "trace"}
                         for r in results.compensators],
        "findings": [{"statement": s, "numbers": f, "holds": h}
                     for s, f, h in findings(results)],
        "figures": figures,
    }
    with open(os.path.join(out, "report.json"), "w", encoding="utf-8") as fh:
        json.dump(json_safe(data), fh, indent=1)
        fh.write("\n")
    return figures

