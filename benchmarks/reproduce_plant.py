r"""``frictionlab reproduce --plant NAME`` benchmark: the thesis's study on a motor plant.

Measures, for ``--plant`` (default qube2):

* ``wall_s`` - the command ``frictionlab reproduce --plant NAME --out DIR --json``
  as a user runs it (a fresh process: imports, numba's on-disk cache, the
  runs through the sweep engine on every core, the figures, the report),
  minimum over ``--repeats``;
* ``runs_s``, ``report_s`` - in this process, after a warm-up:
  :func:`frictionlab.studies.plant_study.run` (every closed-loop run with its
  predictions) and :func:`frictionlab.studies.plant_report.write_report` (the
  report and the four figures);
* ``predict_share`` - the share of one worker's CPU time the predictions take
  (periodic orbit and describing function of one table row against its 40 s
  run, the preset's row of Table 2).

The machine's load average is printed before and after (other jobs on a
shared machine slow every figure down).  The last printed line is a JSON object.

Usage::

    .venv/bin/python benchmarks/reproduce_plant.py [--plant qube2] [--repeats 1]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _cli() -> list[str]:
    exe = Path(sys.executable).with_name("frictionlab")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "frictionlab"]


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plant", default="qube2")
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args(argv)

    from frictionlab.runs import simulate_config
    from frictionlab.studies.plant_report import write_report
    from frictionlab.studies.plant_study import count_runs, run, study
    from frictionlab.studies.predict import predict

    load0 = os.getloadavg()
    walls, reported = [], []
    for _ in range(args.repeats):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            proc = subprocess.run([*_cli(), "reproduce", "--plant", args.plant, "--out", tmp,
                                   "--json", "--no-progress"],
                                  capture_output=True, text=True, check=True)
            walls.append(time.perf_counter() - t0)
            reported.append(json.loads(proc.stdout)["seconds"])
    st = study(args.plant)
    runs_s, report_s = [], []
    for _ in range(args.repeats):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            results = run(st)
            t1 = time.perf_counter()
            write_report(results, tmp, t1 - t0)
            runs_s.append(t1 - t0)
            report_s.append(time.perf_counter() - t1)
    cfg = st.tables[0].setting.config()
    simulate_config(cfg, st.duration)
    predict(cfg)  # warm
    c0 = time.process_time()
    simulate_config(cfg, st.duration)
    c1 = time.process_time()
    predict(cfg)
    c2 = time.process_time()
    out = {"plant": args.plant, "runs": count_runs(st), "wall_s": round(min(walls), 2),
           "seconds": reported[walls.index(min(walls))], "runs_s": round(min(runs_s), 2),
           "report_s": round(min(report_s), 2),
           "predict_share": round((c2 - c1) / (c2 - c0), 3),
           "cpus": os.cpu_count(), "load_before": [round(x, 2) for x in load0],
           "load_after": [round(x, 2) for x in os.getloadavg()]}
    print(f"reproduce --plant {args.plant}: {out['runs']} runs; command {out['wall_s']} s "
          f"wall (reports {out['seconds']} s); in-process runs {out['runs_s']} s, report "
          f"{out['report_s']} s; predictions {100 * out['predict_share']:.0f} % of a row's "
          f"CPU; load {load0[0]:.1f} -> {out['load_after'][0]:.1f}")
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
