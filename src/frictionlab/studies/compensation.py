r"""Model-based friction compensation (Sec. 6): compensators, metrics and tuning.

A compensator estimates the arm friction :math:`\hat F` from the measured arm
velocity and adds it to the feedback control, :math:`u = u_{fb} + \hat F`, so
that the plant's net arm acceleration :math:`u - F` (eq. 5) is close to the
intended :math:`u_{fb}`.  Three compensators, as in Sec. 6.1-6.3:

``coulomb``
    :math:`\hat F = F_C s` with the relay :math:`s` switching at
    :math:`\pm\varepsilon` (Sec. 6.1; state: the relay).
``classical``
    The implementation form of eq. (17) (Sec. 6.2): inside the band
    :math:`|\dot\Omega| < \varepsilon` the estimate balances the feedback
    signal (:math:`\hat F = u_{fb}`, limited to :math:`\pm F_S`); outside it is
    the Stribeck level :math:`(F_C + (F_S - F_C)e^{-(\dot\Omega/v_S)^2})
    \mathrm{sgn}\,\dot\Omega`.  Memoryless.
``lugre``
    The observer of eq. (19) with gain k (Sec. 6.3; state: :math:`\hat z`).
``adaptive``
    The same observer with its Coulomb and stiction levels adapted online
    from the applied u and the measured arm velocity (the adaptive friction
    estimator Sec. 8 proposes; law, stability conditions and safety rules in
    :mod:`frictionlab.model.adaptive`; state: :math:`\hat z` and the law's).

The force laws are those of :mod:`frictionlab.model.friction`, called through the
compiled :func:`frictionlab.model.controller.compensator_force` that the simulator
and the real-time loop run; :class:`Compensator` wraps it as an ``init`` /
``step`` pair with explicit state for scripts, tests and other loops.

The LuGre observer's error signal
---------------------------------
Eq. (19) leaves e open.  With :math:`\tilde z = z - \hat z` the estimation
error, :math:`\dot{\tilde z} = -a\tilde z + k e` (:math:`a = \sigma_0|v|/s(v)
\ge 0`), so e must be a signal that the friction error drives *back*.  The
controller feeds the observers :math:`u - \hat F` (see
:mod:`frictionlab.model.controller`), so the arm observer predicts the acceleration
:math:`u - \hat F` while the arm gets :math:`u - F`; the velocity innovation
:math:`e = \dot\Omega_m - \hat{\dot\Omega}` therefore integrates
:math:`-(F - \hat F) \approx -\sigma_0\tilde z`, and :math:`\dot{\tilde z} =
-a\tilde z - k\sigma_0\int\tilde z` is a damped oscillator: the observer
corrects itself.  The arm's control errors carry no such information and, in
simulation, make the loop fall; docs/compensation.md has the comparison and
:data:`frictionlab.model.controller.DEFAULT_ERROR_SIGNAL` is the result.

Bristle discretisation
----------------------
:math:`\hat z` is advanced with the exact exponential update for the velocity
held over the sample (:func:`frictionlab.model.friction.lugre_step_exact`), which is
stable for any :math:`\sigma_0` and exact in steady sliding.  Forward Euler,
:math:`\hat z^+ = \hat z + h\dot{\hat z}`, has the multiplier
:math:`1 - ah` and diverges once :math:`ah > 2`, i.e. at h = 5 ms for
:math:`\sigma_0|v|/s(v) > 400` 1/s.  With the compensator's defaults
(:math:`F_S` 2.3, :math:`F_C` 1.55, :math:`v_S` 1) that is :math:`|v| > 2.08`
rad/s at :math:`\sigma_0 = 300` and :math:`|v| > 0.78` rad/s at
:math:`\sigma_0 = 1000`, inside the limit cycles of Sec. 5 (3-6 rad/s) - the
likely "numerical problems" of Sec. 6.3.

A LuGre model with :math:`F_S = F_C = 0` (on either side of the velocity) makes
:math:`g(v) = s(v)/\sigma_0` vanish for every v and eq. (19) singular;
:func:`check_compensator` rejects it before anything runs.

Tuning
------
:func:`tune` runs a grid of ``compensation.*`` values, and the loop without
compensation, through the sweep engine (:func:`frictionlab.studies.sweep.evaluate`)
and picks the point with the smallest ``score = peak_to_peak * (1 + w *
reversals/s)`` (peak-to-peak of the measured pendulum angle).  Chatter is a
property of the friction estimate's and u's time series, so the engine
reduces each run with :func:`features_and_chatter`, in its workers, instead
of to its limit-cycle features alone: every point's row carries both, and no
run is repeated to rank it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .. import runs
from ..config import COMPENSATOR_FIELDS, Config, ConfigError, check_compensator
from ..model.controller import (
    COMPENSATOR_CODES,
    COMPENSATORS,
    DEFAULT_ERROR_SIGNAL,
    ERROR_SIGNALS,
    adaptive_force,
    compensator_force,
    compensator_params,
    new_state,
)
from ..model.friction import LUGRE, FrictionParams, copy_friction, with_levels
from ..model.limit_cycles import trajectory_features
from ..model.plants.thesis import PlantParams
from ..model.rig import RigScaling
from . import sweep
from .sweep import make_points, validate_points

#: The smallest peak-to-peak a reduction ratio divides by: one quantum of the rig's
#: pendulum-angle ADC (12 bits, App. B), about 1.5 mrad.  A compensated run whose
#: limit cycle dies out completely (no noise, no quantization) would otherwise
#: report a ratio of 1e17; the rig could not measure anything below one quantum.
PEAK_TO_PEAK_FLOOR = RigScaling().quanta()[0]

__all__ = [
    "COMPENSATORS",
    "DEFAULT_GRIDS",
    "AdaptiveCompensator",
    "ChatterMetrics",
    "ClassicalCompensator",
    "Comparison",
    "Compensator",
    "CompensatorState",
    "CoulombCompensator",
    "LuGreCompensator",
    "TuneResult",
    "chatter",
    "check_compensator",
    "check_grid",
    "compare",
    "default_grid",
    "features_and_chatter",
    "make_compensator",
    "reversals",
    "tune",
]


@dataclass(frozen=True)
class CompensatorState:
    """Explicit state of a compensator.

    Attributes
    ----------
    relay : float
        Coulomb relay output (-1, 0 or +1).
    z_hat : float
        LuGre bristle estimate :math:`\\hat z` (rad).
    friction_estimate : float
        The last :math:`\\hat F` (m/s^2).
    adaptation : tuple of float
        The adaptive law's state (``adaptive`` only): predicted and last
        measured arm velocity, the estimated F_C and F_S, the status code and
        the distance slid (the controller state's fields ``v_hat`` ...
        ``slide``); empty before the first step.
    """

    relay: float = 0.0
    z_hat: float = 0.0
    friction_estimate: float = 0.0
    adaptation: tuple[float, ...] = ()


@dataclass(frozen=True)
class Compensator:
    """A friction compensator: ``init() -> state``, ``step(state, ...) -> (F_hat, state)``.

    Parameters
    ----------
    params : FrictionParams
        The compensator's own friction model (keys ``compensation.*``);
        default: the settings Sec. 6 found best on the rig.
    h : float
        Sampling period (s); the LuGre observer integrates over it.
    """

    kind: ClassVar[str] = ""
    params: FrictionParams = None  # type: ignore[assignment]
    h: float = 0.005
    _cp: np.record = dataclasses.field(default=None, init=False, repr=False,
                                        compare=False)

    def __post_init__(self) -> None:
        if self.kind not in COMPENSATORS:
            raise ValueError(f"compensator must be one of {', '.join(COMPENSATORS)}; "
                             f"got {self.kind!r}")
        if self.params is None:
            object.__setattr__(self, "params", FrictionParams.defaults(self.kind,
                                                                       "compensation"))
        if not isinstance(self.params, FrictionParams):
            raise ValueError("params must be a FrictionParams")
        if not (isinstance(self.h, int | float) and math.isfinite(self.h) and 0 < self.h <= 1):
            raise ValueError(f"h must be in (0, 1] s, got {self.h!r}")
        check_compensator(self.kind, self.params, h=self.h,
                          arm_length=getattr(self, "arm_length", None))
        object.__setattr__(self, "_cp", compensator_params(self.params))

    @property
    def code(self) -> int:
        """The compiled code's compensator number."""
        return COMPENSATOR_CODES[self.kind]

    def init(self, z_hat: float = 0.0) -> CompensatorState:
        """Initial state: relay undecided, bristle at ``z_hat`` (default relaxed)."""
        return CompensatorState(0.0, float(z_hat), 0.0)

    def law(self, state: CompensatorState) -> tuple[int, np.record, float]:
        """The friction law this compensator runs as of ``state``: ``(code, p,
        law_state)`` such that its estimate of a step from a state ``prev`` to
        ``state`` is ``friction_step(code, p, law(prev)[2], v, u_fb, h, e)``
        (:func:`frictionlab.model.friction.friction_step`): its model kind, its
        friction record (the adaptive one's with its levels as of ``state``)
        and the law's memory (the relay, else the bristle)."""
        return self.code, self._cp, state.relay if self.kind == "coulomb" else state.z_hat

    def step(self, state: CompensatorState, v: float, *, u_fb: float = 0.0,
             e: float = 0.0) -> tuple[float, CompensatorState]:
        """Friction estimate for the coming sample.

        Parameters
        ----------
        state : CompensatorState
            From :meth:`init` or the previous step (not modified).
        v : float
            Measured arm velocity (rad/s).
        u_fb : float
            Feedback control signal (the classical form balances it inside
            the band).
        e : float
            Error signal of the LuGre observer, eq. (19).

        Returns
        -------
        (F_hat, next_state)
            ``F_hat`` in m/s^2 (added to u).  For LuGre it is the mean of
            eq. (19)'s :math:`\\hat F` over the sample with v held.
        """
        s = new_state(relay=state.relay, z_hat=state.z_hat)
        f = float(compensator_force(self.code, s, self._cp, float(v), float(u_fb), float(e),
                                    float(self.h)))
        return f, CompensatorState(float(s.relay), float(s.z_hat), f)


