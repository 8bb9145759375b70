r"""The thesis's simulation studies, re-run with their settings (``frictionlab reproduce``).

Studies
-------
* Tables 2-3 (Sec. 5.2): fast design, classical model eq. (17) with eq. (20)'s
  F_S = 2.3, F_C = 1.5, zero-velocity band 0.03 rad/s (the band Sec. 5.2
  widened to for these tables); F_C, then F_S varied.  The thesis's values
  are in :mod:`frictionlab.studies.reference`.
* Tables 4-5: the same grids with the slow design and the band of Sec. 5.2's
  first statement, 0.001 rad/s (with it the slow cycle's period is the
  3.3 s the thesis reports for Figs. 19-20; 3.25 s with 0.03).  The thesis's
  values are not in this repository.
* Tables 6-7 (Sec. 5.3, App. F): fast design, LuGre with eq. (21)'s
  defaults, k = 1 acting in the plant (eq. 19 with e = -theta,
  docs/model.md); one parameter at a time.  The copy of the thesis this
  project was built from withholds the App. F tables, so the grids are
  frictionlab's (:data:`TABLES`): Tables 2-3's grids for F_S and F_C, halving
  and doubling around eq. (21) for F_v and v_S, sigma0 from 25 to 400 (finer
  around 100, where App. F remarks that it is extremal) and 1000, sigma1 from
  0 to 10, k from 0 to 2 in steps of 0.25.  Table 6 holds the friction levels (F_S, F_C, F_v,
  v_S), Table 7 the bristle dynamics and the observer gain (sigma0, sigma1,
  k).
* The omega0 studies of Sec. 5.2 against the rig's Table 1 (:data:`CASES`):
  the plant's omega0 raised to 7.5 (fast design) and lowered to 6.1 (slow),
  with F_C = 1.3 as in Figs. 21-24, the observers and the design kept at 6.8;
  and the LuGre model's resemblance to Figs. 17-18 and, at omega0 7.5, to
  Figs. 21-22 (Sec. 5.3).

Every run lasts :data:`DURATION` s and its features are measured over the
last half (:mod:`frictionlab.model.limit_cycles`); all runs go through the sweep
engine (:func:`frictionlab.studies.sweep.evaluate`: a process pool on every core, or
Dask).  :func:`run` returns the results, :func:`interface_json` the object
``frictionlab reproduce --json`` prints, :func:`write_report` the report
folder: ``report.md`` (the tables beside the thesis's values with relative
differences, the checked statements of Sec. 5.2-5.3, the figures),
``report.json`` (every row with its status and the ``simulate`` command that
repeats it) and one PNG per simulated figure whose caption the thesis keeps
(Figs. 17-24) plus the LuGre cycle.  The command line is
:mod:`frictionlab.cli.reproduce`.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from .. import runs
from ..config import Config, build_config
from ..model.design import PRESETS
from ..model.limit_cycles import FEATURES, comparable, trajectory_features
from ..plotting import plot_cycle_figure, plot_rig_rows
from . import sweep
from .reference import SIMULATED_PERIODS, TABLE1, TABLE2, TABLE3, TABLE_COLUMNS

__all__ = [
    "CASES",
    "DURATION",
    "TABLES",
    "Case",
    "Results",
    "Setting",
    "Table",
    "interface_json",
    "run",
    "statements",
    "write_report",
]

#: Simulated seconds per run; features over the last half.
DURATION = 40.0
#: The six features of the thesis's tables (Table 1's columns).
COLUMNS = TABLE_COLUMNS
#: Signals each figure run sends back from its worker.
TRACE = ("t", "theta_m", "arm_dot_m", "u", "friction")


@dataclass(frozen=True)
class Setting:
    """A base configuration: design preset, plant friction model, ``--set`` overrides."""

    design: str
    friction: str
    sets: tuple[str, ...]

    def config(self, values: Mapping[str, float] | None = None) -> Config:
        cfg = build_config(self.design, self.friction, sets=self.sets)
        return cfg.with_values(values) if values else cfg

    def command(self, values: Mapping[str, float]) -> str:
        """The ``frictionlab simulate`` command that repeats one run."""
        sets = [*self.sets, *(f"{k}={v:g}" for k, v in values.items())]
        return (f"frictionlab simulate --design {self.design} --friction {self.friction} "
                f"--duration {DURATION:g} " + " ".join(f"--set {s}" for s in sets) + " --json")


#: Sec. 5.2, Tables 2-3: the band 0.03 rad/s "to get stiction".
FAST_CLASSICAL = Setting("fast", "classical", ("friction.zero_velocity_band=0.03",))
#: Sec. 5.2's first statement of the zero-velocity band, 0.001 rad/s.
SLOW_CLASSICAL = Setting("slow", "classical", ("friction.zero_velocity_band=0.001",))
#: Sec. 5.3: eq. (21) with k = 1 in the plant (only the fast design was simulated).
LUGRE_EQ21 = Setting("fast", "lugre", ("friction.observer_gain=1",))


@dataclass(frozen=True)
class Table:
    """One of the thesis's simulation tables: keys varied one at a time."""

    number: str
    title: str
    setting: Setting
    varies: tuple[tuple[str, tuple[float, ...]], ...]
    #: the thesis's rows by value (Table 1's columns), where this repository has them
    reference: Mapping[float, tuple[float, ...]] | None = None


