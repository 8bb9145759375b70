r"""Predicting the friction limit cycle: describing function and exact periodic orbit.

Two predictions of the cycle :func:`frictionlab.model.simulation.simulate` runs into
(Sec. 4.1 names the describing function; the thesis itself only simulated):

* :func:`describing_function` -- the friction law against the linearised
  sampled loop seen from the friction input
  (:func:`frictionlab.model.periodic.linear_loop`), with python-control's
  describing-function tools; amplitude and period where the loop's Nyquist
  curve meets :math:`-1/N(A)`.
* :func:`frictionlab.model.periodic.periodic_orbit` -- the cycle as a fixed point of
  the loop's period map, with its features and Floquet multipliers.

:func:`predict` runs both; it is what ``frictionlab predict`` prints.

Describing function
-------------------
With the arm velocity :math:`v = A\sin\omega t` the friction's fundamental is
:math:`N(A)\,v`; the loop closes through the linear part
:math:`H(z)` from an arm acceleration ``w`` (friction enters as ``w = -F``) to
:math:`v`, so a cycle needs :math:`1 + H(e^{j\omega h})N(A) = 0`.  The
friction laws and their N:

* ``coulomb``: the relay with hysteresis :math:`\pm\varepsilon` of Sec. 6.1,
  python-control's ``relay_hysteresis_nonlinearity(F_C, eps)``,
  :math:`N = \frac{4F_C}{\pi A}(\sqrt{1 - \varepsilon^2/A^2} - j\varepsilon/A)`;
* ``classical`` (Coulomb with stiction, eq. 17): along a sinusoidal velocity
  the arm is never at rest, so stiction never acts and N is the Coulomb
  relay's :math:`4F_C/(\pi A)`.  This is the method's blind spot: the
  simulated cycles stick at the turning points, and the longer they stick
  the further the prediction falls off (docs/predict.md);
* ``stribeck`` and ``lugre``: the steady-state friction curve
  :math:`s(v)\,\mathrm{sgn}\,v + F_v v` (eq. 18 at rest of the bristle), a
  static odd curve whose N is integrated numerically (bristle dynamics,
  stiction and the LuGre plant's eq. (19) term ``friction.observer_gain``
  are outside the describing function).

Compensated loops (two friction laws, one inside the controller) are not
covered: their describing function is left ``null``.

python-control and sampled systems
----------------------------------
``control.describing_function_response`` (0.10) mishandles discrete-time
systems: the frequencies it returns are read off the imaginary part of its
z-plane contour, :math:`\sin(\omega h)` (close to :math:`\omega h`) instead
of :math:`\omega`, and its refinement step evaluates the system at
:math:`z = j\omega`.  The workaround used here: evaluate the sampled loop's
frequency response :math:`H(e^{j\omega h})` on a grid (rad/s) and hand
python-control that as a continuous-time, spline-interpolated
``FrequencyResponseData``; its intersections are then in rad/s and are
polished against the exact :math:`H(e^{j\omega h})` with a root finder.
"""

from __future__ import annotations

import itertools
import math
import warnings
from dataclasses import dataclass, field

import control as ct
import numpy as np
import scipy.integrate
import scipy.optimize

from ..config import Config
from ..model.friction import stribeck_classical_force, stribeck_curve
from ..model.periodic import (
    LinearLoop,
    PeriodicOrbit,
    linear_loop,
    orbit_trajectory,
    periodic_orbit,
)
from ..plotting import TRACES, axis_label, config_title, plt, save_figure
from ..runs import loop_spec

__all__ = [
    "DescribingFunctionPrediction",
    "Intersection",
    "Prediction",
    "StaticFrictionNonlinearity",
    "describing_function",
    "discrete_describing_function_response",
    "friction_nonlinearity",
    "plot_prediction",
    "predict",
]