@dataclass(frozen=True)
class CoulombCompensator(Compensator):
    """Pure Coulomb relay with hysteresis :math:`\\pm\\varepsilon` (Sec. 6.1)."""

    kind: ClassVar[str] = "coulomb"


@dataclass(frozen=True)
class ClassicalCompensator(Compensator):
    """Implementation form of the classical model with Stribeck decay and the
    :math:`\\pm\\varepsilon` band (Sec. 6.2)."""

    kind: ClassVar[str] = "classical"


@dataclass(frozen=True)
class LuGreCompensator(Compensator):
    """The LuGre observer of eq. (19) with gain ``params.observer_gain`` (Sec. 6.3).

    ``error_signal`` names what the controller feeds as e (one of
    :data:`frictionlab.model.controller.ERROR_SIGNALS`); :meth:`step` takes e itself.
    """

    kind: ClassVar[str] = "lugre"
    error_signal: str = DEFAULT_ERROR_SIGNAL

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.error_signal not in ERROR_SIGNALS:
            raise ValueError(f"error_signal must be one of {', '.join(ERROR_SIGNALS)}; "
                             f"got {self.error_signal!r}")


@dataclass(frozen=True)
class AdaptiveCompensator(LuGreCompensator):
    """The LuGre observer of eq. (19) with F_C and F_S adapted online
    (:mod:`frictionlab.model.adaptive`).

    ``arm_length`` (:math:`L_1`, m) and ``u_max`` (the saturation of u) are
    the law's; its gains must meet the stability conditions of
    :func:`frictionlab.model.adaptive.check_gains` for ``h`` and ``arm_length``.
    :meth:`step` takes ``u_prev``, the control applied over the last sample.
    """

    kind: ClassVar[str] = "adaptive"
    arm_length: float = PlantParams().arm_length
    u_max: float = RigScaling().u_max

    def step(self, state: CompensatorState, v: float, *, u_fb: float = 0.0, e: float = 0.0,
             u_prev: float = 0.0) -> tuple[float, CompensatorState]:
        """Friction estimate for the coming sample: one tick of the adaptation law
        (with ``u_prev``, the control applied over the last sample), then the
        observer with the adapted levels.  See :meth:`Compensator.step`."""
        s = new_state(z_hat=state.z_hat, u=u_prev)
        if state.adaptation:
            for name, value in zip(_ADAPTATION_FIELDS, state.adaptation, strict=True):
                setattr(s, name, value)
        f = float(adaptive_force(s, self._cp, float(v), float(e), float(self.h),
                                 float(self.arm_length), float(self.u_max)))
        return f, CompensatorState(0.0, float(s.z_hat), f,
                                   tuple(float(getattr(s, name)) for name in _ADAPTATION_FIELDS))

    def law(self, state: CompensatorState) -> tuple[int, np.record, float]:
        """LuGre with the levels the adaptation had reached by ``state`` (both
        directions); see :meth:`Compensator.law`."""
        fc = fs = None
        if state.adaptation:
            named = dict(zip(_ADAPTATION_FIELDS, state.adaptation, strict=True))
            fc, fs = named["fc_hat"], named["fs_hat"]
        p = self._cp if fc is None else with_levels(self._cp, fc, fs, copy_friction(self._cp))
        return LUGRE, p, state.z_hat