_FC = tuple(TABLE2)  # 1.1 ... 1.9
_FS = tuple(TABLE3)  # 1.9 ... 2.7

#: Tables 2-7 with their settings and grids (see the module docstring).
TABLES = (
    Table("2", "fast design, classical model, F_C varied (F_S = 2.3)", FAST_CLASSICAL,
          (("friction.coulomb", _FC),), TABLE2),
    Table("3", "fast design, classical model, F_S varied (F_C = 1.5)", FAST_CLASSICAL,
          (("friction.stiction", _FS),), TABLE3),
    Table("4", "slow design, classical model, F_C varied (F_S = 2.3)", SLOW_CLASSICAL,
          (("friction.coulomb", _FC),)),
    Table("5", "slow design, classical model, F_S varied (F_C = 1.5)", SLOW_CLASSICAL,
          (("friction.stiction", _FS),)),
    Table("6", "fast design, LuGre eq. (21): friction levels varied", LUGRE_EQ21,
          (("friction.stiction", _FS), ("friction.coulomb", _FC),
           ("friction.viscous", (0.0, 0.035, 0.07, 0.14, 0.28)),
           ("friction.stribeck_velocity", (0.25, 0.5, 1.0, 2.0, 4.0)))),
    Table("7", "fast design, LuGre eq. (21): bristle dynamics and observer gain varied",
          LUGRE_EQ21,
          (("friction.sigma0", (25.0, 50.0, 75.0, 100.0, 150.0, 200.0, 300.0, 400.0, 1000.0)),
           ("friction.sigma1", (0.0, 1.0, 2.5, 5.0, 7.5, 10.0)),
           ("friction.observer_gain", (0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0)))),
)


@dataclass(frozen=True)
class Case:
    """One run of the omega0 studies (Sec. 5.2-5.3), compared with the rig's Table 1."""

    name: str
    label: str
    setting: Setting
    values: tuple[tuple[str, float], ...]
    #: the Table 1 row (``fast``/``slow``) it is compared with
    rig: str
    #: file stems of its two figures: (angle and arm velocity, control and friction)
    figures: tuple[str, str] | None = None


_W75 = (("plant.omega0", 7.5), ("friction.coulomb", 1.3))
_W61 = (("plant.omega0", 6.1), ("friction.coulomb", 1.3))

#: Table 1 (the rig) by one physically plausible set for both rows (Sec. 5.2-5.4):
#: classical friction, the plant's omega0 within [6.5, 7.1] around App. A's 6.8,
#: k_u within [0.8, 1.25], and the actuator of App. B.4 (docs/identification.md,
#: "Table 1 with the actuator": the fit that found it and why no such set gets
#: the RMS error below 5 %).
TABLE1_SET = {
    "friction.coulomb": 0.48551,
    "friction.stiction": 2.8708,
    "plant.omega0": 7.0839,
    "plant.input_gain": 0.98704,
    "actuator.curvature": 0.003622,
    "actuator.back_emf": 1.63,
}
_T1 = tuple(f"{k}={v:g}" for k, v in TABLE1_SET.items())