class StaticFrictionNonlinearity(ct.DescribingFunctionNonlinearity):
    """An odd static friction curve ``F(v)`` with its describing function.

    Parameters
    ----------
    curve : callable
        ``F(v)`` (m/s^2 for rad/s), odd in v, smooth for v > 0 except at
        ``breakpoints``.
    name : str
        Description for reports.
    breakpoints : sequence of float
        Positive velocities where the curve jumps (a zero-velocity band's edge).
    """

    _nodes, _weights = np.polynomial.legendre.leggauss(48)

    def __init__(self, curve, name: str, breakpoints=()):
        super().__init__()
        self.curve = curve
        self.name = name
        self.breakpoints = tuple(sorted(b for b in breakpoints if b > 0))

    def __call__(self, x):
        return self.curve(float(x))

    def _isstatic(self):
        return True

    def describing_function(self, A):
        r""":math:`N(A) = \frac{4}{\pi A}\int_0^{\pi/2} F(A\sin\theta)\sin\theta\,d\theta`
        (Gauss-Legendre on each smooth piece between the breakpoints)."""
        if A < 0:
            raise ValueError("cannot evaluate describing function for A < 0")
        if A == 0:
            return complex(np.nan)
        edges = [0.0] + [math.asin(b / A) for b in self.breakpoints if b < A] + [0.5 * math.pi]
        total = 0.0
        for lo, hi in itertools.pairwise(edges):
            th = 0.5 * (hi - lo) * self._nodes + 0.5 * (hi + lo)
            vals = np.array([self.curve(A * math.sin(t)) for t in th]) * np.sin(th)
            total += 0.5 * (hi - lo) * float(vals @ self._weights)
        return complex(4.0 * total / (math.pi * A))


def friction_nonlinearity(cfg: Config):
    """The describing-function nonlinearity of the plant's friction (module docstring).

    Returns
    -------
    (nonlinearity, description) or (None, reason)
    """
    p = cfg.friction
    kind = cfg.friction_kind
    u = cfg.plant_model.u_unit  # the friction levels' unit, that of u
    uv = f"{u}/(rad/s)"
    if kind == "coulomb":
        nl = ct.relay_hysteresis_nonlinearity(p.coulomb, p.hysteresis)
        return nl, f"relay F_C = {p.coulomb:g} {u} with hysteresis eps = {p.hysteresis:g} rad/s"
    if kind == "classical":
        nl = ct.relay_hysteresis_nonlinearity(p.coulomb, 0.0)
        return nl, (f"Coulomb relay F_C = {p.coulomb:g} {u} (stiction F_S = {p.stiction:g} {u} "
                    "acts only at rest, which a sinusoidal velocity never is)")
    if kind in ("stribeck", "lugre"):
        # steady sliding: s(v) sgn v (+ F_v v for LuGre); the stribeck form's
        # zero-velocity band counts as rest (no friction without applied force)
        rec = p.record()
        if kind == "lugre":
            def curve(v):
                return stribeck_curve(v, rec)
            band = ()
        else:
            def curve(v):
                return stribeck_classical_force(v, 0.0, rec)
            band = (p.hysteresis if p.hysteresis > 0 else p.zero_velocity_band,)
        return (StaticFrictionNonlinearity(curve, f"{kind} steady-state curve", band),
                f"{kind} steady-state curve (F_S = {p.stiction:g} {u}, F_C = {p.coulomb:g} {u}, "
                f"v_S = {p.stribeck_velocity:g} rad/s"
                + (f", F_v = {p.viscous:g} {uv})" if kind == "lugre" else ")"))
    return None, f"the {kind!r} friction has no describing-function limit cycle"


@dataclass(frozen=True)
class Intersection:
    """One solution of :math:`1 + H(e^{j\\omega h})N(A) = 0`.

    Attributes
    ----------
    amplitude : float
        Arm-velocity amplitude A (rad/s), the friction's input.
    omega : float
        Frequency (rad/s).
    stable : bool
        Loeb's criterion: a disturbed amplitude returns to A.
    pendulum_amplitude, u_amplitude : float
        Fundamental amplitude of the pendulum angle (rad) and of u (m/s^2).
    residual : float
        :math:`|1 + H N|` at the solution.
    """

    amplitude: float
    omega: float
    stable: bool
    pendulum_amplitude: float
    u_amplitude: float
    residual: float

    @property
    def period(self) -> float:
        return 2.0 * math.pi / self.omega

    def as_dict(self) -> dict:
        return {"amplitude": self.amplitude, "period": self.period, "stable": self.stable,
                "pendulum_amplitude": self.pendulum_amplitude,
                "u_amplitude": self.u_amplitude, "residual": self.residual}