#: The controller state's fields of the adaptive law (:class:`CompensatorState.adaptation`).
_ADAPTATION_FIELDS = ("v_hat", "v_prev", "fc_hat", "fs_hat", "adapt", "slide")

_CLASSES = {"coulomb": CoulombCompensator, "classical": ClassicalCompensator,
            "lugre": LuGreCompensator, "adaptive": AdaptiveCompensator}


def make_compensator(kind: str, params: FrictionParams | None = None, h: float = 0.005,
                     **overrides) -> Compensator:
    """Build a compensator, e.g. ``make_compensator("lugre", sigma0=1000)``.

    Parameters
    ----------
    kind : {"coulomb", "classical", "lugre", "adaptive"}
        The compensator.
    params : FrictionParams, optional
        Its model (default: the compensator's Sec. 6 settings).
    h : float
        Sampling period (s).
    **overrides
        :class:`FrictionParams` fields applied to ``params``.

    Returns
    -------
    Compensator
        A :class:`CoulombCompensator`, :class:`ClassicalCompensator`,
        :class:`LuGreCompensator` or :class:`AdaptiveCompensator`.

    Raises
    ------
    ValueError
        Unknown ``kind``, or an invalid value, named by its key
        (``compensation.sigma0 = inf is out of range ...``); a model
        :func:`check_compensator` rejects (a :class:`ConfigError`).
    """
    if kind not in _CLASSES:
        raise ValueError(f"compensator must be one of {', '.join(COMPENSATORS)}; "
                         f"got {kind!r}")
    base = params if params is not None else FrictionParams.defaults(kind, "compensation")
    if overrides:
        try:
            base = dataclasses.replace(base, **overrides)
        except ValueError as exc:
            # FrictionParams names its fields by the plant's keys (friction.*)
            msg = str(exc)
            prefix = FrictionParams._prefix
            if msg.startswith(prefix):
                msg = "compensation." + msg[len(prefix):]
            raise ValueError(msg) from None
    return _CLASSES[kind](base, h)


