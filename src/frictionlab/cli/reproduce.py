"""``frictionlab reproduce``: every simulation study of the thesis, one report folder.

The studies, their settings and the report are :mod:`frictionlab.studies.reproduce`
(with ``--plant NAME`` for a motor plant: :mod:`frictionlab.studies.plant_study` and
:mod:`frictionlab.studies.plant_report`); this module parses the command line,
checks it before any work, shows progress on stderr and prints the result
(``--json``: the tables as data).
"""

from __future__ import annotations

import os
import sys
import time

from ..config import PLANT_NAMES
from .common import (
    UsageError,
    add_engine_args,
    check_engine_args,
    emit_json,
    progress_bar,
)

__all__ = ["register_cli"]


def cmd_reproduce(args) -> int:
    """``frictionlab reproduce``."""
    from ..studies.reproduce import count_runs, interface_json, run, write_report
    from ..studies.sweep import get_dask

    t0 = time.perf_counter()
    out = args.out
    if os.path.exists(out) and not os.path.isdir(out):
        raise UsageError(f"--out {out}: exists and is not a folder")
    parent = os.path.dirname(os.path.abspath(out))
    if not os.path.isdir(parent):
        raise UsageError(f"--out {out}: folder {parent} does not exist")
    check_engine_args(args)
    if args.dask is not None:
        get_dask(args.dask, args.workers)  # an unreachable scheduler exits 2 before any work
    os.makedirs(out, exist_ok=True)
    if args.plant != "thesis":
        return _reproduce_plant(args, t0)
    runs = count_runs()
    n_figures = 10
    with progress_bar(f"reproduce: {runs} runs, {n_figures} figures",
                      not args.no_progress) as update:
        results = run(args.workers, args.dask,
                      progress=lambda done, total: update(done / (total + n_figures)))
        computed = time.perf_counter() - t0
        figures = write_report(results, out, computed,
                               progress=lambda done, total: update((runs + done)
                                                                   / (runs + total)))
    seconds = time.perf_counter() - t0
    failed = [f"Table {n}, {r['key']} = {r['value']:g}: {r['error']}"
              for n, rows in results.tables.items() for r in rows if r["status"] == "error"]
    failed += [f"{case.label}: {row['error']}" for case, row in results.cases
               if row["status"] == "error"]
    if failed:
        print("frictionlab reproduce: warning: runs failed: " + "; ".join(failed),
              file=sys.stderr)
    print(f"frictionlab reproduce: {runs} runs on {results.workers} worker(s), report "
          f"{os.path.join(out, 'report.md')} and {len(figures)} figures in {seconds:.1f} s",
          file=sys.stderr)
    result = interface_json(results, out, seconds, figures)
    if args.json:
        emit_json(result)
    else:
        for number, rows in result["tables"].items():
            print(f"Table {number}: {len(rows)} rows")
        print(f"report: {os.path.join(out, 'report.md')}")
    return 0


def _reproduce_plant(args, t0: float) -> int:
    """``frictionlab reproduce --plant NAME``: the thesis's study on a motor plant."""
    from ..studies.plant_report import FIGURES, write_report
    from ..studies.plant_study import count_runs, interface_json, run, study

    st = study(args.plant)
    runs = count_runs(st)
    n_figures = len(FIGURES)
    with progress_bar(f"reproduce --plant {args.plant}: {runs} runs, {n_figures} figures",
                      not args.no_progress) as update:
        results = run(st, args.workers, args.dask,
                      progress=lambda done, total: update(done / (total + n_figures)))
        computed = time.perf_counter() - t0
        figures = write_report(results, args.out, computed,
                               progress=lambda done, total: update((runs + done)
                                                                   / (runs + total)))
    seconds = time.perf_counter() - t0
    failed = [f"Table {n}, {r['key']} = {r['value']:g}: {r['error']}"
              for n, rows in results.tables.items() for r in rows if r["status"] == "error"]
    failed += [f"{r['design']} design, {r['friction']} friction, F_C {r['coulomb']:g} V, "
               f"{r['compensation']}: {r['error']}"
               for r in results.compensators if r["status"] == "error"]
    if failed:
        print("frictionlab reproduce: warning: runs failed: " + "; ".join(failed),
              file=sys.stderr)
    report = os.path.join(args.out, "report.md")
    print(f"frictionlab reproduce: {runs} runs of the plant {args.plant} on {results.workers} "
          f"worker(s), report {report} and {len(figures)} figures in {seconds:.1f} s",
          file=sys.stderr)
    result = interface_json(results, args.out, seconds, figures)
    if args.json:
        emit_json(result)
    else:
        for number, rows in result["tables"].items():
            print(f"Table {number}: {len(rows)} rows")
        print(f"report: {report}")
    return 0


def register_cli(sub) -> None:
    """Add ``frictionlab reproduce`` to the CLI's subparsers."""
    p = sub.add_parser(
        "reproduce", help="re-run every simulation study of the thesis into a report folder",
        description="Re-run the thesis's simulation studies with their published settings "
                    "(Tables 2-7, the omega0 studies of Sec. 5.2-5.3, Figs. 17-24) through "
                    "the sweep engine and write report.md, report.json and the figures to "
                    "--out.  With --plant qube2|qube3|furuta-dc: the same study on the "
                    "motor plant (docs/qube.md).")
    p.add_argument("--out", default="reproduction", metavar="DIR",
                   help="report folder, created if missing (default: ./reproduction)")
    p.add_argument("--plant", choices=PLANT_NAMES, default="thesis",
                   help="'thesis' (default): the thesis's studies; a motor plant (qube2, "
                        "qube3, furuta-dc): the same study on it, in volts: the limit cycle "
                        "against F_C and F_S, its predictions and the compensators "
                        "(docs/qube.md)")
    add_engine_args(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.add_argument("--json", action="store_true",
                   help='print one JSON object {"out", "seconds", "figures", "tables"} (with '
                        'a motor --plant also "plant" and "compensators")')
    p.set_defaults(func=cmd_reproduce)