@dataclass(frozen=True)
class DescribingFunctionPrediction:
    """Result of :func:`describing_function`.

    ``amplitude``/``period`` are those of the predicted stable cycle (the
    largest stable intersection), None when there is none.
    """

    amplitude: float | None
    period: float | None
    pendulum_amplitude: float | None
    u_amplitude: float | None
    intersections: tuple[Intersection, ...]
    nonlinearity: str
    message: str = ""

    def interface_dict(self) -> dict:
        """The ``describing_function`` object of ``frictionlab predict --json``."""
        return {"amplitude": self.amplitude, "period": self.period,
                "pendulum_amplitude": self.pendulum_amplitude,
                "u_amplitude": self.u_amplitude,
                "intersections": [i.as_dict() for i in self.intersections],
                "nonlinearity": self.nonlinearity, "message": self.message}


def discrete_describing_function_response(H_of_omega, F, amplitudes, omega):
    """python-control's describing-function intersections for a sampled loop.

    ``control.describing_function_response`` returns wrong frequencies for
    discrete-time systems (module docstring); this hands it the sampled
    loop's frequency response as a continuous-time, spline-interpolated
    ``FrequencyResponseData`` on the grid ``omega`` (rad/s) instead.

    Parameters
    ----------
    H_of_omega : callable
        ``omega -> H(e^{j omega h})`` (vectorised).
    F : nonlinearity
        A python-control describing-function nonlinearity.
    amplitudes, omega : array_like
        Amplitude grid of -1/N(A) and frequency grid (rad/s, below pi/h).

    Returns
    -------
    list of (A, omega)
        The intersections, omega in rad/s.
    """
    omega = np.asarray(omega, dtype=float)
    frd = ct.frd(H_of_omega(omega), omega, smooth=True)
    with warnings.catch_warnings():
        # off-grid refinement warnings and Nyquist-count notes on a partial contour
        warnings.simplefilter("ignore")
        resp = ct.describing_function_response(frd, F, np.asarray(amplitudes, dtype=float),
                                               omega, refine=True, warn_nyquist=False)
    return [(float(a), float(w)) for a, w in resp.intersections]


def _polish(H, F, a, w, w_max):
    """Solve 1 + H(w) N(a) = 0 exactly from (a, w) (log-amplitude, frequency)."""

    def g(x):
        aa, ww = math.exp(x[0]), x[1]
        val = 1.0 + H(np.array([ww]))[0] * ct.describing_function(F, aa)
        return [val.real, val.imag]

    sol = scipy.optimize.root(g, [math.log(a), w], method="hybr", tol=1e-12)
    if sol.success and 0 < sol.x[1] < w_max:
        return math.exp(sol.x[0]), float(sol.x[1])
    return a, w


def _loeb_stable(H, F, a: float, w: float, d: float = 1e-4) -> bool:
    r"""Loeb's criterion: the cycle at ``(a, w)`` is stable when the critical
    locus :math:`C(A) = -1/N(A)` crosses the Nyquist curve :math:`H` from its
    unstable side as A grows, i.e. when
    :math:`\mathrm{Im}(\overline{C'(A)}\,H'(\omega)) < 0` (derivatives by
    central differences; for a relay, whose locus runs out along the negative
    real axis, this is the Nyquist curve passing that axis upwards)."""

    def C(A):
        return -1.0 / complex(ct.describing_function(F, A))

    dC = (C(a * (1 + d)) - C(a * (1 - d))) / (2 * a * d)
    hw = H(np.array([w * (1 - d), w * (1 + d)]))
    dH = (hw[1] - hw[0]) / (2 * w * d)
    return bool((np.conj(dC) * dH).imag < 0.0)