# ---------------------------------------------------------------------------
# metrics
# ---------------------------------------------------------------------------


def reversals(signal: np.ndarray, threshold: float) -> int:
    """Full sign reversals of ``signal``: passages from above ``+threshold`` to
    below ``-threshold`` or back (a Schmitt trigger, so noise around zero does
    not count)."""
    x = np.asarray(signal, dtype=float)
    if not threshold > 0:
        raise ValueError(f"threshold must be > 0, got {threshold}")
    side = np.where(x > threshold, 1, np.where(x < -threshold, -1, 0))
    side = side[side != 0]
    return int(np.count_nonzero(np.diff(side)))


@dataclass(frozen=True)
class ChatterMetrics:
    """Control chatter over an analysis window.

    Attributes
    ----------
    reversals_per_s : float
        Sign reversals per second of the friction estimate, counted with a
        Schmitt trigger at half the compensator's Coulomb level (a smooth
        limit cycle has two per period; a toggling relay many more).
    u_roughness : float
        RMS of the sample-to-sample change of u (m/s^2).
    """

    reversals_per_s: float
    u_roughness: float

    def as_dict(self) -> dict[str, float]:
        return dataclasses.asdict(self)


def chatter(traj, window: float | None = None) -> ChatterMetrics:
    """:class:`ChatterMetrics` of a trajectory over its last ``window`` seconds
    (default: the last half)."""
    t = traj.t
    if len(t) < 3:
        return ChatterMetrics(0.0, 0.0)
    span = window if window is not None else 0.5 * (t[-1] - t[0])
    m = t >= t[-1] - span - 1e-12
    seconds = max(float(np.count_nonzero(m)) * traj.h, traj.h)
    f = traj["friction_hat"][m]
    cfg = traj.config
    level = cfg.compensation.coulomb if cfg is not None else 0.0
    thr = 0.5 * level if level > 0 else 0.5 * float(np.max(np.abs(f), initial=0.0))
    n_rev = reversals(f, thr) if thr > 0 else 0
    u = traj["u"][m]
    rough = float(np.sqrt(np.mean(np.diff(u) ** 2))) if len(u) > 1 else 0.0
    return ChatterMetrics(n_rev / seconds, rough)