#: The omega0 studies and the figure runs.
CASES = (
    Case("fast", "fast, nominal plant (Figs. 17-18)", FAST_CLASSICAL, (), "fast",
         ("fig17", "fig18")),
    Case("fast_w75", "fast, plant omega0 7.5, F_C 1.3 (Figs. 21-22)", FAST_CLASSICAL, _W75,
         "fast", ("fig21", "fig22")),
    Case("fast_w75_both", "fast, omega0 7.5 in plant and design, F_C 1.3", FAST_CLASSICAL,
         (*_W75, ("design.omega0", 7.5)), "fast"),
    Case("slow", "slow, nominal plant (Figs. 19-20)", SLOW_CLASSICAL, (), "slow",
         ("fig19", "fig20")),
    Case("slow_w61", "slow, plant omega0 6.1, F_C 1.3 (Figs. 23-24)", SLOW_CLASSICAL, _W61,
         "slow", ("fig23", "fig24")),
    Case("slow_w61_band", "slow, plant omega0 6.1, F_C 1.3, band 0.03 rad/s", SLOW_CLASSICAL,
         (*_W61, ("friction.zero_velocity_band", 0.03)), "slow"),
    Case("lugre", "LuGre eq. (21), fast, nominal plant", LUGRE_EQ21, (), "fast",
         ("lugre_angle_velocity", "lugre_control_friction")),
    Case("lugre_w75", "LuGre eq. (21), fast, plant omega0 7.5", LUGRE_EQ21,
         (("plant.omega0", 7.5),), "fast"),
    Case("table1_fast", "Table 1's set with the actuator, fast", Setting("fast", "classical", _T1),
         (), "fast"),
    Case("table1_slow", "Table 1's set with the actuator, slow", Setting("slow", "classical", _T1),
         (), "slow"),
)

#: What each figure shows (the thesis's captions, in brief).
CAPTIONS = {
    "fig17": "Fig. 17: fast design; measured pendulum angle and arm velocity "
             "(compare with the rig's Figs. 9 and 12)",
    "fig18": "Fig. 18: fast design; control signal and friction force (compare with Fig. 10)",
    "fig19": "Fig. 19: slow design; measured pendulum angle and arm velocity "
             "(compare with Figs. 13 and 16)",
    "fig20": "Fig. 20: slow design; control signal and friction force (compare with Fig. 14)",
    "fig21": "Fig. 21: fast design, plant omega0 = 7.5, F_C = 1.3; measured pendulum angle "
             "and arm velocity (compare with Figs. 9 and 12)",
    "fig22": "Fig. 22: fast design, plant omega0 = 7.5, F_C = 1.3; control signal and "
             "friction force (compare with Fig. 10)",
    "fig23": "Fig. 23: slow design, plant omega0 = 6.1, F_C = 1.3; measured pendulum angle "
             "and arm velocity (compare with Figs. 13 and 16)",
    "fig24": "Fig. 24: slow design, plant omega0 = 6.1, F_C = 1.3; control signal and "
             "friction force (compare with Fig. 14)",
    "lugre_angle_velocity": "LuGre (Sec. 5.3): eq. (21) with k = 1, fast design; measured "
                            "pendulum angle and arm velocity (said to resemble Fig. 17)",
    "lugre_control_friction": "LuGre (Sec. 5.3): eq. (21) with k = 1, fast design; control "
                              "signal and friction force (said to resemble Fig. 18)",
}


def reduce_with_trace(cfg: Config, duration: float | None,
                      window: float | None) -> dict[str, Any]:
    """A sweep reduction that also returns the last cycles' signals for a figure.

    The features of :func:`frictionlab.studies.sweep.reduce_features`, plus ``trace``:
    :data:`TRACE` over the last six periods (at least 5 s).
    """

    traj = runs.simulate_config(cfg, duration)
    feats = trajectory_features(traj, window)
    out: dict[str, Any] = {name: getattr(feats, name) for name in FEATURES}
    out["status"] = feats.status
    t = traj.t
    span = max(6.0 * feats.period, 5.0) if feats.period else 5.0
    keep = t >= t[-1] - span if len(t) else slice(0)
    out["trace"] = {name: traj[name][keep] for name in TRACE}
    return out


@dataclass(frozen=True)
class Results:
    """What :func:`run` computed.

    Attributes
    ----------
    tables : dict
        Table number -> rows, in the order of the table's keys and values:
        ``key``, ``value``, the seven features, ``status``, ``error``.
    cases : list of (Case, row)
        The omega0 studies; a row with figures has ``trace``.
    workers : int
        Threads used (Dask workers with ``dask``).
    """

    tables: dict[str, list[dict[str, Any]]]
    cases: list[tuple[Case, dict[str, Any]]]
    workers: int