def describing_function(cfg: Config, *, amplitudes=None, omega=None,
                        loop: LinearLoop | None = None) -> DescribingFunctionPrediction:
    """Describing-function prediction of the friction limit cycle.

    Parameters
    ----------
    cfg : Config
    amplitudes : array_like, optional
        Arm-velocity amplitudes (rad/s) of the -1/N(A) locus (default 400
        points log-spaced over 1e-3 .. 1e3).
    omega : array_like, optional
        Frequencies (rad/s) of the Nyquist curve (default 4000 points
        log-spaced from 0.05 rad/s to just below the Nyquist frequency pi/h).
    loop : LinearLoop, optional
        The linear part (default :func:`frictionlab.model.periodic.linear_loop`).
    """
    nl, name = friction_nonlinearity(cfg)
    if nl is None:
        return DescribingFunctionPrediction(None, None, None, None, (), "", name)
    if cfg.compensation_kind != "none":
        return DescribingFunctionPrediction(
            None, None, None, None, (), name,
            "the describing function covers the uncompensated loop only")
    loop = loop or linear_loop(loop_spec(cfg))
    w_nyq = math.pi / loop.h
    if omega is None:
        omega = np.logspace(math.log10(0.05), math.log10(0.999 * w_nyq), 800)
    if amplitudes is None:
        amplitudes = np.logspace(-3, 3, 61)

    def H(w):
        return loop.frequency_response(w, "arm_dot")

    amplitudes = np.asarray(amplitudes, dtype=float)
    with np.errstate(invalid="ignore"):
        # no -1/N below a relay's hysteresis or inside a zero-velocity band
        n_vals = ct.describing_function(nl, amplitudes)
        amplitudes = amplitudes[np.isfinite(n_vals) & (np.abs(n_vals) > 0)]
    found = []
    for a, w in discrete_describing_function_response(H, nl, amplitudes, omega):
        a, w = _polish(H, nl, a, w, w_nyq)
        N = complex(ct.describing_function(nl, a))
        res = abs(1.0 + H(np.array([w]))[0] * N)
        if not res < 1e-6 or any(abs(a - f.amplitude) < 1e-6 * a and abs(w - f.omega) < 1e-6 * w
                                 for f in found):
            continue
        stable = _loeb_stable(H, nl, a, w)
        # the other signals' fundamentals: w = -N v
        wamp = abs(N) * a
        th = abs(loop.frequency_response([w], "theta")[0]) * wamp
        u = abs(loop.frequency_response([w], "u")[0]) * wamp
        found.append(Intersection(a, w, stable, float(th), float(u), float(res)))
    found.sort(key=lambda i: i.amplitude)
    stable = [i for i in found if i.stable]
    best = stable[-1] if stable else None
    msg = "" if best else ("no intersection of the Nyquist curve with -1/N(A)" if not found
                           else "no stable intersection")
    if best is None:
        return DescribingFunctionPrediction(None, None, None, None, tuple(found), name, msg)
    return DescribingFunctionPrediction(best.amplitude, best.period, best.pendulum_amplitude,
                                        best.u_amplitude, tuple(found), name, msg)


@dataclass(frozen=True)
class Prediction:
    """Both predictions of the loop's friction limit cycle."""

    periodic_orbit: PeriodicOrbit
    describing_function: DescribingFunctionPrediction
    notes: list[str] = field(default_factory=list)

    def interface_dict(self) -> dict:
        """The ``frictionlab predict --json`` object."""
        return {"periodic_orbit": self.periodic_orbit.interface_dict(),
                "describing_function": self.describing_function.interface_dict(),
                "notes": list(self.notes)}


def predict(cfg: Config, **orbit_options) -> Prediction:
    """Predict the friction limit cycle of ``cfg`` both ways.

    Parameters
    ----------
    cfg : Config
    **orbit_options
        Passed to :func:`frictionlab.model.periodic.periodic_orbit`.
    """
    notes = []
    if cfg.sim.noise > 0:
        notes.append("sim.noise is ignored: both predictions are of the noise-free loop")
    return Prediction(periodic_orbit(loop_spec(cfg), **orbit_options), describing_function(cfg),
                      notes)