@dataclass(frozen=True)
class Comparison:
    """One configuration with and without its compensator."""

    status: str
    features: dict[str, Any]
    chatter: ChatterMetrics
    baseline_status: str
    baseline_features: dict[str, Any]
    baseline_chatter: ChatterMetrics

    @property
    def reduction(self) -> float | None:
        """Peak-to-peak without / with compensation (None if undefined).

        The compensated peak-to-peak counts as at least :data:`PEAK_TO_PEAK_FLOOR`.
        """
        a = self.baseline_features.get("peak_to_peak")
        b = self.features.get("peak_to_peak")
        if (a is None or not (b is not None and b >= 0) or self.status == "fell"
                or self.baseline_status == "fell"):
            return None
        return a / max(b, PEAK_TO_PEAK_FLOOR)

    def as_dict(self) -> dict[str, Any]:
        return {"status": self.status, "features": self.features,
                "chatter": self.chatter.as_dict(), "baseline_status": self.baseline_status,
                "baseline_features": self.baseline_features,
                "baseline_chatter": self.baseline_chatter.as_dict(),
                "reduction": self.reduction}


def _run(cfg: Config, duration: float | None, window: float | None, controller=None):
    traj = runs.simulate_config(cfg, duration, controller=controller)
    feats = trajectory_features(traj, window)
    status = "fell" if traj.status == "fell" else feats.status
    return traj, status, feats.interface_dict(), chatter(traj, window)


def features_and_chatter(cfg: Config, duration: float | None,
                         window: float | None) -> dict[str, Any]:
    """One run reduced to its limit-cycle features and its :func:`chatter`.

    The sweep engine's ``reduce`` for :func:`tune` (it runs in the engine's
    workers, so it lives at module level).

    Parameters
    ----------
    cfg : Config
        The run's configuration.
    duration, window : float or None
        As for :func:`frictionlab.runs.run_features`.

    Returns
    -------
    dict
        ``status``, the seven features of
        :data:`frictionlab.model.limit_cycles.FEATURES`, and the fields of
        :class:`ChatterMetrics` (``reversals_per_s``, ``u_roughness``).
    """
    _, status, feats, ch = _run(cfg, duration, window)
    return {**feats, "status": status, **ch.as_dict()}


