r"""The plant as a python-control system (:func:`to_control`, :func:`linearize`).

An outer layer: this module imports python-control, the model does not.
``frictionlab.to_control`` and ``frictionlab.linearize`` load it on first use.

The system
----------
:func:`to_control` returns the continuous-time plant of eq. (6) with the
configured arm friction, as a ``control.NonlinearIOSystem``:

=========  =============  ==============================================  =======
role       name           meaning                                         unit
=========  =============  ==============================================  =======
input      ``u``          commanded arm tip acceleration (eq. 1)          m/s^2
state      ``theta``      pendulum angle, 0 = upright                     rad
state      ``theta_dot``  pendulum angular velocity                       rad/s
state      ``arm``        arm angle :math:`\Omega`                        rad
state      ``arm_dot``    arm angular velocity :math:`\dot\Omega`         rad/s
state      ``z``          LuGre bristle deflection (``lugre`` only)       m/s^2 per
                                                                          sigma0
output     ``theta``      measured pendulum angle                         rad
output     ``arm``        measured arm angle                              rad
output     ``arm_dot``    measured arm velocity                           rad/s
=========  =============  ==============================================  =======

The outputs are the three signals the rig measures (the C of eq. 7), without
the sensor's noise and quantisation.  The state derivative is
:func:`frictionlab.model.plants.thesis.rhs` (eq. 6, with ``plant.input_gain``), or
for a motor plant (``--plant furuta-dc|qube2|qube3``: u the motor voltage, friction
in volts) :func:`frictionlab.model.plants.furuta_dc.rhs`, driven by the
friction law of :mod:`frictionlab.model.friction` that the simulator uses, evaluated
at the current state: viscous, the ideal Coulomb relay, stiction + Coulomb
with the zero-velocity band (the applied force is ``input_gain * u``), its
Stribeck form, and LuGre (eq. 18, its bristle state ``z`` as a fifth state,
with eq. (19)'s term of gain ``friction.observer_gain`` and error
``e = -theta``, as in the simulator).  The Coulomb relay
with hysteresis (``friction.hysteresis > 0``) has memory that a
continuous-time state cannot hold and is refused.  The discontinuous laws
make the right-hand side discontinuous at zero arm velocity: integrate
with small steps (or use :func:`frictionlab.simulate_config`, whose
integrator handles sticking exactly).

The linearisation
-----------------
:func:`linearize` linearises that system about the upright equilibrium
(all states 0, u = 0) with python-control.  With friction ``none`` it is
eq. (7) plus the damping term :math:`-2\zeta\omega_0` in ``A[1, 1]`` (eq. 7
exactly when ``plant.zeta`` = 0), with ``B`` scaled by ``plant.input_gain``.
The smooth friction laws enter: viscous friction adds
:math:`-F_v/L_1` to the arm, LuGre its pre-sliding spring and damper (states
``z``: :math:`\dot z = \dot\Omega + k\theta`, :math:`F = \sigma_0 z +
\sigma_1 \dot z + F_v \dot\Omega`).  Coulomb, stiction and Stribeck friction have no derivative at
zero velocity; they are left out of the linearisation (their effect, the
limit cycle, is what :func:`frictionlab.simulate` and the limit-cycle
analysis are for), so it is the frictionless one for those models.
"""

from __future__ import annotations

import dataclasses
import math

import control
import numpy as np

from .config import Config, build_config
from .model.friction import COULOMB, KINDS, LUGRE, NONE, friction_step, lugre_dz, lugre_force
from .model.plants.furuta_dc import dc_accelerations, dc_record
from .model.plants.furuta_dc import rhs as dc_rhs
from .model.plants.thesis import ARM, ARM_DOT, THETA, Z, rhs

__all__ = ["INPUTS", "OUTPUTS", "STATES", "linearize", "to_control"]

#: Input, mechanical state and output names of :func:`to_control`'s system.
INPUTS = ("u",)
STATES = ("theta", "theta_dot", "arm", "arm_dot")
OUTPUTS = ("theta", "arm", "arm_dot")
#: Output rows: the measured states.
_MEASURED = [THETA, ARM, ARM_DOT]
#: Friction models whose law is smooth at zero velocity (kept by :func:`linearize`).
_SMOOTH = ("none", "viscous", "lugre")


def _config(config: Config | None) -> Config:
    if config is None:
        return build_config()
    if not isinstance(config, Config):
        raise TypeError(f"config must be a frictionlab Config (build_config(...)), "
                        f"got {type(config).__name__}")
    return config


