"""``frictionlab sweep``: parameter sweeps on the command line.

The sweep engine (points, backends, the crash-safe output file) is
:mod:`frictionlab.studies.sweep`; this module parses the command line, checks
everything before any work, drives the engine with a progress bar on stderr,
resumes interrupted sweeps, and presents the rows: ``--table`` (markdown
shaped like the thesis's Tables 2-7, :func:`markdown_table`) and ``--plot``
(each feature against the varied key, :func:`plot_sweep`).
"""

from __future__ import annotations

import math
import signal
import sys
import time
from collections.abc import Mapping, Sequence
from contextlib import closing
from typing import Any

from ..config import inert_keys
from ..model.limit_cycles import FEATURES
from ..studies.sweep import (
    MODES,
    STATUSES,
    SWINGUP_COLUMNS,
    OutputMismatch,
    SweepFile,
    get_dask,
    iter_evaluate,
    make_points,
    parse_vary,
    point_ident,
    reduce_swingup,
    validate_points,
)
from .common import (
    UsageError,
    add_config_args,
    add_engine_args,
    check_engine_args,
    check_output_path,
    check_window,
    config_from_args,
    emit_json,
    flush_notes,
    hanging_start,
    note,
    progress_bar,
)

__all__ = ["NOT_A_CYCLE_MARKER", "UNDEFINED_MARKERS", "markdown_table", "plot_sweep",
           "register_cli"]


# ---------------------------------------------------------------------------
# tables and plots
# ---------------------------------------------------------------------------

#: Table 2's columns after the varied key, with their headers.
TABLE_HEADERS = (("peak1", "peak1"), ("peak2", "peak2"), ("valley", "valley"),
                 ("period", "T"), ("max_u", "max(u)"), ("max_arm_velocity", "max(Ω̇)"))


def _cell(v: Any) -> str:
    return "-" if v is None else f"{v:#.3g}"


def _key_cell(v: Any) -> str:
    return "-" if v is None else f"{v:g}"


def _one_table(rows: Sequence[Mapping[str, Any]], keys: Sequence[str]) -> str:
    with_status = any(r["status"] != "limit_cycle" for r in rows)
    swing_up = any("caught" in r for r in rows)
    head = ([*keys, *(h for _, h in TABLE_HEADERS)] + (["caught", "swing_up_time"] if swing_up
                                                         else [])
            + (["status"] if with_status else []))
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for r in rows:
        cells = [_key_cell(r[k]) for k in keys] + [_cell(r[f]) for f, _ in TABLE_HEADERS]
        if swing_up:
            caught = r.get("caught")
            cells += ["-" if caught is None else ("yes" if caught else "no"),
                      _cell(r.get("swing_up_time"))]
        if with_status:
            cells.append(r["status"])
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _groups(rows: Sequence[Mapping[str, Any]], varies: Sequence[tuple[str, Sequence[float]]],
            mode: str, base_vals: Mapping[str, Any]) -> list[tuple[str, list]]:
    """(key, rows) per table/plot panel: one per key in ``oat`` mode, one in ``grid``."""
    if mode == "grid" or len(varies) == 1:
        return [(varies[0][0], list(rows))]
    keys = [k for k, _ in varies]
    by_ident = {point_ident(r, keys): r for r in rows}
    out = []
    for k, values in varies:
        grp = []
        for v in values:
            r = by_ident.get(point_ident({**base_vals, k: v}, keys))
            if r is not None:
                grp.append(r)
        out.append((k, grp))
    return out


def markdown_table(rows: Sequence[Mapping[str, Any]],
                   varies: Sequence[tuple[str, Sequence[float]]], mode: str = "grid",
                   base_vals: Mapping[str, Any] | None = None) -> str:
    """Markdown table(s) shaped like the thesis's Tables 2-7 (one parameter per table).

    Columns: the varied key(s), peak1, peak2, valley, T, max(u), max(Ω̇)
    (three significant digits; ``-`` where undefined), plus ``caught`` and
    ``swing_up_time`` (s) for a sweep with ``--swing-up`` and ``status`` when
    some row is not a limit cycle.  In ``oat`` mode with several keys, one
    table per key (blank line between), each with its own key column only.

    Parameters
    ----------
    rows : sequence of mappings
        Rows of :func:`frictionlab.studies.sweep.evaluate`, in sweep order.
    varies : sequence of (key, values)
        The sweep's keys and values (:func:`frictionlab.studies.sweep.parse_vary`).
    mode : {"grid", "oat"}
        The sweep's mode.
    base_vals : mapping, optional
        The keys' base values (``oat``: the other keys' values in each table).

    Returns
    -------
    str
        The table(s), without a trailing newline.
    """
    base_vals = base_vals or {}
    if mode == "grid" or len(varies) == 1:
        return _one_table(rows, [k for k, _ in varies])
    return "\n\n".join(_one_table(grp, [k]) for k, grp in
                       _groups(rows, varies, mode, base_vals))