def _jobs() -> tuple[dict[tuple[Setting, bool], list[dict[str, float]]], int]:
    """The distinct runs, grouped by (setting, with trace), and their count."""
    groups: dict[tuple[Setting, bool], list[dict[str, float]]] = {}
    seen: set = set()
    for table in TABLES:
        for key, values in table.varies:
            for v in values:
                point = {key: v}
                ident = (table.setting, False, table.setting.config(point))
                if ident not in seen:
                    seen.add(ident)
                    groups.setdefault((table.setting, False), []).append(point)
    for case in CASES:
        groups.setdefault((case.setting, True), []).append(dict(case.values))
    return groups, sum(len(p) for p in groups.values())


def count_runs() -> int:
    """Number of closed-loop runs :func:`run` makes."""
    return _jobs()[1]


def run(workers: int | None = None, dask: str | None = None,
        progress: Callable[[int, int], None] | None = None) -> Results:
    """Run every study through the sweep engine.

    Parameters
    ----------
    workers : int, optional
        Threads of the compiled batch evaluator (Dask workers with
        ``dask="local"``).  Default: all cores, as ``frictionlab sweep``.
    dask : {"local", "tcp://HOST:PORT"}, optional
        Run on Dask distributed.
    progress : callable, optional
        ``progress(done, total)`` in runs, after every chunk of runs.

    Returns
    -------
    Results
    """

    groups, total = _jobs()
    if workers is None and dask is None:
        workers = os.cpu_count() or 1
    results: dict[tuple[Setting, bool], list[dict[str, Any]]] = {}
    done = 0
    for (setting, trace), points in groups.items():
        base = done

        def step(n, _total, base=base):
            if progress is not None:
                progress(base + n, total)

        results[(setting, trace)] = sweep.evaluate(
            setting.config(), points, duration=DURATION, workers=workers, dask=dask,
            progress=step, reduce=reduce_with_trace if trace else None)
        done += len(points)

    by_config: dict[tuple[Setting, Config], dict[str, Any]] = {}
    for (setting, trace), rows in results.items():
        if not trace:
            for point, row in zip(groups[(setting, trace)], rows, strict=True):
                by_config[(setting, setting.config(point))] = row
    tables = {}
    for table in TABLES:
        rows = []
        for key, values in table.varies:
            for v in values:
                row = by_config[(table.setting, table.setting.config({key: v}))]
                rows.append({"key": key, "value": v,
                             **{name: row[name] for name in FEATURES},
                             "status": row["status"], "error": row["error"],
                             "command": table.setting.command({key: v})})
        tables[table.number] = rows
    cases = []
    trace_rows = {s: iter(rows) for (s, trace), rows in results.items() if trace}
    for case in CASES:
        row = next(trace_rows[case.setting])
        cases.append((case, {**row, "command": case.setting.command(dict(case.values))}))
    return Results(tables, cases, workers or os.cpu_count() or 1)


def interface_json(results: Results, out: str, seconds: float,
                   figures: Sequence[str]) -> dict[str, Any]:
    """The object ``frictionlab reproduce --json`` prints.

    ``tables`` maps "2".."7" to rows holding the varied key with its value and
    the six features (``None`` where the cycle lacks one, or the run fell).
    """
    tables = {number: [{row["key"]: row["value"], **{c: row[c] for c in COLUMNS}}
                       for row in rows]
              for number, rows in results.tables.items()}
    return {"out": out, "seconds": round(seconds, 3), "figures": list(figures),
            "tables": tables, "table1": {k: v for k, v in table1(results).items()
                                         if k in ("rms", "set")}}


def table1(results: Results) -> dict[str, Any]:
    """Table 1 by :data:`TABLE1_SET`: ``rms``, the RMS relative error over the 12
    features of both rows (a missing feature compared as a fit compares it,
    :func:`frictionlab.model.limit_cycles.comparable`; a run without a limit
    cycle counts as 100 % off), ``set``, and per row its features and relative
    errors (``rows``)."""

    errs: list[float] = []
    rows = {}
    for rig in ("fast", "slow"):
        row = _case(results, f"table1_{rig}")
        rel = {}
        for c, ref in zip(COLUMNS, TABLE1[rig], strict=True):
            v = comparable(row, c) if row["status"] == "limit_cycle" else None
            rel[c] = None if v is None else (v - ref) / ref
            errs.append(1.0 if v is None else rel[c])
        rows[rig] = {"features": {c: row[c] for c in COLUMNS}, "relative_error": rel,
                     "status": row["status"]}
    rms = math.sqrt(sum(e * e for e in errs) / len(errs))
    return {"rms": rms, "set": dict(TABLE1_SET), "rows": rows}


