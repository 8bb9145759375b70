r"""The thesis's limit-cycle study on a motor plant (``frictionlab reproduce --plant NAME``).

The thesis varied the plant's friction levels one at a time and read the
limit cycle's features (Tables 2-5, Sec. 5.2; LuGre in App. F), predicted
nothing, and compensated the friction in Sec. 6.  :func:`run` does all three
for a DC-motor Furuta pendulum (the QUBE-Servo 2 and 3 presets,
``--plant qube2|qube3``, or ``furuta-dc``), with u the motor voltage and
every friction level in volts (docs/model.md, "The DC-motor Furuta pendulum"):

* **Tables** (:data:`TABLES`): F_C varied at fixed F_S and F_S at fixed F_C,
  classical friction (eq. 17, the preset's zero-velocity band) and LuGre
  (eq. 18 with the preset's levels, the bristle scaled to them, k = 0 in
  the plant), the fast and the slow design of Sec. 2.4 on the plant's
  linearisation.  The grids are around the preset's levels (F_S 0.2 V,
  F_C 0.15 V on a QUBE) and scale with them; the slow design falls at the
  preset's levels (its arm loop is too weak for them), so its tables start
  from a tenth of the preset's F_C to find where it still balances.
* **Predictions**: every table row is also predicted, by the exact periodic
  orbit (:func:`frictionlab.model.periodic.periodic_orbit`) and the
  describing function (:func:`frictionlab.studies.predict.describing_function`),
  and compared with the simulation: the period, peak1 (orbit) and the
  pendulum angle's first harmonic (describing function; the simulation's
  first harmonic over its last whole periods, :func:`first_harmonic`).
* **Compensators** (:data:`COMPENSATORS`): each of Sec. 6's compensators
  (and the adaptive one) on the fast design, its levels matched to the
  plant's (``compensation.coulomb``, ``stiction`` = the plant's), at four
  F_C levels, for classical and LuGre plant friction; the shrink factor is
  the uncompensated cycle's peak-to-peak over the compensated one's
  (:attr:`frictionlab.studies.compensation.Comparison.reduction`), and the
  slow design's cycle at its base levels likewise.

Every run lasts :data:`DURATION` s, features over the last half; all runs go
through the sweep engine (a process pool on every core, or Dask).  The report
(``report.md``, ``report.json``, the figures) is written by
:mod:`frictionlab.studies.plant_report`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .. import runs
from ..config import PLANT_NAMES, Config, ConfigValueError, build_config
from ..model.limit_cycles import FEATURES, trajectory_features
from ..model.plants.furuta_dc import PRESET_FRICTION
from . import sweep
from .compensation import PEAK_TO_PEAK_FLOOR, chatter
from .predict import predict

__all__ = [
    "COMPENSATORS",
    "DURATION",
    "MOTOR_PLANTS",
    "TABLE_COLUMNS",
    "TRACE",
    "PlantResults",
    "PlantSetting",
    "PlantStudy",
    "PlantTable",
    "count_runs",
    "first_harmonic",
    "interface_json",
    "reduce_compensated",
    "reduce_with_prediction",
    "run",
    "study",
]

#: Simulated seconds per run; features over the last half.
DURATION = 40.0
#: The plants this study runs on (the thesis's own is ``reproduce`` without ``--plant``).
MOTOR_PLANTS = tuple(p for p in PLANT_NAMES if p != "thesis")
#: The features of a table row (the thesis's six and the peak-to-peak angle).
TABLE_COLUMNS = ("peak1", "peak2", "valley", "period", "max_u", "max_arm_velocity",
                 "peak_to_peak")
#: Signals a traced run sends back from its worker (the figures').
TRACE = ("t", "theta", "theta_dot", "theta_m", "arm", "arm_dot_m", "u", "friction")
#: The compensators compared (Sec. 6.1-6.3 and the adaptive one).
COMPENSATORS = ("coulomb", "classical", "lugre", "adaptive")

#: The QUBE presets' levels (volts) the grids below are written for; another
#: plant's grids are scaled by its preset F_C over this one.
_QUBE_FC = 0.15


@dataclass(frozen=True)
class PlantSetting:
    """A base configuration of the study: plant, design, plant friction, compensator, sets."""

    plant: str
    design: str
    friction: str
    sets: tuple[tuple[str, float], ...] = ()
    compensation: str = "none"

    def config(self, values: Mapping[str, float] | None = None) -> Config:
        cfg = build_config(self.design, self.friction, self.compensation, sets=self.sets,
                           plant=self.plant)
        return cfg.with_values(values) if values else cfg

    def command(self, values: Mapping[str, float] | None = None) -> str:
        """The ``frictionlab simulate`` command that repeats one run."""
        sets = {**dict(self.sets), **(values or {})}
        comp = (f" --compensation {self.compensation}" if self.compensation != "none" else "")
        return (f"frictionlab simulate --plant {self.plant} --design {self.design} "
                f"--friction {self.friction}{comp} --duration {DURATION:g} "
                + "".join(f"--set {k}={v:g} " for k, v in sets.items()) + "--json")


@dataclass(frozen=True)
class PlantTable:
    """One table: ``key`` varied over ``values`` on ``setting``."""

    number: str
    title: str
    setting: PlantSetting
    varies: tuple[tuple[str, tuple[float, ...]], ...]


@dataclass(frozen=True)
class PlantStudy:
    """What :func:`run` computes for one plant (:func:`study` builds the full one).

    Attributes
    ----------
    plant : str
    tables : tuple of PlantTable
        Rows of features and predictions.
    compensator_levels : tuple of float
        F_C (V) of the compensator runs on the fast design (F_S of the preset).
    compensator_frictions : tuple of str
        Plant friction models of the compensator runs.
    slow_base : tuple of (key, value)
        The slow design's compensator runs' levels (where it balances); empty:
        no slow-design compensator runs.
    figure_fc : float
        The F_C of the figures' runs (the preset's).
    duration : float
        Seconds per run.
    predict : bool
        Predict every table row.
    """

    plant: str
    tables: tuple[PlantTable, ...]
    compensator_levels: tuple[float, ...]
    compensator_frictions: tuple[str, ...]
    slow_base: tuple[tuple[str, float], ...]
    figure_fc: float
    duration: float = DURATION
    predict: bool = True
    compensators: tuple[str, ...] = field(default=COMPENSATORS)


def _grid(r: float, values: Sequence[float]) -> tuple[float, ...]:
    return tuple(float(f"{v * r:.6g}") for v in values)


def study(plant: str = "qube2") -> PlantStudy:
    """The full study of ``plant`` (its grids, see the module docstring).

    Raises
    ------
    ConfigValueError
        ``plant`` is not a motor plant (field ``plant``).
    """
    if plant not in MOTOR_PLANTS:
        raise ConfigValueError("plant", plant, "a motor plant: " + ", ".join(MOTOR_PLANTS))
    pf = PRESET_FRICTION[plant]
    fs0, fc0 = pf["friction.stiction"], pf["friction.coulomb"]
    r = fc0 / _QUBE_FC
    fc_fast = _grid(r, (0.025, 0.05, 0.075, 0.1, 0.125, 0.15, 0.175, 0.2))
    fs_fast = _grid(r, (0.15, 0.175, 0.2, 0.25, 0.3, 0.35, 0.4))
    # the slow design balances only below about a third of the preset's levels
    slow_fs, slow_fc = _grid(r, (0.1,))[0], _grid(r, (0.025,))[0]
    fc_slow = _grid(r, (0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.08, 0.1))
    fs_slow = _grid(r, (0.025, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3))
    fast = (("friction.stiction", fs0), ("friction.coulomb", fc0))
    slow = (("friction.stiction", slow_fs), ("friction.coulomb", slow_fc))

    def tables_of(design: str, friction: str, base, fc_values, fs_values, first: int):
        s = PlantSetting(plant, design, friction, base)
        fs, fc = dict(base)["friction.stiction"], dict(base)["friction.coulomb"]
        name = "classical model" if friction == "classical" else "LuGre model"
        return (PlantTable(str(first), f"{design} design, {name}, F_C varied (F_S = {fs:g} V)",
                           s, (("friction.coulomb", fc_values),)),
                PlantTable(str(first + 1),
                           f"{design} design, {name}, F_S varied (F_C = {fc:g} V)",
                           s, (("friction.stiction", fs_values),)))

    tables = (*tables_of("fast", "classical", fast, fc_fast, fs_fast, 2),
              *tables_of("slow", "classical", slow, fc_slow, fs_slow, 4),
              *tables_of("fast", "lugre", fast, fc_fast, fs_fast, 6),
              *tables_of("slow", "lugre", slow, fc_slow, fs_slow, 8))
    return PlantStudy(plant, tables, _grid(r, (0.05, 0.1, 0.15, 0.2)), ("classical", "lugre"),
                      slow, fc0)


# ---------------------------------------------------------------------------
# the reductions (run in the sweep engine's workers)
# ---------------------------------------------------------------------------


def first_harmonic(t: np.ndarray, y: np.ndarray, period: float | None,
                   window: float) -> float | None:
    """Amplitude of the first harmonic of ``y`` at ``period`` over the last whole
    periods within ``window`` s of the end (None without a period)."""
    if not period or period <= 0 or len(t) < 3:
        return None
    n = int(window // period)
    if n < 1:
        return None
    m = t >= t[-1] - n * period
    tt, yy = t[m], y[m]
    w = 2.0 * math.pi / period
    return float(2.0 / len(tt) * abs(np.sum((yy - yy.mean()) * np.exp(-1j * w * tt))))


def _run_row(cfg: Config, duration: float | None, window: float | None,
             trace: bool) -> tuple[dict[str, Any], Any]:
    traj = runs.simulate_config(cfg, duration)
    feats = trajectory_features(traj, window)
    out: dict[str, Any] = {name: getattr(feats, name) for name in FEATURES}
    out["status"] = "fell" if traj.status == "fell" else feats.status
    t = traj.t
    span = window if window is not None else 0.5 * (t[-1] if len(t) else 0.0)
    keep = t >= t[-1] - span if len(t) else slice(0)
    arm = traj["arm"][keep]
    out["arm_peak_to_peak"] = (float(arm.max() - arm.min())
                               if out["status"] == "limit_cycle" and len(arm) else None)
    out["fundamental"] = (first_harmonic(t, traj["theta"], feats.period, span)
                          if out["status"] == "limit_cycle" else None)
    if trace:
        period = feats.period or 1.0
        keep = t >= t[-1] - max(4.0 * period, 4.0) if len(t) else slice(0)
        out["trace"] = {name: (t if name == "t" else traj[name])[keep] for name in TRACE}
    return out, traj


def _num(v: Any) -> float | None:
    return None if v is None or not math.isfinite(v) else float(v)


def reduce_with_prediction(cfg: Config, duration: float | None,
                           window: float | None) -> dict[str, Any]:
    """A table row: the run's features, ``arm_peak_to_peak`` (rad),
    ``fundamental`` (the pendulum angle's first harmonic, rad) and both
    predictions (``orbit``: found, stable, period, peak1, peak_to_peak;
    ``describing_function``: period, pendulum_amplitude, arm-velocity
    amplitude)."""
    out, _ = _run_row(cfg, duration, window, trace=False)
    pr = predict(cfg)
    po, df = pr.periodic_orbit, pr.describing_function
    found = bool(po.found)
    out["orbit"] = {"found": found, "stable": None if po.stable is None else bool(po.stable),
                    "period": _num(po.period) if found else None,
                    "peak1": _num(po.features.peak1) if found else None,
                    "peak_to_peak": _num(po.features.peak_to_peak) if found else None}
    out["describing_function"] = {"period": _num(df.period),
                                  "pendulum_amplitude": _num(df.pendulum_amplitude),
                                  "amplitude": _num(df.amplitude)}
    return out


def reduce_features(cfg: Config, duration: float | None,
                    window: float | None) -> dict[str, Any]:
    """A table row without predictions (:class:`PlantStudy` ``predict=False``)."""
    return _run_row(cfg, duration, window, trace=False)[0]


def reduce_compensated(cfg: Config, duration: float | None,
                       window: float | None) -> dict[str, Any]:
    """A compensator run: features, the estimate's sign reversals per second and
    the control's roughness (:func:`frictionlab.studies.compensation.chatter`),
    and its last cycles (``trace``)."""
    out, traj = _run_row(cfg, duration, window, trace=True)
    out.update(chatter(traj, window).as_dict())
    return out


# ---------------------------------------------------------------------------
# the study
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class PlantResults:
    """What :func:`run` computed.

    Attributes
    ----------
    study : PlantStudy
    tables : dict
        Table number -> rows: ``key``, ``value``, the features, ``status``,
        ``error``, ``arm_peak_to_peak``, ``fundamental``, ``orbit``,
        ``describing_function`` (with predictions), ``command``.
    compensators : list of dict
        One row per compensated run: ``design``, ``friction``, ``coulomb``
        (the plant's F_C, V), ``compensation`` (``none`` for the baseline),
        the features, ``reduction`` (baseline peak-to-peak over this one's),
        ``reversals_per_s``, ``u_roughness``, ``trace`` (the fast design at
        the figures' F_C, and the slow design), ``command``.
    workers : int
    """

    study: PlantStudy
    tables: dict[str, list[dict[str, Any]]]
    compensators: list[dict[str, Any]]
    workers: int


def _compensator_jobs(st: PlantStudy) -> list[tuple[PlantSetting, dict[str, Any]]]:
    jobs = []
    fs = PRESET_FRICTION[st.plant]["friction.stiction"]
    for friction in st.compensator_frictions:
        for fc in st.compensator_levels:
            levels = (("friction.stiction", fs), ("friction.coulomb", fc))
            for comp in ("none", *st.compensators):
                sets = levels + ((("compensation.stiction", fs), ("compensation.coulomb", fc))
                                 if comp != "none" else ())
                jobs.append((PlantSetting(st.plant, "fast", friction, sets, comp),
                             {"design": "fast", "friction": friction, "coulomb": fc,
                              "stiction": fs, "compensation": comp}))
    base = dict(st.slow_base)
    for comp in ("none", *st.compensators) if st.slow_base else ():
        sets = st.slow_base + ((("compensation.stiction", base["friction.stiction"]),
                                ("compensation.coulomb", base["friction.coulomb"]))
                               if comp != "none" else ())
        jobs.append((PlantSetting(st.plant, "slow", "classical", sets, comp),
                     {"design": "slow", "friction": "classical",
                      "coulomb": base["friction.coulomb"],
                      "stiction": base["friction.stiction"], "compensation": comp}))
    return jobs


def _table_configs(st: PlantStudy) -> set[tuple[PlantSetting, Config]]:
    return {(t.setting, t.setting.config({key: v})) for t in st.tables
            for key, values in t.varies for v in values}


def count_runs(st: PlantStudy) -> int:
    """Number of closed-loop runs :func:`run` makes for ``st`` (a configuration two
    tables share runs once)."""
    return len(_table_configs(st)) + len(_compensator_jobs(st))


def run(st: PlantStudy, workers: int | None = None, dask: str | None = None,
        progress: Callable[[int, int], None] | None = None) -> PlantResults:
    """Run the study ``st`` through the sweep engine.

    Parameters
    ----------
    st : PlantStudy
        :func:`study` of a plant, or a reduced one (tests).
    workers : int, optional
        Worker processes (default: all cores).
    dask : {"local", "tcp://HOST:PORT"}, optional
        Run on Dask distributed.
    progress : callable, optional
        ``progress(done, total)`` in runs, after every chunk.

    Returns
    -------
    PlantResults
    """
    total = count_runs(st)
    if workers is None and dask is None:
        workers = os.cpu_count() or 1
    reduce = reduce_with_prediction if st.predict else reduce_features
    done = 0

    def evaluate(setting: PlantSetting, points, red):
        nonlocal done
        base = done

        def step(n, _total):
            if progress is not None:
                progress(base + n, total)

        rows = sweep.evaluate(setting.config(), points, duration=st.duration, workers=workers,
                              dask=dask, progress=step, reduce=red)
        done += len(points)
        return rows

    # the tables' runs: one engine call per setting, each distinct configuration once
    # (Table 2's preset F_C is Table 3's preset F_S)
    by_setting: dict[PlantSetting, list[dict[str, float]]] = {}
    seen: dict[tuple[PlantSetting, Config], int] = {}
    for table in st.tables:
        for key, values in table.varies:
            for v in values:
                ident = (table.setting, table.setting.config({key: v}))
                if ident not in seen:
                    points = by_setting.setdefault(table.setting, [])
                    seen[ident] = len(points)
                    points.append({key: v})
    results = {setting: evaluate(setting, points, reduce)
               for setting, points in by_setting.items()}
    tables: dict[str, list[dict[str, Any]]] = {}
    for table in st.tables:
        rows = []
        for key, values in table.varies:
            for v in values:
                point = {key: v}
                i = seen[(table.setting, table.setting.config(point))]
                own = by_setting[table.setting][i]
                row = results[table.setting][i]
                rows.append({"key": key, "value": v,
                             **{k: x for k, x in row.items() if k not in own},
                             "command": table.setting.command(point)})
        tables[table.number] = rows
    # the compensator runs: one engine call per base (the compensator kind is not a key);
    # each job's levels are its point
    jobs = _compensator_jobs(st)
    groups: dict[PlantSetting, list[int]] = {}
    for i, (setting, _info) in enumerate(jobs):
        groups.setdefault(replace(setting, sets=()), []).append(i)
    comp_rows: list[dict[str, Any]] = [{}] * len(jobs)
    for base, idx in groups.items():
        points = [dict(jobs[i][0].sets) for i in idx]
        for i, p, row in zip(idx, points, evaluate(base, points, reduce_compensated),
                             strict=True):
            setting, info = jobs[i]
            comp_rows[i] = {**info, **{k: v for k, v in row.items() if k not in p},
                            "command": setting.command()}
    rows = _with_reductions(comp_rows)
    return PlantResults(st, tables, rows, workers or os.cpu_count() or 1)


def _with_reductions(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    base = {(r["design"], r["friction"], r["coulomb"]): r for r in rows
            if r["compensation"] == "none"}
    for r in rows:
        b = base[(r["design"], r["friction"], r["coulomb"])]
        a, c = b.get("peak_to_peak"), r.get("peak_to_peak")
        ok = (a is not None and c is not None and c >= 0 and b["status"] != "fell"
              and r["status"] != "fell")
        r["baseline_peak_to_peak"] = a
        r["reduction"] = a / max(c, PEAK_TO_PEAK_FLOOR) if ok else None
    return rows


def interface_json(results: PlantResults, out: str, seconds: float,
                   figures: Sequence[str]) -> dict[str, Any]:
    """The object ``frictionlab reproduce --plant NAME --json`` prints.

    ``tables`` maps "2".."9" to rows: the varied key with its value, the
    features of :data:`TABLE_COLUMNS`, ``status``, ``arm_peak_to_peak`` and
    ``fundamental`` (rad), ``orbit`` and ``describing_function`` (the
    predictions); ``compensators`` lists the compensated runs with their
    ``reduction``.
    """
    tables = {}
    for number, rows in results.tables.items():
        tables[number] = [
            {row["key"]: row["value"], **{c: row.get(c) for c in TABLE_COLUMNS},
             "status": row["status"], "arm_peak_to_peak": row.get("arm_peak_to_peak"),
             "fundamental": row.get("fundamental"),
             **({"orbit": row.get("orbit"), "describing_function":
                 row.get("describing_function")} if results.study.predict else {})}
            for row in rows]
    comps = [{k: v for k, v in r.items()
              if k in ("design", "friction", "coulomb", "stiction", "compensation", "status",
                       "peak_to_peak", "baseline_peak_to_peak", "reduction", "max_u",
                       "reversals_per_s")}
             for r in results.compensators]
    return {"plant": results.study.plant, "out": out, "seconds": round(seconds, 3),
            "figures": list(figures), "tables": tables, "compensators": comps}
