r"""The thesis's numbers (issue: shallow peaks, shoulders, Table 1): what
``frictionlab reproduce`` finds, counted.

Prints, from one :func:`frictionlab.studies.reproduce.run`:

* ``tables_2_3_worst`` - the largest relative difference of any feature of
  Tables 2-3 from the thesis;
* ``lugre_rows`` / ``lugre_rows_with_peak2`` / ``lugre_rows_with_valley`` /
  ``lugre_shoulders`` - Tables 6-7: rows, rows that have a ``peak2``, a
  ``valley``, and a ``peak2`` without ``valley`` (a shoulder); and
  ``lugre_rows_with_two_maxima_at_2pct``, the rows with two maxima of at
  least 2 % prominence, the former definition (which had no shoulders: its
  rows had both ``peak2`` and ``valley`` or neither), recomputed from the
  same runs by :func:`frictionlab.model.limit_cycles.features`;
* ``table1_rms`` - Table 1 by :data:`~frictionlab.studies.reproduce.TABLE1_SET`.

Usage::

    .venv/bin/python benchmarks/thesis_numbers.py
"""

from __future__ import annotations

import json
import time


def main() -> None:
    from frictionlab.model.limit_cycles import features
    from frictionlab.runs import simulate_config
    from frictionlab.studies import reproduce as rp
    from frictionlab.studies.reference import TABLE_COLUMNS

    t0 = time.perf_counter()
    res = rp.run()
    worst = 0.0
    for table in rp.TABLES[:2]:
        for row in res.tables[table.number]:
            for c, ref in zip(TABLE_COLUMNS, table.reference[row["value"]], strict=True):
                worst = max(worst, abs(row[c] - ref) / ref)
    rows = [r for n in ("6", "7") for r in res.tables[n]]
    out = {
        "tables_2_3_worst": round(worst, 4),
        "lugre_rows": len(rows),
        "lugre_rows_with_peak2": sum(r["peak2"] is not None for r in rows),
        "lugre_rows_with_valley": sum(r["valley"] is not None for r in rows),
        "lugre_shoulders": sum(r["peak2"] is not None and r["valley"] is None for r in rows),
    }
    two = 0
    for n in ("6", "7"):
        table = next(t for t in rp.TABLES if t.number == n)
        for r in res.tables[n]:
            traj = simulate_config(table.setting.config({r["key"]: r["value"]}), rp.DURATION)
            f = features(traj.t, traj["theta_m"], fell=traj.status == "fell",
                         rel_prominence=0.02)
            two += f.valley is not None
    out["lugre_rows_with_two_maxima_at_2pct"] = two
    out["table1_rms"] = round(rp.table1(res)["rms"], 4)
    out["seconds"] = round(time.perf_counter() - t0, 1)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