#: Markers of the runs whose feature is undefined, drawn on the bottom edge of
#: a panel (by status), and of the runs that are not limit cycles but still
#: have a value (at the value).
UNDEFINED_MARKERS = {"fell": "v", "settled": "s", "limit_cycle": "d", "error": "X"}
NOT_A_CYCLE_MARKER = "x"


def plot_sweep(rows: Sequence[Mapping[str, Any]],
               varies: Sequence[tuple[str, Sequence[float]]], path: str, mode: str = "grid",
               base_vals: Mapping[str, Any] | None = None, base=None) -> str:
    """Each feature against the varied parameter, one subplot per feature.

    ``oat`` with several keys: one column of subplots per key.  ``grid`` with
    several keys: x is the first key, one line per combination of the others.
    A run whose feature is undefined (``None``, or any feature of a run that
    fell: its maxima are those of the fall, not of a cycle) has no point on
    the line, which breaks there; it is marked on the panel's bottom edge by
    its status (:data:`UNDEFINED_MARKERS`: a triangle for ``fell``), outside
    the data, so the y range is that of the defined values.  A run that
    settled but has a value is a cross at that value.  A legend at the bottom
    explains the markers.  Axes carry units (the key's and the feature's);
    several lines differ in colour, line style and marker; the title names
    the swept keys, the design and the fixed parameters of ``base``.

    Parameters
    ----------
    rows, varies, mode, base_vals
        As for :func:`markdown_table`.
    path : str
        Output file (``.png``, ``.pdf`` or ``.svg``); its path is printed on
        stderr.
    base : Config, optional
        The sweep's base configuration (for the title).

    Returns
    -------
    str
        ``path``.
    """
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from ..plotting import config_title, feature_label, key_label, save_figure, series_style

    base_vals = base_vals or {}
    keys = [k for k, _ in varies]
    groups = _groups(rows, varies, mode, base_vals)
    ncol = len(groups)
    fig, axes = plt.subplots(len(FEATURES), ncol, figsize=(4.2 * ncol + 1, 13), sharex="col",
                             squeeze=False, layout="constrained")
    used: set[str] = set()
    for col, (xkey, grp) in enumerate(groups):
        others = [k for k in keys if k != xkey] if mode == "grid" else []
        lines: dict[tuple, list] = {}
        for r in grp:
            lines.setdefault(tuple(r[k] for k in others), []).append(r)
        for j, feat in enumerate(FEATURES):
            ax = axes[j, col]
            edge = ax.get_xaxis_transform()  # x in data, y in axes coordinates
            for i, (combo, rs) in enumerate(lines.items()):
                rs = sorted(rs, key=lambda r: r[xkey])
                x = [r[xkey] for r in rs]
                y = [math.nan if r[feat] is None or r["status"] == "fell" else r[feat]
                     for r in rs]
                label = ", ".join(f"{k}={v:g}" for k, v in zip(others, combo, strict=True))
                ln, = ax.plot(x, y, ms=3, label=label or None, **series_style(i))
                color = ln.get_color()
                odd = [(a, b) for a, b, r in zip(x, y, rs, strict=True)
                       if r["status"] != "limit_cycle" and not math.isnan(b)]
                if odd:
                    used.add("odd")
                    ax.plot(*zip(*odd, strict=True), NOT_A_CYCLE_MARKER, color=color, ms=7)
                for status, marker in UNDEFINED_MARKERS.items():
                    xs = [a for a, b, r in zip(x, y, rs, strict=True)
                          if math.isnan(b) and r["status"] == status]
                    if xs:
                        used.add(status)
                        # stacked a little per line, so that lines' marks do not hide
                        ax.plot(xs, [0.04 * i] * len(xs), marker, color=color, ms=7,
                                transform=edge, clip_on=False)
            if all(r[feat] is None or r["status"] == "fell" for r in grp):
                ax.text(0.5, 0.5, "undefined for every run", transform=ax.transAxes,
                        ha="center", va="center", color="0.4")
                ax.set_yticks([])
            ax.set_ylabel(feature_label(feat) if col == 0 else "")
            ax.grid(alpha=0.3)
            if j == 0 and others and len(lines) <= 12:
                ax.legend(fontsize=7)
        axes[-1, col].set_xlabel(key_label(xkey))
    explain = {"odd": (NOT_A_CYCLE_MARKER, "not a limit cycle (value drawn)"),
               "fell": (UNDEFINED_MARKERS["fell"], "fell: no value (bottom edge)"),
               "settled": (UNDEFINED_MARKERS["settled"], "settled: no value (bottom edge)"),
               "limit_cycle": (UNDEFINED_MARKERS["limit_cycle"],
                               "limit cycle without this feature (bottom edge)"),
               "error": (UNDEFINED_MARKERS["error"], "error: no value (bottom edge)")}
    handles = [Line2D([], [], marker=m, ls="", color="0.3", ms=7, label=text)
               for k, (m, text) in explain.items() if k in used]
    width_in, _ = fig.get_size_inches()
    title = "sweep of " + ", ".join(keys)
    if base is not None:
        title = config_title(base, title, exclude=keys, width=int(12 * width_in))
    # constrained layout: the title above the panels, the marker legend below them
    fig.suptitle(title, fontsize=9)
    if handles:
        fig.legend(handles=handles, loc="outside lower center", ncol=min(3, len(handles)),
                   fontsize=8, frameon=False)
    return save_figure(fig, path, dpi=100)