# ---------------------------------------------------------------------------
# the statements of Sec. 5.2-5.3 and App. F, checked
# ---------------------------------------------------------------------------


def _rel(a: float | None, b: float) -> float | None:
    return None if a is None else (a - b) / b


def _block(results: Results, number: str, key: str) -> list[dict[str, Any]]:
    return [r for r in results.tables[number] if r["key"] == key]


def _rising(rows: Sequence[Mapping[str, Any]], name: str) -> bool | None:
    vals = [r[name] for r in rows]
    if any(v is None for v in vals):
        return None
    return all(a < b for a, b in itertools.pairwise(vals))


def _falling(rows: Sequence[Mapping[str, Any]], name: str) -> bool | None:
    return _rising(rows[::-1], name)


def _middle_extreme(rows: Sequence[Mapping[str, Any]], name: str, sign: int) -> bool:
    """Is the middle row's value the largest (sign 1) or smallest (sign -1)?"""
    vals = [r[name] for r in rows]
    if any(v is None for v in vals):
        return False
    mid = sign * vals[len(vals) // 2]
    return all(mid > sign * v for i, v in enumerate(vals) if i != len(vals) // 2)


def _span(rows: Sequence[Mapping[str, Any]], name: str) -> float:
    vals = [r[name] for r in rows if r[name] is not None]
    if not vals:
        return math.nan
    return (max(vals) - min(vals)) / (sum(vals) / len(vals))


def _case(results: Results, name: str) -> dict[str, Any]:
    return next(row for case, row in results.cases if case.name == name)


def _rig_error(row: Mapping[str, Any], rig: str) -> float:
    """Largest relative difference of a run's six features from Table 1's row."""
    errs = [abs(_rel(row[c], r)) if row[c] is not None else math.inf
            for c, r in zip(COLUMNS, TABLE1[rig], strict=True)]
    return max(errs)


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:+.1f} %"


def statements(results: Results) -> list[tuple[str, str, bool | None]]:
    """The thesis's statements about its simulations, checked on ``results``.

    Returns
    -------
    list of (statement, what frictionlab finds, agrees)
        ``agrees`` is ``None`` for a statement of resemblance that the numbers
        beside it have to judge.
    """
    out: list[tuple[str, str, bool | None]] = []
    worst, where = 0.0, ""
    for table in TABLES:
        if table.reference is None:
            continue
        for row in results.tables[table.number]:
            ref = table.reference[row["value"]]
            for c, r in zip(COLUMNS, ref, strict=True):
                e = abs(_rel(row[c], r)) if row[c] is not None else math.inf
                if e > worst:
                    worst, where = e, f"Table {table.number}, {row['key']} = {row['value']:g}, {c}"
    out.append(("Tables 2-3: every entry within 5 % of the thesis",
                f"largest difference {100 * worst:.1f} % ({where})", worst <= 0.05))
    amps = ("peak1", "peak2", "max_u", "max_arm_velocity")
    for number, design in (("2", "fast"), ("4", "slow")):
        rows = _block(results, number, "friction.coulomb")
        ok = all(_rising(rows, a) for a in amps) and _rising(rows, "period")
        out.append((f"Sec. 5.2, {design} design: a lower F_C gives lower maxima and a slightly "
                    "shorter period",
                    f"period {_f(rows[0]['period'])} -> {_f(rows[-1]['period'])} s, peak1 "
                    f"{_f(rows[0]['peak1'])} -> {_f(rows[-1]['peak1'])} rad over F_C "
                    f"{rows[0]['value']:g} -> {rows[-1]['value']:g}", bool(ok)))
    for number, design in (("3", "fast"), ("5", "slow")):
        rows = _block(results, number, "friction.stiction")
        ok = all(_rising(rows, a) for a in amps) and _falling(rows, "period")
        out.append((f"Sec. 5.2, {design} design: a lower F_S gives smaller amplitudes and a "
                    "longer period",
                    f"period {_f(rows[0]['period'])} -> {_f(rows[-1]['period'])} s, peak1 "
                    f"{_f(rows[0]['peak1'])} -> {_f(rows[-1]['peak1'])} rad over F_S "
                    f"{rows[0]['value']:g} -> {rows[-1]['value']:g}", bool(ok)))
    for fc, fs, design in (("2", "3", "fast"), ("4", "5", "slow")):
        a = _span(results.tables[fc], "peak1")
        b = _span(results.tables[fs], "peak1")
        out.append((f"Sec. 5.2, {design} design: F_S changes the cycle less than F_C",
                     f"peak1 spans {100 * b:.0f} % over F_S, {100 * a:.0f} % over F_C", b < a))
    for design, figs in (("fast", "17-18"), ("slow", "19-20")):
        row = _case(results, design)
        ref = SIMULATED_PERIODS[design]
        e = _rel(row["period"], ref)
        out.append((f"Sec. 5.2: the simulated {design} cycle of Figs. {figs} has T = {ref:g} s",
                    f"T = {_f(row['period'])} s ({_pct(e)})",
                    e is not None and abs(e) <= 0.05))
    nominal = _case(results, "fast")
    w75 = _case(results, "fast_w75")
    both = _case(results, "fast_w75_both")
    out.append(("Sec. 5.2: the plant's omega0 = 7.5 (observers at 6.8) makes the fast cycle "
                "resemble the rig's almost perfectly; 7.5 in the observers too does not",
                f"largest difference from Table 1: {100 * _rig_error(w75, 'fast'):.0f} % "
                f"(nominal plant {100 * _rig_error(nominal, 'fast'):.0f} %, 7.5 in both "
                f"{100 * _rig_error(both, 'fast'):.0f} %); period "
                f"{_pct(_rel(w75['period'], TABLE1['fast'][3]))}",
                _rig_error(w75, "fast") < min(_rig_error(nominal, "fast"),
                                              _rig_error(both, "fast"))))
    snom = _case(results, "slow")
    w61 = _case(results, "slow_w61")
    out.append(("Sec. 5.2: the plant's omega0 = 6.1 gives the slow design an acceptable "
                "resemblance",
                f"period {_f(w61['period'])} s ({_pct(_rel(w61['period'], TABLE1['slow'][3]))}"
                f" from the rig's 2.1 s; nominal plant {_f(snom['period'])} s); largest "
                f"difference {100 * _rig_error(w61, 'slow'):.0f} % (nominal "
                f"{100 * _rig_error(snom, 'slow'):.0f} %)",
                _rig_error(w61, "slow") < _rig_error(snom, "slow")))
    sig = {r["value"]: r for r in _block(results, "7", "friction.sigma0")}
    trio = [sig[s] for s in (50.0, 100.0, 200.0)]
    ext = [_middle_extreme(trio, "period", 1)] + [
        _middle_extreme(trio, a, -1) for a in ("peak1", "max_u")]
    out.append(("App. F: sigma0 = 100 is extremal in amplitudes and period",
                "over sigma0 = 50, 100, 200: period "
                + " / ".join(_f(sig[s]["period"]) for s in (50.0, 100.0, 200.0))
                + " s, peak1 " + " / ".join(_f(sig[s]["peak1"]) for s in (50.0, 100.0, 200.0))
                + " rad", all(ext)))
    ks = _block(results, "7", "friction.observer_gain")
    out.append(("App. F: the observer gain k (0 to 2) changes the cycle",
                "period " + " / ".join(_f(r["period"]) for r in ks) + " s, peak1 "
                + " / ".join(_f(r["peak1"]) for r in ks) + " rad over k = "
                + " / ".join(f"{r['value']:g}" for r in ks),
                bool(_falling(ks, "period") and _rising(ks, "peak1"))))
    lug = _case(results, "lugre")
    lug75 = _case(results, "lugre_w75")
    for lrow, crow, figs in ((lug, nominal, "17-18"), (lug75, w75, "21-22")):
        diffs = ", ".join(f"{c} {_pct(_rel(lrow[c], crow[c]))}"
                          for c in ("period", "peak1", "max_u", "max_arm_velocity"))
        extra = " and plant omega0 7.5" if lrow is lug75 else ""
        out.append((f"Sec. 5.3: LuGre with eq. (21){extra} gives cycles like Figs. {figs}",
                    f"against the classical run: {diffs}", None))
    return out


# ---------------------------------------------------------------------------
# the report folder
# ---------------------------------------------------------------------------


def _f(v: float | None) -> str:
    return "-" if v is None else f"{v:#.3g}"


def _design_name(cfg: Config) -> str:

    for name, spec in PRESETS.items():
        if dataclasses.replace(spec, omega0=cfg.design.omega0) == cfg.design:
            return name
    return "custom"


def describe(cfg: Config, sep: str = "; ") -> str:
    """The design, the friction and its parameters, and the omega0s (``sep`` between
    the design and the rest)."""
    f = cfg.friction
    if cfg.friction_kind == "classical":
        fr = (f"classical friction F_S {f.stiction:g}, F_C {f.coulomb:g} m/s², "
              f"band {f.zero_velocity_band:g} rad/s")
    elif cfg.friction_kind == "lugre":
        fr = (f"LuGre F_S {f.stiction:g}, F_C {f.coulomb:g}, F_v {f.viscous:g}, "
              f"σ0 {f.sigma0:g}, σ1 {f.sigma1:g}, v_S {f.stribeck_velocity:g}, "
              f"k {f.observer_gain:g}")
    else:
        fr = f"{cfg.friction_kind} friction"
    return (f"{_design_name(cfg)} design{sep}{fr}; ω0 plant {cfg.plant.omega0:g}, "
            f"design {cfg.design.omega0:g} rad/s")


def _table_md(table: Table, rows: Sequence[Mapping[str, Any]]) -> list[str]:
    heads = ("peak1 (rad)", "peak2 (rad)", "valley (rad)", "T (s)", "max(u) (m/s²)",
             "max(Ω̇) (rad/s)")
    with_status = any(r["status"] != "limit_cycle" for r in rows)
    lines = ["| key | value | " + " | ".join(heads) + (" | status |" if with_status else " |"),
             "|---" * (2 + len(heads) + with_status) + "|"]
    for r in rows:
        cells = []
        for i, c in enumerate(COLUMNS):
            cell = _f(r[c])
            if table.reference is not None:
                ref = table.reference[r["value"]][i]
                cell += f" ({_f(ref)}, {_pct(_rel(r[c], ref))})"
            cells.append(cell)
        status = f" {r['status']}" + (f": {r['error']}" if r["error"] else "") + " |"
        lines.append(f"| {r['key']} | {r['value']:g} | " + " | ".join(cells) + " |"
                     + (status if with_status else ""))
    return lines


def _report_md(results: Results, seconds: float, figures: Sequence[str]) -> str:
    # the package's root, which no layer imports at module level (it names them all)
    from .. import __version__

    lines = [
        "# The thesis's simulation studies, re-run by frictionlab",
        "",
        f"`frictionlab reproduce` (frictionlab {__version__}): {count_runs()} closed-loop "
        f"runs on {results.workers} worker(s) in {seconds:.1f} s.  Each run lasts "
        f"{DURATION:g} s; the features are measured on the measured pendulum angle over "
        "the last half (docs/cli.md).  The classical model is eq. (17) with F_S = 2.3, "
        "F_C = 1.5 (eq. 20); the zero-velocity band is 0.03 rad/s for the fast design "
        "(Sec. 5.2's Tables 2-3) and 0.001 rad/s for the slow design (Sec. 5.2's first "
        "statement).  The LuGre model is eq. (21) with k = 1 acting in the plant "
        "(eq. 19 with e = -theta; docs/model.md).  `report.json` holds every row with its "
        "status and the `frictionlab simulate` command that repeats it.",
        "",
        "## The thesis's statements, checked",
        "",
        "| statement | frictionlab | agrees |",
        "|---|---|---|",
    ]
    for text, found, agrees in statements(results):
        mark = "see the numbers" if agrees is None else ("yes" if agrees else "**no**")
        lines.append(f"| {text} | {found} | {mark} |")
    for table in TABLES:
        lines += ["", f"## Table {table.number}: {table.title}", ""]
        cfg = table.setting.config()
        lines.append(f"Base: {describe(cfg)}.  "
                     + ("Each cell: frictionlab (the thesis, relative difference)."
                        if table.reference is not None else
                        "The thesis's values are not in this repository."))
        lines.append("")
        lines += _table_md(table, results.tables[table.number])
    lines += ["", "## Sec. 5.2-5.3: the plant's omega0 against the rig (Table 1)", "",
              "Each cell: frictionlab (the rig's Table 1, relative difference).", "",
              "| case | peak1 (rad) | peak2 (rad) | valley (rad) | T (s) | max(u) (m/s²) | "
              "max(Ω̇) (rad/s) |", "|---" * 7 + "|"]
    for case, row in results.cases:
        ref = TABLE1[case.rig]
        cells = [f"{_f(row[c])} ({_f(r)}, {_pct(_rel(row[c], r))})"
                 for c, r in zip(COLUMNS, ref, strict=True)]
        status = "" if row["status"] == "limit_cycle" else f" [{row['status']}]"
        lines.append(f"| {case.label}{status} | " + " | ".join(cells) + " |")
    t1 = table1(results)
    lines += ["", "## Table 1 by one plausible set, with the actuator of App. B.4", "",
              f"RMS relative error over the 12 features: **{100 * t1['rms']:.1f} %**.  Set: "
              + ", ".join(f"`{k}={v:g}`" for k, v in TABLE1_SET.items())
              + " (classical friction, the other keys at their defaults).", "",
              "| row | " + " | ".join(COLUMNS) + " |", "|---" * (1 + len(COLUMNS)) + "|"]
    for rig, r in t1["rows"].items():
        cells = [f"{_f(r['features'][c])} ({_f(ref)}, {_pct(r['relative_error'][c])})"
                 for c, ref in zip(COLUMNS, TABLE1[rig], strict=True)]
        lines.append(f"| {rig} | " + " | ".join(cells) + " |")
    lines += ["", "## Figures", ""]
    for path in figures:
        stem = os.path.splitext(os.path.basename(path))[0]
        lines += [f"![{stem}]({os.path.basename(path)})", "",
                  f"*{CAPTIONS.get(stem, 'Table 1 against one set for both rows')}*", ""]
    return "\n".join(lines) + "\n"


def _plain(obj: Any) -> Any:
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    return obj


def write_report(results: Results, out: str, seconds: float,
                 progress: Callable[[int, int], None] | None = None) -> list[str]:
    """Write ``report.md``, ``report.json`` and the figures into the folder ``out``.

    Parameters
    ----------
    results : Results
    out : str
        An existing folder; files of the same names are replaced.
    seconds : float
        Time the runs took (stated in the report).
    progress : callable, optional
        ``progress(done, total)`` in figures.

    Returns
    -------
    list of str
        The figure paths, in order.
    """

    jobs = sorted(((case, row, stem, kind)
                   for case, row in results.cases if case.figures and "trace" in row
                   for stem, kind in zip(case.figures, ("angle_velocity", "control_friction"),
                                         strict=True)),
                  key=lambda job: list(CAPTIONS).index(job[2]))
    figures = []
    for i, (case, row, stem, kind) in enumerate(jobs):
        cfg = case.setting.config(dict(case.values))
        path = os.path.join(out, f"{stem}.png")
        desc = describe(cfg, sep="\n")
        title = f"{CAPTIONS[stem].split(':')[0]} (simulated): {desc}"
        plot_cycle_figure(row["trace"], path, kind, title)
        figures.append(path)
        if progress is not None:
            progress(i + 1, len(jobs))
    t1 = table1(results)
    t1_rows = {rig: row for rig in ("fast", "slow")
               for case, row in results.cases if case.name == f"table1_{rig}"}
    if all("trace" in row for row in t1_rows.values()):

        path = os.path.join(out, "table1.png")
        plot_rig_rows({rig: row["trace"] for rig, row in t1_rows.items()},
                      {rig: row for rig, row in t1_rows.items()}, TABLE1, path,
                      f"Table 1 (the rig) against one set for both rows, RMS relative "
                      f"error {100 * t1['rms']:.1f} %\n"
                      + ", ".join(f"{k} {v:g}" for k, v in TABLE1_SET.items()))
        figures.append(path)
    with open(os.path.join(out, "report.md"), "w", encoding="utf-8") as fh:
        fh.write(_report_md(results, seconds, figures))
    data = {
        "duration": DURATION,
        "tables": {t.number: {"title": t.title, "base": t.setting.command({}),
                              "thesis": ({f"{v:g}": dict(zip(COLUMNS, r, strict=True))
                                          for v, r in t.reference.items()}
                                         if t.reference else None),
                              "rows": results.tables[t.number]}
                   for t in TABLES},
        "omega0_studies": [{"name": c.name, "case": c.label, "rig": dict(zip(COLUMNS, TABLE1[c.rig],
                                                             strict=True)),
                            **{k: v for k, v in row.items() if k != "trace"}}
                           for c, row in results.cases],
        "statements": [{"statement": s, "frictionlab": f, "agrees": a}
                       for s, f, a in statements(results)],
        "table1": t1,
        "figures": figures,
    }
    with open(os.path.join(out, "report.json"), "w", encoding="utf-8") as fh:
        json.dump(_plain(data), fh, indent=1)
        fh.write("\n")
    return figures
