"""``frictionlab reproduce``: every simulation study of the thesis, one report folder.

The studies, their settings and the report are :mod:`frictionlab.studies.reproduce`;
this module parses the command line, checks it before any work, shows
progress on stderr and prints the result (``--json``: the tables as data).
"""

from __future__ import annotations

import os
import sys
import time

from .common import UsageError, add_engine_args, check_engine_args, emit_json, progress_bar

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


def register_cli(sub) -> None:
    """Add ``frictionlab reproduce`` to the CLI's subparsers."""
    p = sub.add_parser(
        "reproduce", help="re-run every simulation study of the thesis into a report folder",
        description="Re-run the thesis's simulation studies with their published settings "
                    "(Tables 2-7, the omega0 studies of Sec. 5.2-5.3, Figs. 17-24) through "
                    "the sweep engine and write report.md, report.json and the figures to "
                    "--out.")
    p.add_argument("--out", default="reproduction", metavar="DIR",
                   help="report folder, created if missing (default: ./reproduction)")
    add_engine_args(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.add_argument("--json", action="store_true",
                   help='print one JSON object {"out", "seconds", "figures", "tables"}')
    p.set_defaults(func=cmd_reproduce)