# ---------------------------------------------------------------------------
# command line
# ---------------------------------------------------------------------------


def register_cli(sub) -> None:
    """Add ``frictionlab sweep`` to the CLI's subparsers."""
    p = sub.add_parser(
        "sweep", help="vary keys; one row of limit-cycle features per parameter set",
        description="Run the closed loop for every parameter set and reduce each run to its "
                    "limit-cycle features (the thesis's Tables 2-7).  Rows are written to "
                    "--out as they complete; --resume continues an interrupted sweep.")
    add_config_args(p)
    p.add_argument("--vary", action="append", default=[], metavar="KEY=V1,V2,...",
                   help="values of a key: a list V1,V2,... or START:STOP:N (N evenly spaced "
                        "values, both ends included); repeatable")
    p.add_argument("--mode", choices=MODES, default="grid",
                   help="grid: every combination (default); oat: one key at a time, the "
                        "others at their base values (the thesis's tables)")
    p.add_argument("--duration", type=float, default=None,
                   help="simulated time per run in s (default: sim.duration = 40)")
    p.add_argument("--window", type=float, default=None,
                   help="analyse the last S seconds of each run (default: the last half)")
    add_engine_args(p)
    p.add_argument("--chunk-size", type=int, default=None,
                   help="parameter sets per task (default: at most 50 and a quarter of a "
                        "worker's share, smaller at the end)")
    p.add_argument("--out", required=True, metavar="FILE",
                   help="results, FILE.csv (crash-safe, written as it goes) or FILE.parquet")
    p.add_argument("--resume", action="store_true",
                   help="keep the rows already in --out and run only the missing points")
    p.add_argument("--force", action="store_true", help="overwrite an existing --out")
    p.add_argument("--swing-up", action="store_true",
                   help="each point swings up from sim.initial_angle (pi = hanging unless "
                        "set) before balancing; adds the columns caught (1/0) and "
                        "swing_up_time (s), status not_caught when it never balanced")
    p.add_argument("--table", action="store_true",
                   help="print a markdown table shaped like the thesis's Tables 2-7 (on "
                        "stderr with --json)")
    p.add_argument("--plot", metavar="FILE.png", help="plot each feature against the key")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.add_argument("--json", action="store_true",
                   help='print one JSON object {"rows", "out", "seconds"}')
    p.set_defaults(func=cmd_sweep)