def plot_prediction(cfg: Config, result: Prediction, path: str) -> str:
    r"""Draw both predictions: the Nyquist picture and the orbit against the DF's sinusoid.

    Left: the sampled loop's Nyquist curve :math:`H(e^{j\omega h})` (arm
    velocity per unit arm acceleration, dash-dot) with the critical locus
    :math:`-1/N(A)` (dotted) and their intersections (stable: dots, unstable:
    crosses).  Right: the periodic orbit's measured pendulum angle over one
    period (solid) and the describing function's sinusoid of the predicted
    pendulum amplitude and period (dash-dot).  The path is printed on stderr.
    """
    loop = linear_loop(loop_spec(cfg))
    nl, _ = friction_nonlinearity(cfg)
    df, po = result.describing_function, result.periodic_orbit
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 5.0))
    w_ref = 2 * math.pi / (df.period or po.period or 1.0)
    w = np.logspace(math.log10(0.2 * w_ref),
                    math.log10(min(10 * w_ref, 0.999 * math.pi / loop.h)), 600)
    Hw = loop.frequency_response(w, "arm_dot")
    ax.plot(Hw.real, Hw.imag, label=r"$H(e^{j\omega h})$, loop seen from the friction",
            **TRACES["model"])
    if nl is not None and df.nonlinearity:
        a_ref = df.amplitude or 1.0
        A = np.linspace(0.2 * a_ref, 2.0 * a_ref, 200)
        with np.errstate(invalid="ignore", divide="ignore"):
            C = -1.0 / ct.describing_function(nl, A)
        ax.plot(C.real, C.imag, label=r"$-1/N(A)$, friction",
                **{**TRACES["reference"], "lw": 2.4})
    for i in df.intersections:
        if df.amplitude is not None and i.amplitude < 0.1 * df.amplitude:
            continue
        pt = loop.frequency_response([i.omega], "arm_dot")[0]
        ax.plot(pt.real, pt.imag, "o" if i.stable else "x", color="k", ms=7, ls="none",
                label=f"A = {i.amplitude:.3g} rad/s, T = {i.period:.3g} s"
                      + ("" if i.stable else " (unstable)"))
    ax.axhline(0, color="0.85", lw=0.6, zorder=0)
    ax.axvline(0, color="0.85", lw=0.6, zorder=0)
    ax.set_xlabel(axis_label("Re H", "(rad/s)/(m/s^2)"))
    ax.set_ylabel(axis_label("Im H", "(rad/s)/(m/s^2)"))
    ax.set_title("describing function", fontsize=10)
    ax.legend(fontsize=8, loc="best")
    ax.grid(alpha=0.3)
    if po.found:
        traj = orbit_trajectory(loop_spec(cfg), po.state, po.period + loop.h)
        bx.plot(traj.t, traj["theta_m"], label=f"periodic orbit, measured (T = {po.period:.3g} s)",
                **TRACES["measured"])
    if df.pendulum_amplitude is not None:
        T = df.period
        t = np.linspace(0, T, 300)
        bx.plot(t, df.pendulum_amplitude * np.sin(2 * math.pi * t / T),
                label=f"describing function, 1st harmonic (T = {T:.3g} s)", **TRACES["model"])
    bx.set_xlabel(axis_label("time from the upward zero crossing", "s"))
    bx.set_ylabel(axis_label("pendulum angle", "rad"))
    bx.set_title("one period" + ("" if po.found else ": no periodic orbit found")
                 + ("" if po.stable in (None, True) else " (unstable orbit)"), fontsize=10)
    bx.legend(fontsize=8, loc="best")
    bx.grid(alpha=0.3)
    fig.suptitle(config_title(cfg, "frictionlab predict"), fontsize=9)
    return save_figure(fig, path)