def compare(cfg: Config, duration: float | None = None, window: float | None = None, *,
            controller=None, return_trajectories: bool = False):
    """Run ``cfg`` with its compensator and with ``compensation = none``.

    Parameters
    ----------
    cfg : Config
        The compensated configuration (``cfg.compensation_kind`` != none).
    duration, window : float, optional
        As for :func:`frictionlab.runs.run_features`.
    controller : Controller, optional
        A controller for the compensated run (e.g. another error signal).
    return_trajectories : bool
        Also return the two trajectories.

    Returns
    -------
    Comparison or (Comparison, Trajectory, Trajectory)
        The comparison, and with ``return_trajectories`` the compensated and
        the baseline trajectories.

    Raises
    ------
    ConfigError
        No compensator, or one :func:`check_compensator` rejects (before
        anything runs).
    """
    if cfg.compensation_kind == "none":
        raise ConfigError("compare needs a compensator (coulomb, classical or lugre)")
    check_compensator(cfg.compensation_kind, cfg.compensation)
    traj, st, feats, ch = _run(cfg, duration, window, controller)
    base_cfg = dataclasses.replace(cfg, compensation_kind="none")
    btraj, bst, bfeats, bch = _run(base_cfg, duration, window)
    out = Comparison(st, feats, ch, bst, bfeats, bch)
    return (out, traj, btraj) if return_trajectories else out


# ---------------------------------------------------------------------------
# tuning
# ---------------------------------------------------------------------------

#: Default search grids of ``frictionlab compensate tune`` around the values
#: Sec. 6 explored (the thesis varied sigma0, sigma1 and k for LuGre; the
#: adaptive compensator's grid varies its law's gains).
DEFAULT_GRIDS: dict[str, list[tuple[str, list[float]]]] = {
    "coulomb": [("compensation.coulomb", [1.1, 1.3, 1.5, 1.7, 1.9]),
                ("compensation.hysteresis", [0.0, 0.01, 0.02, 0.05, 0.08, 0.12])],
    "classical": [("compensation.stiction", [1.9, 2.3, 2.7]),
                  ("compensation.coulomb", [1.3, 1.5, 1.55, 1.7]),
                  ("compensation.stribeck_velocity", [0.5, 1.0, 2.0]),
                  ("compensation.hysteresis", [0.02, 0.05, 0.08, 0.12])],
    "lugre": [("compensation.sigma0", [50.0, 100.0, 300.0, 1000.0]),
              ("compensation.sigma1", [2.0, 4.0, 6.0, 10.0]),
              ("compensation.observer_gain", [1.0, 3.0, 7.0, 15.0])],
    # the adaptation law's gain and bandwidth, with and without eq. (19)'s correction
    "adaptive": [("compensation.adaptation_gain", [50.0, 200.0, 1000.0]),
                 ("compensation.adaptation_bandwidth", [10.0, 20.0, 50.0]),
                 ("compensation.observer_gain", [0.0, 7.0])],
}


#: The grid keys that :func:`default_grid` scales to a motor plant's defaults
#: (levels and gains; velocities, bands and the law's bandwidth are kept).
_SCALED_GRID_FIELDS = ("coulomb", "stiction", "sigma0", "sigma1", "observer_gain",
                       "adaptation_gain")


def default_grid(cfg: Config) -> list[tuple[str, list[float]]]:
    """The default tuning grid of ``cfg``'s compensator.

    :data:`DEFAULT_GRIDS` on the thesis plant.  On a motor plant the same
    grid about the plant's own defaults (:func:`frictionlab.config.motor_friction_defaults`,
    volts): each level or gain value is the motor default times the thesis
    grid's value over the thesis default (the LuGre k grid 1, 3, 7, 15 about
    7 becomes 0.14 to 2.1 times the motor plant's k), so the grid spans the
    same ratios around a setting that is meaningful there.
    """
    kind = cfg.compensation_kind
    grid = DEFAULT_GRIDS.get(kind, [])
    if not cfg.motor:
        return list(grid)
    thesis = FrictionParams.defaults(kind, "compensation")
    out = []
    for key, values in grid:
        field = key.split(".", 1)[1]
        ref = getattr(thesis, field)
        if field in _SCALED_GRID_FIELDS and ref:
            own = getattr(cfg.compensation, field)
            values = [float(f"{v * own / ref:.4g}") for v in values]
        out.append((key, list(values)))
    return out