def to_control(config: Config | None = None) -> control.NonlinearIOSystem:
    """The plant of eq. (6) with its arm friction as a python-control system.

    Parameters
    ----------
    config : Config, optional
        Plant (``plant.*``) and friction (``--friction``, ``friction.*``)
        settings; default :func:`frictionlab.build_config` (the thesis's
        plant with classical friction).  Design and simulation settings are
        not used.

    Returns
    -------
    control.NonlinearIOSystem
        Continuous time; input ``u``; states ``theta, theta_dot, arm,
        arm_dot`` (and ``z`` for LuGre friction); outputs ``theta, arm,
        arm_dot`` (see the module docstring).

    Raises
    ------
    ValueError
        For the Coulomb relay with hysteresis (``friction.hysteresis > 0``).

    Examples
    --------
    >>> import control, numpy as np, frictionlab as fl
    >>> sys = fl.to_control(fl.build_config(friction="lugre"))
    >>> t = np.linspace(0.0, 0.5, 51)
    >>> resp = control.input_output_response(sys, t, np.zeros_like(t), [0.05, 0, 0, 0, 0])
    """
    cfg = _config(config)
    kind = KINDS.index(cfg.friction_kind)
    fp = cfg.friction.record()
    if kind == COULOMB and cfg.friction.hysteresis > 0.0:
        raise ValueError(
            f"friction.hysteresis = {cfg.friction.hysteresis:g}: the Coulomb relay with "
            "hysteresis has a memory a continuous-time system cannot hold; use "
            "friction.hysteresis=0 (the ideal relay) or the sampled simulator")
    plant = cfg.plant
    motor = cfg.motor
    ku = 1.0 if motor else plant.input_gain
    step = dc_rhs if motor else rhs
    rec = plant.record()
    states = (*STATES, "z") if kind == LUGRE else STATES

    def external(x, u0):
        # what the classical law's stiction holds: the applied force (eq. 17);
        # for a motor plant the voltage that would hold the arm still
        # (frictionlab.model.plants.furuta_dc's docstring)
        if not motor:
            return ku * u0
        th = float(x[THETA])
        _, arm_dd, _, g_arm = dc_accelerations(math.sin(th), math.cos(th), float(x[1]),
                                               float(x[ARM_DOT]), u0, dc_record(rec))
        return arm_dd / g_arm

    def updfcn(t, x, u, params):
        x = np.asarray(x, dtype=float)
        u0 = float(np.asarray(u, dtype=float).reshape(-1)[0])
        v = float(x[ARM_DOT])
        if kind == LUGRE:
            # eq. (19)'s term k e with the plant's error e = -theta, as in the simulator
            dz = lugre_dz(v, float(x[Z]), -float(x[THETA]), fp)
            friction = lugre_force(v, float(x[Z]), dz, fp)
        elif kind == NONE:
            friction = 0.0
        else:
            friction, _ = friction_step(kind, fp, 0.0, v, external(x, u0), 0.0, 0.0)
        dx = step(t, x, (u0, friction), plant)
        if kind == LUGRE:
            dx[Z] = dz
        return dx

    def outfcn(t, x, u, params):
        return np.asarray(x, dtype=float)[_MEASURED]

    return control.NonlinearIOSystem(
        updfcn, outfcn, inputs=list(INPUTS), outputs=list(OUTPUTS), states=list(states),
        name=f"frictionlab_{cfg.friction_kind}")


def linearize(config: Config | None = None) -> control.StateSpace:
    """The upright linearisation of :func:`to_control`'s plant, eq. (7).

    Parameters
    ----------
    config : Config, optional
        As for :func:`to_control`.  Viscous and LuGre friction enter the
        linearisation; Coulomb, stiction and Stribeck friction, discontinuous
        at zero velocity, are left out (module docstring).

    Returns
    -------
    control.StateSpace
        Continuous time, with the state, input and output names of
        :func:`to_control`.  With friction ``none`` and ``plant.zeta`` = 0 it
        is eq. (7): ``A = [[0, 1, 0, 0], [w0^2, 0, 0, 0], [0, 0, 0, 1],
        [0, 0, 0, 0]]``, ``B = k_u [0, -w0^2/g, 0, 1/L1]^T``.

    Examples
    --------
    >>> import control, frictionlab as fl
    >>> cfg = fl.build_config("fast", "none")
    >>> sysd = control.c2d(fl.linearize(cfg), cfg.design.h)   # the design model
    """
    cfg = _config(config)
    if cfg.friction_kind not in _SMOOTH:
        cfg = dataclasses.replace(cfg, friction_kind="none")
    sys = to_control(cfg)
    x0 = np.zeros(sys.nstates)
    # eq. (6) is odd about the upright equilibrium, so python-control's
    # forward differences are exact there to O(eps^2): far below 1e-9
    return sys.linearize(x0, 0.0, copy_names=True,
                         name=f"frictionlab_linearized_{cfg.friction_kind}")

