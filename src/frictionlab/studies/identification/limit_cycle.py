r"""Friction and process identification from limit-cycle features (Sec. 5).

The thesis compared limit cycles of the real rig (Table 1) with simulated
ones while varying the friction parameters one at a time, and found no
setting that matched (Sec. 5.2-5.4); it suspected the process parameters
:math:`\omega_0` and :math:`k_u` (``plant.omega0``, ``plant.input_gain``).
This module fits any chosen parameter keys to the measured features of one or
more experiments (fast and slow designs, each with its own settings) at once.

Cost
----
For every experiment e and every measured feature f (Table 1's columns and
``peak_to_peak``; a feature may be unknown) the residual is the weighted
relative error

.. math::

    r_{e,f} = w_f \, \frac{f^{sim}_{e}(p) - f^{meas}_{e}}{f^{meas}_{e}},

and the cost is :math:`C(p) = \sum r_{e,f}^2`.  A run that falls or does not
settle into a limit cycle, or lacks a measured feature, gets the finite
residual :data:`PENALTY` (times the weight) for each such feature, larger than
any plausible relative error, so the global search is steered away from it.
A simulated cycle with a shoulder (``peak2`` but no ``valley``,
:mod:`frictionlab.model.limit_cycles`) has its ``valley`` taken equal to its
``peak2``, and one with a single maximum and no shoulder its ``peak2`` and
``valley`` equal to ``peak1``: each is the continuous limit of a double peak
whose dip has just filled in.

Search
------
1. Global: :func:`scipy.optimize.differential_evolution` over the bounds
   (in coordinates normalised to [0, 1]); each generation's population is
   evaluated in one batch through :func:`frictionlab.studies.sweep.evaluate` (all
   experiments of all members in one call of the compiled batch evaluator,
   :mod:`frictionlab.studies.batch`, on the engine's threads, or on a Dask cluster).
   The engine's workers are chosen once for the whole fit
   (:func:`frictionlab.studies.sweep.auto_workers` on the fit's largest number of
   runs: all cores, one thread for a fit under about half a second of
   work).  The global search may run on shorter runs than the rest
   (``search_duration``, ``search_window``): it only has to find the basin
   of the optimum, which the polish then refines on full-length runs.
2. Local: :func:`scipy.optimize.least_squares` (trust region reflective,
   within the bounds) from the best point, with a central-difference
   Jacobian whose relative step (default 1 %) lies well above the
   simulator's feature noise: features are only piecewise smooth in the
   parameters because the loop is sampled (the period of a limit cycle
   locked to the 5 ms sampling moves in steps of a few ms).  The 2n
   perturbed points of one Jacobian are again one batch.

Stiction above Coulomb
----------------------
The classical (eq. 17) and LuGre (eq. 18) models take the static friction
to be at least the kinetic one, :math:`F_S \ge F_C` (Sec. 4: "the static
friction force is larger than the kinetic friction force").  When a
stiction and its Coulomb level are both fitted (:data:`STICTION_PAIRS`), the
search covers only that region, by construction rather than by a penalty:
the stiction's normalised coordinate spans
:math:`[\max(F_S^{lo}, F_C), F_S^{hi}]`, so every point of the unit box is
feasible and the global search wastes no member (bounds narrowed
accordingly: :math:`F_C \le F_S^{hi}`, :math:`F_S \ge F_C^{lo}`).  An
estimate on the constraint is warned about.  ``stiction_above_coulomb=False``
lifts it.

Uncertainty and identifiability
-------------------------------
The covariance of the estimate and the identifiability check:
:mod:`frictionlab.studies.identification.uncertainty`.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import differential_evolution, least_squares

from ...config import (
    Config,
    ConfigError,
    ConfigValueError,
    build_config,
    parse_assignment,
)
from ...io.notes import Note
from ...model.limit_cycles import FEATURES, comparable
from .. import sweep
from .measured import (
    DEFAULT_BOUNDS,
    PENALTY,
    STICTION_PAIRS,
    Experiment,
    check_bounds,
    check_fit_keys,
    default_bounds,
    parse_experiments,
    refusal,
)
from .uncertainty import (
    FLAT_RATIO,
    FLAT_SENSITIVITY,
    POOR_RELATIVE_STDERR,
    covariance,
    identifiability,
)

__all__ = [
    "DEFAULT_BOUNDS",
    "FLAT_RATIO",
    "FLAT_SENSITIVITY",
    "PENALTY",
    "STICTION_PAIRS",
    "Experiment",
    "FitResult",
    "LimitCycleProblem",
    "default_bounds",
    "fit_limit_cycle",
    "identifiability",
    "parse_experiments",
]

# ---------------------------------------------------------------------------
# the problem: parameters -> residuals
# ---------------------------------------------------------------------------


Evaluator = Callable[..., list[dict]]


def _sweep_evaluate(base, points, **kw) -> list[dict]:

    return sweep.evaluate(base, points, **kw)


class LimitCycleProblem:
    """Residuals of a parameter vector against the measured experiments.

    Parameters
    ----------
    experiments : sequence of Experiment
    keys : sequence of str
        Keys to fit.
    friction : str
        Plant friction model of the simulations.
    sets : sequence of ``"KEY=VALUE"`` or ``(key, value)``
        Settings common to all experiments (applied before each
        experiment's own ``sets``).
    bounds : mapping ``{key: (lo, hi)}``, optional
        Overrides of :func:`default_bounds`.
    weights : mapping ``{feature: w}``, optional
        Feature weights (default 1).
    duration, window : float
        Simulated time per run and the analysed final window (s).
    evaluate : callable, optional
        ``sweep.evaluate(base, points, duration=, window=, workers=, dask=)`` with
        the contract of :func:`frictionlab.studies.sweep.evaluate` (the default).
    workers, dask
        Passed to ``evaluate``.
    stiction_above_coulomb : bool
        When a stiction and its Coulomb level are both fitted
        (``friction.stiction`` and ``friction.coulomb``, or the ``_negative``
        pair), search only F_S >= F_C (see :attr:`pairs`).

    Attributes
    ----------
    lo, hi : ndarray
        The searched bounds of the keys (narrowed by the constraints).
    pairs : list of (int, int)
        Indices (Coulomb, stiction) into ``keys`` of the pairs searched
        with stiction >= Coulomb level.
    """

    def __init__(
        self,
        experiments: Sequence[Experiment],
        keys: Sequence[str],
        *,
        friction: str = "classical",
        sets: Sequence[Any] = (),
        bounds: Mapping[str, tuple[float, float]] | None = None,
        weights: Mapping[str, float] | None = None,
        duration: float = 30.0,
        window: float | None = 20.0,
        evaluate: Evaluator | None = None,
        workers: int | None = None,
        dask: str | None = None,
        stiction_above_coulomb: bool = True,
        plant: str = "thesis",
    ):
        if not experiments:
            raise ConfigError("no experiments to fit")
        self.experiments = list(experiments)
        self.plant = plant
        self.keys = check_fit_keys(keys, plant)
        self.duration, self.window = _run_length(duration, window)
        self.friction = friction
        self.workers, self.dask = workers, dask
        self._evaluate = evaluate or _sweep_evaluate
        weights = dict(weights or {})
        for name, w in weights.items():
            if name not in FEATURES:
                raise ConfigValueError("weights", name, ", ".join(FEATURES),
                                       f"unknown feature {name!r}; known features: "
                                  f"{', '.join(FEATURES)}")
            if not (math.isfinite(w) and w >= 0):
                raise ConfigValueError("weights", w, ">= 0",
                                       f"weight of {name} must be >= 0, got {w}")
        self.weights = weights
        # one configuration per experiment; all are expressed as points on the
        # first one, so a whole population is a single batch
        configs = []
        common = [k for k, _ in (parse_assignment(a) if isinstance(a, str) else a
                                 for a in sets)]
        if "sim.duration" in common:
            raise ConfigValueError("sim.duration", None, "unset (the fit's runs last its duration)",
                                   "sim.duration: the length of the fit's runs is the fit's "
                                   f"duration (here {self.duration:g} s)")
        for exp in self.experiments:
            for key in exp.sets:
                if key in self.keys:
                    raise ConfigError(f"experiment {exp.label!r} sets {key}, which is being "
                                      "fitted")
                if key == "sim.duration":
                    raise ConfigError(f"experiment {exp.label!r} sets sim.duration: every run "
                                      f"of the fit lasts the fit's duration ({self.duration:g} s)")
            configs.append(build_config(design=exp.design, friction=friction,
                                        sets=[*sets, *exp.sets.items()], plant=plant))
        self.configs = configs
        self.base = configs[0]
        base_flat = self.base.as_flat_dict()
        self.diffs: list[dict[str, Any]] = []
        for exp, cfg in zip(self.experiments, configs, strict=True):
            diff = {}
            for k, v in cfg.as_flat_dict().items():
                if k in ("friction_kind", "compensation_kind") or k in self.keys:
                    continue
                if v != base_flat[k]:
                    if v is None:
                        raise ConfigError(f"experiment {exp.label!r}: {k} cannot be unset "
                                          "relative to the first experiment")
                    diff[k] = v
            self.diffs.append(diff)
        # bounds
        given = dict(bounds or {})
        for k in given:
            if k not in self.keys:
                raise ConfigValueError("bounds", k, "the fitted keys",
                                       f"given for {k}, which is not fitted")
        lo, hi = [], []
        for k in self.keys:
            b = given.get(k) or default_bounds(k, self.base.get(k), plant)
            check_bounds(k, float(b[0]), float(b[1]), plant)
            lo.append(float(b[0]))
            hi.append(float(b[1]))
        self.lo, self.hi = np.array(lo), np.array(hi)
        self.pairs: list[tuple[int, int]] = []
        if stiction_above_coulomb:
            for c_key, s_key in STICTION_PAIRS:
                if c_key in self.keys and s_key in self.keys:
                    self._add_pair(self.keys.index(c_key), self.keys.index(s_key))
        # residual layout: (experiment index, feature) pairs
        self.layout: list[tuple[int, str]] = []
        meas, w = [], []
        for i, exp in enumerate(self.experiments):
            for name in FEATURES:
                if name in exp.features:
                    self.layout.append((i, name))
                    meas.append(exp.features[name])
                    w.append(self.weights.get(name, 1.0))
        self.measured = np.array(meas)
        self.w = np.array(w)
        self.nfev = 0
        self._cache: dict[tuple, tuple[np.ndarray, list[dict]]] = {}

    def with_runs(self, duration: float, window: float | None) -> LimitCycleProblem:
        """The same problem with runs of ``duration`` s analysed over their last
        ``window`` s (the global search's shorter runs, :func:`search_settings`),
        with its own evaluation count and cache."""
        other = copy.copy(self)
        other.duration, other.window = _run_length(duration, window)
        other.nfev = 0
        other._cache = {}
        return other

    def _add_pair(self, ic: int, i_s: int) -> None:
        """Search only F_S >= F_C for keys ``ic`` (Coulomb) and ``i_s`` (stiction).

        The bounds implied by the constraint are applied (F_C <= F_S <= the
        stiction's upper bound, F_S >= F_C >= the Coulomb's lower bound);
        bounds that leave no F_S >= F_C are refused.
        """
        c_key, s_key = self.keys[ic], self.keys[i_s]
        if self.lo[ic] >= self.hi[i_s]:
            raise refusal(
                "bounds", {c_key: (self.lo[ic], self.hi[ic]), s_key: (self.lo[i_s], self.hi[i_s])},
                "bounds that leave some stiction >= Coulomb level",
                f"bounds of {c_key} ({self.lo[ic]:g}:{self.hi[ic]:g}) and {s_key} "
                f"({self.lo[i_s]:g}:{self.hi[i_s]:g}) leave no stiction >= Coulomb level; "
                "widen them or fit without the constraint",
                "stiction_above_coulomb")
        self.hi[ic] = min(self.hi[ic], self.hi[i_s])
        self.lo[i_s] = max(self.lo[i_s], self.lo[ic])
        self.pairs.append((ic, i_s))

    # -- coordinates ------------------------------------------------------

    @property
    def n(self) -> int:
        return len(self.keys)

    @property
    def m(self) -> int:
        return len(self.layout)

    def to_params(self, x: np.ndarray) -> np.ndarray:
        """Normalised coordinates [0, 1] -> parameter values.

        Rows of ``x`` are parameter sets (a single vector is one set).  Each
        key maps linearly onto its bounds, except the stiction of a
        constrained pair (:attr:`pairs`), whose coordinate spans
        [max(its lower bound, F_C), its upper bound]: every point of the
        unit box is a parameter set with F_S >= F_C.
        """
        x = np.clip(np.asarray(x, dtype=float), 0.0, 1.0)
        p = self.lo + x * (self.hi - self.lo)
        for ic, i_s in self.pairs:
            floor = np.maximum(self.lo[i_s], p[..., ic])
            p[..., i_s] = floor + x[..., i_s] * (self.hi[i_s] - floor)
        return p

    def to_unit(self, p: np.ndarray) -> np.ndarray:
        """Parameter values -> normalised coordinates (inverse of :meth:`to_params`;
        a stiction below F_C in a constrained pair maps to F_S = F_C)."""
        p = np.asarray(p, dtype=float)
        x = (p - self.lo) / (self.hi - self.lo)
        for ic, i_s in self.pairs:
            floor = np.maximum(self.lo[i_s], p[..., ic])
            span = self.hi[i_s] - floor
            with np.errstate(invalid="ignore", divide="ignore"):
                xs = np.where(span > 0, (p[..., i_s] - floor) / span, 0.0)
            x[..., i_s] = np.clip(xs, 0.0, 1.0)
        return x

    def unit_jacobian(self, x: np.ndarray) -> np.ndarray:
        """d(parameters)/d(normalised coordinates) at one point ``x`` (n, n)."""
        x = np.clip(np.asarray(x, dtype=float), 0.0, 1.0)
        width = self.hi - self.lo
        D = np.diag(width)
        p = self.to_params(x)
        for ic, i_s in self.pairs:
            floor = max(self.lo[i_s], p[ic])
            D[i_s, i_s] = self.hi[i_s] - floor
            if p[ic] > self.lo[i_s]:
                D[i_s, ic] = (1.0 - x[i_s]) * width[ic]
        return D

    def current(self) -> np.ndarray:
        """The keys' values in the base configuration (clipped to the bounds)."""
        vals = [self.base.get(k) for k in self.keys]
        v = np.array([np.nan if x is None else float(x) for x in vals])
        mid = 0.5 * (self.lo + self.hi)
        v = np.where(np.isfinite(v), v, mid)
        return np.clip(v, self.lo, self.hi)

    # -- evaluation -------------------------------------------------------

    def points(self, params: np.ndarray) -> list[dict[str, Any]]:
        """Sweep points (all experiments of every parameter row of ``params``)."""
        pts = []
        for p in np.atleast_2d(params):
            values = {k: float(v) for k, v in zip(self.keys, p, strict=True)}
            for diff in self.diffs:
                pts.append({**diff, **values})
        return pts

    def residuals_from_rows(self, rows: Sequence[Mapping[str, Any]]) -> np.ndarray:
        """Residual vector of one parameter set from its experiments' rows."""
        r = np.empty(self.m)
        for j, (i, name) in enumerate(self.layout):
            row = rows[i]
            sim = _sim_feature(row, name)
            if sim is None:
                r[j] = PENALTY
            else:
                r[j] = float(np.clip((sim - self.measured[j]) / self.measured[j],
                                     -PENALTY, PENALTY))
        return r * self.w

    def evaluate_batch(self, params: np.ndarray,
                       progress: Callable[[int, int], None] | None = None,
                       ) -> tuple[np.ndarray, list[list[dict]]]:
        """Residuals (S, m) and the rows per parameter set, for S parameter sets.

        Parameter sets already evaluated come from a cache.
        """
        params = np.atleast_2d(np.asarray(params, dtype=float))
        keys = [tuple(np.round(p, 12)) for p in params]
        todo = [i for i, k in enumerate(keys) if k not in self._cache]
        todo_unique = list(dict.fromkeys(keys[i] for i in todo))
        if todo_unique:
            pts = self.points(np.array(todo_unique))
            kw = {"duration": self.duration, "window": self.window,
                  "workers": self.workers, "dask": self.dask}
            if progress is not None:
                kw["progress"] = progress
            rows = self._evaluate(self.base, pts, **kw)
            if rows and all(r.get("status") == "error" for r in rows):
                # a broken backend, not a bad parameter set: do not fit penalties
                raise RuntimeError(f"every simulation of the batch failed: {rows[0].get('error')}")
            self.nfev += len(todo_unique)
            ne = len(self.experiments)
            for j, k in enumerate(todo_unique):
                chunk = list(rows[j * ne:(j + 1) * ne])
                self._cache[k] = (self.residuals_from_rows(chunk), chunk)
        res = np.array([self._cache[k][0] for k in keys])
        return res, [self._cache[k][1] for k in keys]

    def residuals(self, params: np.ndarray) -> np.ndarray:
        return self.evaluate_batch(params)[0][0]

    def jacobian(self, params: np.ndarray, rel_step: float) -> np.ndarray:
        """Central-difference Jacobian dr/dp (m, n) in parameter units.

        The step of key j is ``rel_step * |p_j|`` (at least ``rel_step`` times
        1 % of its bound width); a step leaving the bounds becomes one-sided.
        """
        return self.line_fit(params, rel_step, (-1.0, 1.0))[0]

    def line_fit(self, params: np.ndarray, rel_step: float,
                 multiples: Sequence[float] = (-2.0, -1.0, 0.0, 1.0, 2.0),
                 ) -> tuple[np.ndarray, float]:
        """Jacobian by straight-line fits along each key, and the features' jitter.

        Key j is set to ``p_j + k * step_j`` for every k of ``multiples``
        (steps as in :meth:`jacobian`, clipped to the bounds; all other keys
        at ``params``), and every residual is fitted with a straight line in
        that key by least squares.  With ``(-1, 1)`` the slope is the
        central difference.  With more points the slope averages over the
        simulator's feature jitter (the sampled loop makes features
        piecewise constant in the parameters), so that one step landing on
        a jump does not set a column of J.

        Returns
        -------
        J : ndarray (m, n)
            The slopes dr/dp in parameter units.
        jitter : float
            Pooled variance of the residuals about their lines (weighted
            relative-feature units): the simulator's own feature jitter at
            the scale of the steps; 0 when the points leave no degree of
            freedom (two per key).
        """
        p = np.asarray(params, dtype=float)
        width = self.hi - self.lo
        step = rel_step * np.maximum(np.abs(p), 0.01 * width)
        offsets, rows = [], []
        for j in range(self.n):
            vals = sorted({float(np.clip(p[j] + k * step[j], self.lo[j], self.hi[j]))
                           for k in multiples})
            offsets.append(np.array(vals) - p[j])
            for v in vals:
                q = p.copy()
                q[j] = v
                rows.append(q)
        res, _ = self.evaluate_batch(np.array(rows))
        J = np.empty((self.m, self.n))
        rss, dof, at = 0.0, 0, 0
        for j, t in enumerate(offsets):
            r = res[at:at + len(t)]
            at += len(t)
            tc = t - t.mean()
            J[:, j] = tc @ (r - r.mean(axis=0)) / (tc @ tc)
            fit = r.mean(axis=0) + np.outer(tc, J[:, j])
            rss += float(np.sum((r - fit) ** 2))
            dof += (len(t) - 2) * self.m
        return J, (rss / dof if dof > 0 else 0.0)


def _sim_feature(row: Mapping[str, Any], name: str) -> float | None:
    if row.get("status") != "limit_cycle":
        return None
    return comparable(row, name)


# ---------------------------------------------------------------------------
# the fit
# ---------------------------------------------------------------------------


@dataclass
class FitResult:
    """Result of :func:`fit_limit_cycle`.

    ``residuals``/``simulated``/``measured`` are keyed by experiment label
    then feature; residuals are relative errors (unweighted).  ``bounds``
    are the searched bounds (narrowed by the constraints); ``constraints``
    names the enforced ``stiction >= coulomb`` relations.
    """

    keys: list[str]
    estimate: dict[str, float]
    stderr: dict[str, float | None]
    residuals: dict[str, dict[str, float | None]]
    simulated: dict[str, dict[str, float | None]]
    measured: dict[str, dict[str, float]]
    status: dict[str, str]
    cost: float
    warnings: list[str]
    bounds: dict[str, tuple[float, float]]
    singular_values: list[float]
    correlation: list[list[float | None]] | None
    global_cost: float
    generations: int
    evaluations: int
    seconds: float
    constraints: list[str] = field(default_factory=list)
    extra: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {
            "estimate": self.estimate,
            "stderr": self.stderr,
            "residuals": self.residuals,
            "cost": self.cost,
            "warnings": self.warnings,
            "simulated": self.simulated,
            "measured": self.measured,
            "status": self.status,
            "bounds": {k: list(v) for k, v in self.bounds.items()},
            "constraints": self.constraints,
            "singular_values": self.singular_values,
            "correlation": self.correlation,
            "global_search": {"cost": self.global_cost, "generations": self.generations},
            "evaluations": self.evaluations,
            "seconds": self.seconds,
        }


#: Most function and Jacobian evaluations of the least-squares polish.
POLISH_NFEV = 12


def _max_runs(prob: LimitCycleProblem, maxiter: int, popsize: int) -> int:
    """Most simulations a fit runs: every generation of the global search
    (the initial population and ``maxiter`` more), the polish (a residual
    vector and a central-difference Jacobian per step), and the optimum
    with the 4 points per key of :meth:`LimitCycleProblem.line_fit`, each
    parameter set once per experiment."""
    members = popsize * prob.n
    polish = POLISH_NFEV * (2 * prob.n + 1) + 4 * prob.n + 1
    return len(prob.experiments) * (members * (maxiter + 1) + polish)


def _run_length(duration: float, window: float | None) -> tuple[float, float | None]:
    """``(duration, window)`` of a fit's runs, checked: duration > 0, window in
    (0, duration] or None."""
    if not (duration > 0 and math.isfinite(duration)):
        raise ConfigValueError("duration", duration, "(0, inf) s",
                               f"duration must be > 0 s, got {duration}")
    if window is not None and not (0 < window <= duration):
        raise ConfigValueError("window", window, f"(0, {duration:g}] s",
                               f"window must be in (0, duration], got {window}")
    return float(duration), window


def search_settings(duration: float, window: float | None, search_duration: float | None,
                    search_window: float | None) -> tuple[float, float | None]:
    """Run length and window of the global search (see :func:`fit_limit_cycle`).

    Raises
    ------
    ConfigValueError
        A search duration that is not positive (``field`` ``search_duration``),
        or a search window outside (0, search duration] (``search_window``).
    """
    if search_duration is None:
        s_duration = float(duration)
    else:
        s_duration = float(search_duration)
        if not (s_duration > 0 and math.isfinite(s_duration)):
            raise ConfigValueError("search_duration", search_duration, "(0, inf) s",
                                   f"search_duration must be > 0 s, got {search_duration}")
    if search_window is not None:
        s_window: float | None = float(search_window)
    elif window is None or search_duration is None:
        s_window = window
    else:
        s_window = window * s_duration / duration
    if s_window is not None and not (0 < s_window <= s_duration):
        raise ConfigValueError("search_window", s_window, f"(0, {s_duration:g}] s",
                               f"search_window must be in (0, {s_duration:g}] s (the search "
                               f"duration), got {s_window:g}")
    return s_duration, s_window


def fit_limit_cycle(
    experiments: Sequence[Experiment],
    keys: Sequence[str],
    *,
    seed: int = 0,
    maxiter: int = 40,
    popsize: int = 8,
    rel_step: float = 0.01,
    progress: Callable[[str, float], None] | None = None,
    search_duration: float | None = None,
    search_window: float | None = None,
    **problem: Any,
) -> FitResult:
    """Fit parameter keys to measured limit-cycle features (see the module docstring).

    Parameters
    ----------
    experiments, keys
        See :class:`LimitCycleProblem`.
    **problem
        The problem's keywords, as :class:`LimitCycleProblem` takes them
        (written once, there): ``friction``, ``sets``, ``bounds``,
        ``weights``, ``duration`` (30 s), ``window`` (20 s), ``evaluate``,
        ``workers``, ``dask``, ``stiction_above_coulomb``.  ``workers``
        ``None`` (without ``dask``, the default): chosen
        once for the whole fit by :func:`frictionlab.studies.sweep.auto_workers`
        from the fit's largest number of runs (all cores unless the whole
        fit is under about half a second of serial work), not per
        generation.  With the default reduction these are threads of the
        compiled batch evaluator.
    seed : int
        Seed of the global search.
    maxiter : int
        Generations of differential evolution (at most).
    popsize : int
        Population size per fitted key (scipy's multiplier).
    rel_step : float
        Relative finite-difference step of the Jacobian.
    progress : callable, optional
        ``progress(stage, fraction, best_cost)`` with stage ``"global"`` (after
        every generation) or ``"local"`` (before and after the polish).
    search_duration, search_window : float, optional
        Run length and feature window (s) of the global search only; the
        polish, the reported cost, the standard errors and the
        identifiability check use ``duration`` and ``window``.  Shorter
        search runs find the basin of the optimum for a fraction of the cost
        (see docs/identification.md).  Default: ``duration``; the search
        window defaults to ``window`` scaled by ``search_duration /
        duration`` (``None``, the last half, stays ``None``).

    Returns
    -------
    FitResult
    """
    t0 = time.perf_counter()
    if maxiter < 1 or popsize < 2:
        raise ConfigError(f"maxiter must be >= 1 and popsize >= 2, got {maxiter}, {popsize}")
    if not 1e-5 <= rel_step <= 0.2:
        raise ConfigError(f"rel_step must be in [1e-5, 0.2], got {rel_step}")
    prob = LimitCycleProblem(experiments, keys, **problem)
    if prob.workers is None and prob.dask is None:

        prob.workers = sweep.auto_workers(prob.base, _max_runs(prob, maxiter, popsize),
                                          prob.duration)
    search = prob
    s_duration, s_window = search_settings(prob.duration, prob.window, search_duration,
                                           search_window)
    if (s_duration, s_window) != (prob.duration, prob.window):
        search = prob.with_runs(s_duration, s_window)
    report = progress or (lambda stage, f, c: None)

    def cost_vec(xt: np.ndarray) -> np.ndarray:
        # vectorized DE: xt has shape (n, S)
        res, _ = search.evaluate_batch(search.to_params(xt.T))
        return np.sum(res**2, axis=1)

    gen = [0]

    def callback(intermediate_result):
        gen[0] += 1
        report("global", min(1.0, gen[0] / maxiter), float(intermediate_result.fun))

    x0 = prob.to_unit(prob.current())
    de = differential_evolution(
        cost_vec, [(0.0, 1.0)] * prob.n, maxiter=maxiter, popsize=popsize, seed=seed,
        init="latinhypercube", polish=False,
        vectorized=True, updating="deferred", x0=x0, tol=1e-3, atol=0.0,
        mutation=(0.5, 1.0), recombination=0.7, callback=callback,
    )
    report("global", 1.0, float(de.fun))
    x_best = np.clip(de.x, 0.0, 1.0)
    global_cost = float(de.fun)

    def fun(x):
        return prob.residuals(prob.to_params(x))

    def jac(x):
        return prob.jacobian(prob.to_params(x), rel_step) @ prob.unit_jacobian(x)

    report("local", 0.0, global_cost)
    try:
        ls = least_squares(fun, x_best, jac=jac, bounds=(0.0, 1.0), method="trf",
                           x_scale="jac", max_nfev=POLISH_NFEV, ftol=1e-6, xtol=1e-6)
        x_loc = np.clip(ls.x, 0.0, 1.0)
        if np.sum(fun(x_loc) ** 2) < np.sum(fun(x_best) ** 2):
            x_best = x_loc
    except (ValueError, np.linalg.LinAlgError):
        pass
    report("local", 1.0, float(np.sum(fun(x_best) ** 2)))
    p = prob.to_params(x_best)
    res, rows_list = prob.evaluate_batch(p)
    r = res[0]
    rows = rows_list[0]
    cost = float(np.sum(r**2))
    J, jitter = prob.line_fit(p, rel_step)
    warnings: list[str] = []
    cov, why = covariance(J, cost, prob.m, prob.n, jitter)
    if why:
        warnings.append(why)
    stderr: dict[str, float | None] = {}
    corr = None
    if cov is not None:
        sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
        stderr = {k: float(v) for k, v in zip(prob.keys, sd, strict=True)}
        with np.errstate(invalid="ignore", divide="ignore"):
            c = cov / np.outer(sd, sd)
        corr = [[float(v) if math.isfinite(v) else None for v in row] for row in c]
    else:
        stderr = dict.fromkeys(prob.keys)
    sv, flat = identifiability(J, p, prob.keys)
    warnings += flat
    for k, v in zip(prob.keys, p, strict=True):
        se = stderr.get(k)
        if se is not None and v != 0 and se / abs(v) > POOR_RELATIVE_STDERR:
            warnings.append(f"{k} is poorly determined: standard error {se:.3g} "
                            f"({100 * se / abs(v):.0f} % of the estimate)")
    tol = 1e-3
    at_constraint = set()
    for ic, i_s in prob.pairs:
        if p[i_s] - p[ic] <= tol * (prob.hi[i_s] - prob.lo[i_s]):
            at_constraint.add(i_s)
            warnings.append(Note(
                f"{prob.keys[i_s]} = {prob.keys[ic]} = {p[ic]:.4g}: the estimate is at the "
                "constraint stiction >= Coulomb level, which the fit enforces (the "
                "unconstrained optimum may lie below it); fitting without the constraint "
                "lifts it", "stiction_above_coulomb"))
    for i, (k, v, lo, hi) in enumerate(zip(prob.keys, p, prob.lo, prob.hi, strict=True)):
        if i in at_constraint:
            continue
        if v <= lo + tol * (hi - lo) or v >= hi - tol * (hi - lo):
            warnings.append(Note(f"{k} = {v:.4g} is at its search bound [{lo:g}, {hi:g}]: "
                                 "widen its bounds or treat the estimate with care",
                                 "bounds"))
    for i, row in enumerate(rows):
        if row.get("status") != "limit_cycle":
            warnings.append(f"experiment {prob.experiments[i].label!r}: the fitted "
                            f"simulation has status {row.get('status')!r}, not a limit cycle")
    residuals: dict[str, dict[str, float | None]] = {}
    simulated: dict[str, dict[str, float | None]] = {}
    measured: dict[str, dict[str, float]] = {}
    status: dict[str, str] = {}
    for i, exp in enumerate(prob.experiments):
        residuals[exp.label] = {}
        measured[exp.label] = dict(exp.features)
        simulated[exp.label] = {name: _sim_feature(rows[i], name) for name in FEATURES}
        status[exp.label] = str(rows[i].get("status"))
    for j, (i, name) in enumerate(prob.layout):
        sim = simulated[prob.experiments[i].label][name]
        meas = prob.measured[j]
        residuals[prob.experiments[i].label][name] = (
            None if sim is None else float((sim - meas) / meas))
    return FitResult(
        keys=prob.keys,
        estimate={k: float(v) for k, v in zip(prob.keys, p, strict=True)},
        stderr=stderr,
        residuals=residuals,
        simulated=simulated,
        measured=measured,
        status=status,
        cost=cost,
        warnings=warnings,
        bounds={k: (float(lo), float(hi))
                for k, lo, hi in zip(prob.keys, prob.lo, prob.hi, strict=True)},
        singular_values=sv,
        correlation=corr,
        global_cost=global_cost,
        generations=int(de.nit),
        evaluations=prob.nfev + (search.nfev if search is not prob else 0),
        seconds=time.perf_counter() - t0,
        constraints=[f"{prob.keys[i_s]} >= {prob.keys[ic]}" for ic, i_s in prob.pairs],
        extra={"configs": prob.configs},
    )


def experiment_config(result: FitResult, experiment_index: int) -> Config:
    """The configuration of one experiment at the fitted estimate (for plots)."""
    cfg = result.extra["configs"][experiment_index]
    return cfg.with_values(result.estimate)