@dataclass(frozen=True)
class TuneResult:
    """Outcome of :func:`tune`.

    Attributes
    ----------
    best : dict
        The winning ``compensation.*`` values.
    peak_to_peak, score : float
        The winner's peak-to-peak (rad) and penalised score.
    status : str
        The winner's run status.
    chatter : ChatterMetrics
        The winner's chatter.
    baseline_status, baseline_peak_to_peak, baseline_chatter
        The same loop without compensation.
    candidates : list of dict
        Every grid point that kept the pendulum up, best first: values,
        status, peak_to_peak, chatter, score.
    evaluated, failed : int
        Grid points run, and those that fell or errored.
    """

    best: dict[str, float]
    peak_to_peak: float
    score: float
    status: str
    chatter: ChatterMetrics
    baseline_status: str
    baseline_peak_to_peak: float | None
    baseline_chatter: ChatterMetrics
    candidates: list[dict[str, Any]]
    evaluated: int
    failed: int

    @property
    def reduction(self) -> float | None:
        """Baseline peak-to-peak / tuned peak-to-peak (at least :data:`PEAK_TO_PEAK_FLOOR`)."""
        if self.baseline_peak_to_peak is None or not self.peak_to_peak >= 0:
            return None
        return self.baseline_peak_to_peak / max(self.peak_to_peak, PEAK_TO_PEAK_FLOOR)

    def as_dict(self) -> dict[str, Any]:
        return {"best": self.best, "peak_to_peak": self.peak_to_peak, "score": self.score,
                "status": self.status, "chatter": self.chatter.as_dict(),
                "baseline_status": self.baseline_status,
                "baseline_peak_to_peak": self.baseline_peak_to_peak,
                "baseline_chatter": self.baseline_chatter.as_dict(),
                "reduction": self.reduction, "candidates": self.candidates,
                "evaluated": self.evaluated, "failed": self.failed}


def check_grid(cfg: Config, grid: Sequence[tuple[str, Sequence[float]]]) -> list[dict]:
    """The grid's points, every one validated (raises :class:`ConfigError` before
    anything runs): only ``compensation.*`` keys the compensator reads, values in
    range, and a model :func:`check_compensator` accepts."""
    if cfg.compensation_kind == "none":
        raise ConfigError("tuning needs a compensator: coulomb, classical or lugre")
    used = COMPENSATOR_FIELDS[cfg.compensation_kind]
    for key, _ in grid:
        section, _, field = key.partition(".")
        if section != "compensation":
            raise ConfigError(f"tune varies compensator parameters only (compensation.*), "
                              f"got {key!r}")
        if field not in used:
            raise ConfigError(f"{key} has no effect on the {cfg.compensation_kind!r} "
                              f"compensator; it reads {', '.join(sorted(used))}")
    points = make_points(cfg, grid, "grid")
    validate_points(cfg, points)
    for p in points:
        c = cfg.with_values(p)
        check_compensator(c.compensation_kind, c.compensation)
    return points