def _plan(args):
    """Everything checked before any work: (base, varies, points, duration, file,
    rows already in the file when resuming)."""
    base = hanging_start(args, config_from_args(args))
    if not args.vary:
        raise UsageError("a sweep needs at least one --vary KEY=V1,V2,... (or START:STOP:N)")
    varies = [parse_vary(v, args.plant) for v in args.vary]
    points = make_points(base, varies, args.mode)
    validate_points(base, points)
    for key in inert_keys(base, [k for k, _ in varies]):
        note(args, f"frictionlab sweep: note: varying {key} has no effect with the "
                   f"{base.friction_kind!r} plant friction and the "
                   f"{base.compensation_kind!r} compensator")
    keys = [k for k, _ in varies]
    if args.duration is not None:
        if "sim.duration" in keys:
            raise UsageError("give the run length either by --duration or by "
                             "--vary sim.duration, not both")
        try:
            base = base.with_values({"sim.duration": args.duration})
        except ValueError as exc:
            raise UsageError(f"--duration: {exc}") from None
    if "sim.duration" in keys:  # each point's own length: the window fits the shortest
        check_window(args.window, min(v for k, vals in varies if k == "sim.duration"
                                      for v in vals), "--vary sim.duration, shortest")
    else:
        check_window(args.window, base.sim.duration,
                     "--duration" if args.duration is not None else "sim.duration")
    check_engine_args(args)
    if args.chunk_size is not None and args.chunk_size < 1:
        raise UsageError(f"--chunk-size must be >= 1, got {args.chunk_size}")
    check_output_path(args.plot, (".png", ".pdf", ".svg"), "--plot")
    check_output_path(args.out, (".csv", ".parquet"), "--out")
    if args.resume and args.force:
        raise UsageError("--resume and --force exclude each other")
    # each point runs for its own sim.duration (varied, or the base's)
    duration = None if "sim.duration" in keys else base.sim.duration
    base_flat = base.as_flat_dict()
    meta = {"keys": keys, "mode": args.mode, "duration": duration, "window": args.window,
            "base": base_flat, "vary": {k: v for k, v in varies}}
    if args.swing_up:
        meta["swing_up"] = True
    out = SweepFile(args.out, keys, meta, SWINGUP_COLUMNS if args.swing_up else ())
    if out.exists() and not args.resume:
        if not args.force:
            raise UsageError(f"--out {args.out} exists; use --resume to continue it or "
                             "--force to overwrite it")
    try:
        old = out.load() if args.resume else []  # a file that does not match exits 2 here
    except OutputMismatch as exc:
        raise UsageError(f"--resume: {exc} (use another --out, or --force to overwrite)"
                         ) from None
    if args.dask is not None and points:
        get_dask(args.dask, args.workers)  # an unreachable scheduler exits 2 before any output
    flush_notes(args)
    return base, varies, points, duration, out, old


def cmd_sweep(args) -> int:
    """``frictionlab sweep``."""
    t0 = time.perf_counter()
    base, varies, points, duration, out, old = _plan(args)
    keys = [k for k, _ in varies]
    if args.force:
        out.remove()
    have: dict[tuple, dict] = {}
    for r in old:
        have[point_ident(r, keys)] = r  # a later row for the same point wins
    todo = [i for i, p in enumerate(points)
            if have.get(point_ident(p, keys), {}).get("status", "error") == "error"]
    results: dict[int, dict] = {}

    def on_term(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, on_term)
    out.open()
    done = len(points) - len(todo)
    try:
        with progress_bar(f"sweep {len(points)} points", not args.no_progress) as upd:
            upd(done / len(points))
            with closing(iter_evaluate(base, [points[i] for i in todo], duration=duration,
                                       window=args.window, workers=args.workers,
                                       dask=args.dask, chunk_size=args.chunk_size,
                                       reduce=reduce_swingup if args.swing_up else None)
                         ) as chunks:
                for idx, rows in chunks:
                    out.append(rows)
                    for j, row in zip(idx, rows, strict=True):
                        results[todo[j]] = row
                    done += len(idx)
                    upd(done / len(points))
    except KeyboardInterrupt:
        out.close()
        print(f"frictionlab sweep: interrupted with {done} of {len(points)} points in "
              f"{out.journal}; rerun with --resume to finish", file=sys.stderr)
        raise
    finally:
        signal.signal(signal.SIGTERM, previous)
    ordered = [results[i] if i in results else have[point_ident(p, keys)]
               for i, p in enumerate(points)]
    wanted = {point_ident(p, keys) for p in points}
    extra = [r for ident, r in have.items() if ident not in wanted]
    out.finish(ordered + extra)
    base_vals = {k: base.get(k) for k in keys}
    table = markdown_table(ordered, varies, args.mode, base_vals) if args.table else None
    if args.plot:
        plot_sweep(ordered, varies, args.plot, args.mode, base_vals, base)
    counts = {s: sum(r["status"] == s for r in ordered + extra) for s in STATUSES}
    result = {"rows": len(ordered) + len(extra), "out": args.out,
              "seconds": round(time.perf_counter() - t0, 3)}
    if table is not None:
        # stdout is the table, or with --json the JSON object alone
        print(table, file=sys.stderr if args.json else sys.stdout)
    print(f"frictionlab sweep: {result['rows']} rows in {args.out} ({len(todo)} computed, "
          f"{len(points) - len(todo)} resumed) in {result['seconds']:.1f} s; "
          + ", ".join(f"{s}: {c}" for s, c in counts.items() if c)
          + (f"; plot {args.plot}" if args.plot else ""), file=sys.stderr)
    if args.json:
        emit_json(result)
    return 0