def tune(
    cfg: Config,
    grid: Sequence[tuple[str, Sequence[float]]] | None = None,
    *,
    duration: float | None = None,
    window: float | None = None,
    chatter_weight: float = 0.05,
    workers: int | None = None,
    dask: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    return_trajectories: bool = False,
):
    """Search compensator parameters that minimise the limit cycle.

    Every grid point, and then the loop without compensation (for the
    reduction ratio and the baseline's chatter), runs through
    :func:`frictionlab.studies.sweep.evaluate` with :func:`features_and_chatter` as
    the reduction, so that each row carries the peak-to-peak of the measured
    pendulum angle and the :func:`chatter`.  Of the points that kept the
    pendulum up (``limit_cycle`` or ``settled`` with a peak-to-peak), the one
    with the smallest ``peak_to_peak * (1 + chatter_weight *
    reversals_per_s)`` wins; ties go to the smaller peak-to-peak, then to the
    earlier grid point.

    Parameters
    ----------
    cfg : Config
        Plant, design and compensator; the grid's keys override its
        ``compensation.*`` values.
    grid : sequence of (key, values), optional
        ``compensation.*`` keys and their values (Cartesian product);
        default :func:`default_grid` (:data:`DEFAULT_GRIDS` of the compensator,
        scaled to a motor plant's defaults).
    duration, window : float, optional
        Per run (defaults: ``sim.duration``; the last half).
    chatter_weight : float
        Penalty weight w (s): 20 reversals/s double the score at w = 0.05.
    workers, dask
        Passed to both :func:`frictionlab.studies.sweep.evaluate` calls.
    progress : callable, optional
        Called as ``progress(done, total)``: runs done of the grid's points
        and the baseline.
    return_trajectories : bool
        Also return the winner's and the baseline's trajectories (for a
        before/after figure; the two runs are simulated once more,
        in-process, and are the runs the rows describe: the simulator is
        deterministic).

    Returns
    -------
    TuneResult or (TuneResult, Trajectory, Trajectory)
        The result, and with ``return_trajectories`` the winner's and the
        baseline's trajectories.

    Raises
    ------
    ConfigError
        Bad grid (unknown or non-compensator keys, invalid values, a model
        :func:`check_compensator` rejects), bad weights; raised before any
        simulation.
    RuntimeError
        No grid point kept the pendulum up, or the run without compensation
        failed (an engine error row).
    """
    if not (isinstance(chatter_weight, int | float) and math.isfinite(chatter_weight)
            and chatter_weight >= 0):
        raise ConfigError(f"chatter weight must be >= 0, got {chatter_weight!r}")
    grid = list(grid) if grid is not None else default_grid(cfg)
    points = check_grid(cfg, grid)
    total = len(points) + 1

    def report(done: int, _: int) -> None:
        if progress is not None:
            progress(done, total)

    run = {"duration": duration, "window": window, "workers": workers, "dask": dask,
           "reduce": features_and_chatter}
    rows = sweep.evaluate(cfg, points, progress=report, **run)
    base_cfg = dataclasses.replace(cfg, compensation_kind="none")
    (brow,) = sweep.evaluate(base_cfg, [{}], progress=lambda d, n: report(total, total), **run)
    if brow["status"] == "error":
        raise RuntimeError(f"the run without compensation failed: {brow['error']}")
    cands = []
    for p, r in zip(points, rows, strict=True):
        if r["status"] not in ("limit_cycle", "settled") or r["peak_to_peak"] is None:
            continue
        ch = _row_chatter(r)
        cands.append({"values": dict(p), "status": r["status"],
                      "peak_to_peak": r["peak_to_peak"], "chatter": ch.as_dict(),
                      "score": r["peak_to_peak"] * (1.0 + chatter_weight * ch.reversals_per_s)})
    if not cands:
        raise RuntimeError(f"every one of the {len(rows)} grid points fell or failed; "
                           "widen the grid")
    cands.sort(key=lambda c: (c["score"], c["peak_to_peak"]))  # stable: then grid order
    win = cands[0]
    res = TuneResult(
        best=win["values"], peak_to_peak=win["peak_to_peak"], score=win["score"],
        status=win["status"], chatter=ChatterMetrics(**win["chatter"]),
        baseline_status=brow["status"],
        baseline_peak_to_peak=None if brow["status"] == "fell" else brow["peak_to_peak"],
        baseline_chatter=_row_chatter(brow), candidates=cands, evaluated=len(rows),
        failed=len(rows) - len(cands))
    if not return_trajectories:
        return res
    return (res, runs.simulate_config(cfg.with_values(res.best), duration),
            runs.simulate_config(base_cfg, duration))


def _row_chatter(row: dict[str, Any]) -> ChatterMetrics:
    """The chatter columns of a row of :func:`features_and_chatter`."""
    return ChatterMetrics(row["reversals_per_s"], row["u_roughness"])
