"""The DC-motor Furuta plant (model/plants/furuta_dc.py): independent checks of
its equations, linearisation, integrator and friction units (issue 30)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from frictionlab.model.friction import KINDS, FrictionParams
from frictionlab.model.params import ParamError
from frictionlab.model.plants.furuta_dc import (
    HOMEBUILT,
    PRESET_FRICTION,
    PRESETS,
    QUBE2,
    QUBE2_WORKBOOK,
    QUBE3,
    SUBSTEPS,
    DCRecord,
    FurutaDCParams,
    linearization,
    max_arm_acceleration,
    mechanical_energy,
    pendulum_energy,
    preset,
    rhs,
    swing_ratio,
    tick,
)

H = 0.005
NO_FRICTION = FrictionParams().record()


def _lossless(p: FurutaDCParams) -> FurutaDCParams:
    """No damping and no back-EMF current (the motor's terminals open)."""
    return dataclasses.replace(p, arm_damping=0.0, pendulum_damping=0.0, emf_constant=0.0)


def _constants(p: FurutaDCParams):
    """J_p, J_0, b, c from the parameters, written here independently of the model."""
    j_p = p.pendulum_mass * p.pendulum_length**2 / 3.0
    j_0 = p.arm_mass * p.arm_length**2 / 3.0 + p.rotor_inertia + p.pendulum_mass * p.arm_length**2
    b = p.pendulum_mass * p.pendulum_length / 2.0 * p.arm_length
    c = p.pendulum_mass * p.g * p.pendulum_length / 2.0
    return j_p, j_0, b, c


def _energy(x, p: FurutaDCParams) -> float:
    """Kinetic energy of the two thin rods by integrating over the pendulum's
    length (the Lagrangian's T), plus the pendulum's potential energy."""
    th, thd, ad = x[0], x[1], x[3]
    _, j_0, _, c = _constants(p)
    j_r = j_0 - p.pendulum_mass * p.arm_length**2
    # points of the pendulum at distance s from its pivot: velocity from the arm's
    # rotation and the pendulum's swing (theta from upright)
    s = np.linspace(0.0, p.pendulum_length, 2001)
    dm = p.pendulum_mass / p.pendulum_length
    tangential = p.arm_length * ad + s * math.cos(th) * thd
    radial = -s * math.sin(th) * ad
    vertical = -s * math.sin(th) * thd
    v2 = tangential**2 + radial**2 + vertical**2
    t_pend = 0.5 * dm * np.trapezoid(v2, s)
    return 0.5 * j_r * ad * ad + t_pend + c * (math.cos(th) - 1.0)


def _run(x, p, n, u=0.0, substeps=SUBSTEPS["none"], kind="none", fp=NO_FRICTION, mem=0.0):
    pp = p.record()
    code = KINDS.index(kind)
    out = np.empty((n, 5))
    for k in range(n):
        uk = u(k * H) if callable(u) else u
        _, mem = tick(x, uk, mem, substeps, 1, H, pp, code, fp)
        out[k] = x
    return out


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_the_linearization_is_the_jacobian_of_rhs(name):
    p = preset(name)
    A, B = linearization(p)
    eps = 1e-6
    A_fd = np.zeros((4, 4))
    for j in range(4):
        d = np.zeros(4)
        d[j] = eps
        A_fd[:, j] = (rhs(0.0, d, 0.0, p) - rhs(0.0, -d, 0.0, p)) / (2 * eps)
    B_fd = (rhs(0.0, np.zeros(4), eps, p) - rhs(0.0, np.zeros(4), -eps, p)) / (2 * eps)
    np.testing.assert_allclose(A, A_fd, rtol=1e-7, atol=1e-7 * np.abs(A).max())
    np.testing.assert_allclose(B.ravel(), B_fd, rtol=1e-7)


@pytest.mark.slow  # python-control's import: 3 s of CPU
def test_the_linearization_agrees_with_python_control():
    import control as ct  # python-control: 3 s to import, only here
    for p in (QUBE2, QUBE3, HOMEBUILT):
        sys = ct.nlsys(lambda t, x, u, params, p=p: rhs(t, x, u[0], p), None, states=4,
                       inputs=1, outputs=4)
        lin = ct.linearize(sys, np.zeros(4), np.zeros(1))
        A, B = linearization(p)
        np.testing.assert_allclose(lin.A, A, rtol=1e-5, atol=1e-5 * np.abs(A).max())
        np.testing.assert_allclose(lin.B, B, rtol=1e-5)


def test_the_linearization_in_the_thesis_limit():
    """An arm far heavier than the pendulum and a stiff motor: the pendulum
    row reduces to eq. (7) with omega0^2 = c/J_p and the pivot's acceleration
    L_r arm_ddot as input."""
    p = _lossless(QUBE2)
    A, B = linearization(p)
    j_p, j_0, b, c = _constants(p)
    det = j_p * j_0 - b * b
    np.testing.assert_allclose(A[1, 0], j_0 * c / det, rtol=1e-12)
    # dtheta_ddot/du < 0 at upright; positive u accelerates the arm (eq. 6's signs)
    assert B[1, 0] < 0 < B[3, 0]
    np.testing.assert_allclose(B[1, 0] / B[3, 0], -b / j_p, rtol=1e-12)
    # the thesis's eq. (6): theta_ddot = -(omega0^2/g) cos(theta) a for a pivot
    # acceleration a = L_r arm_ddot
    omega0_sq = c / j_p
    np.testing.assert_allclose(B[1, 0], -(omega0_sq / p.g) * p.arm_length * B[3, 0],
                               rtol=1e-12)


def test_the_mass_matrix_and_the_friction_torque_in_volts():
    """F volts of friction act as the torque -k_t F / R_m on the arm: M times the
    change of the accelerations is (0, -k_t F / R_m), with M built here."""
    rng = np.random.default_rng(3)
    for p in (QUBE2, HOMEBUILT):
        j_p, j_0, b, _ = _constants(p)
        for _ in range(5):
            x = rng.uniform(-3, 3, 4)
            u, F = rng.uniform(-10, 10, 2)
            d = rhs(0.0, x, (u, F), p) - rhs(0.0, x, u, p)
            M = np.array([[j_p, b * math.cos(x[0])],
                          [b * math.cos(x[0]), j_0 + j_p * math.sin(x[0]) ** 2]])
            tau = M @ np.array([d[1], d[3]])
            np.testing.assert_allclose(tau, [0.0, -p.torque_constant * F / p.resistance],
                                       atol=1e-12)
            # friction in volts is the same as that much less input voltage
            np.testing.assert_array_equal(rhs(0.0, x, (u, F), p), rhs(0.0, x, u - F, p))


def test_energy_is_conserved_by_the_tick_and_by_solve_ivp():
    p = _lossless(QUBE2)
    x0 = np.array([2.5, 1.0, 0.0, 3.0, 0.0])
    e0 = _energy(x0, p)
    assert mechanical_energy(x0, p) == pytest.approx(e0, rel=1e-6)
    x = x0.copy()
    traj = _run(x, p, int(10.0 / H))
    assert np.ptp(traj[:, 0]) > 1.0 and np.ptp(traj[:, 2]) > 1.0  # large swings
    assert abs(mechanical_energy(x, p) - e0) / abs(e0) < 1e-6
    assert abs(_energy(x, p) - e0) / abs(e0) < 1e-6


@pytest.mark.slow
def test_energy_is_conserved_by_solve_ivp_on_rhs():
    p = _lossless(QUBE2)
    x0 = np.array([2.5, 1.0, 0.0, 3.0])
    sol = solve_ivp(rhs, (0.0, 10.0), x0, args=(0.0, p), method="DOP853", rtol=1e-11,
                    atol=1e-12)
    e0 = _energy(x0, p)
    assert abs(_energy(sol.y[:, -1], p) - e0) / abs(e0) < 1e-6


def _period(theta, level=math.pi):
    """Mean period from the upward crossings of ``level`` (linear interpolation)."""
    y = theta - level
    i = np.where((y[:-1] < 0) & (y[1:] >= 0))[0]
    t = (i + y[i] / (y[i] - y[i + 1])) * H
    return float(np.mean(np.diff(t)))


@pytest.mark.parametrize("locked", [False, True])
def test_the_small_hanging_swing_has_the_closed_form_period(locked):
    """Small oscillation about hanging, no damping, no back-EMF: linearising the
    two equations at theta = pi (cos = -1) gives
    J_p d'' - b phi'' = -c d,  -b d'' + J_0 phi'' = 0,  so
    omega^2 = c J_0 / (J_p J_0 - b^2) with the arm free, and c / J_p with the
    arm locked (J_0 -> infinity; here J_0 = 100 kg m^2, 1e-6 off)."""
    p = _lossless(QUBE2)
    if locked:
        p = dataclasses.replace(p, rotor_inertia=100.0)
    j_p, j_0, b, c = _constants(p)
    omega = math.sqrt(c / j_p) if locked else math.sqrt(c * j_0 / (j_p * j_0 - b * b))
    x = np.array([math.pi + 1e-3, 0.0, 0.0, 0.0, 0.0])
    traj = _run(x, p, int(3.0 / H))
    assert _period(traj[:, 0]) == pytest.approx(2 * math.pi / omega, rel=2e-5)
    if not locked:  # the arm swings against the pendulum (momentum is conserved)
        assert np.ptp(traj[:, 2]) > 1e-4


def test_the_tick_follows_solve_ivp_on_a_driven_run():
    """u = 1 + 3 sin(2.7 t) V held over each sample, QUBE-Servo 2 with damping
    and back-EMF, against solve_ivp restarted every sample."""
    p = QUBE2
    x = np.array([math.pi - 0.5, 0.0, 0.0, 0.0, 0.0])
    y = x[:4].copy()
    err = 0.0
    for k in range(int(1.0 / H)):
        u = 1.0 + 3.0 * math.sin(2.7 * k * H)
        tick(x, u, 0.0, SUBSTEPS["none"], 1, H, p.record(), 0, NO_FRICTION)
        y = solve_ivp(rhs, (0.0, H), y, args=(u, p), method="DOP853", rtol=1e-11,
                      atol=1e-12).y[:, -1]
        err = max(err, float(np.max(np.abs(x[:4] - y))))
    assert abs(y[3]) > 1.0  # the arm was driven
    assert err < 2e-5


def test_signs_follow_the_thesis_plant():
    p = QUBE2
    # upright: positive u accelerates the arm and tips the pendulum negatively
    d = rhs(0.0, np.zeros(4), 1.0, p)
    assert d[3] > 0 > d[1]
    # hanging: the pendulum lags the arm, theta increases at first
    x = np.array([math.pi, 0.0, 0.0, 0.0, 0.0])
    _run(x, p, 4, u=5.0)
    assert x[0] > math.pi and x[2] > 0


def test_stiction_holds_the_arm_against_the_voltage_that_would_move_it():
    """Classical friction: with the pendulum hanging at rest, a voltage below F_S
    leaves the arm at rest (the friction balances it exactly), one above moves it."""
    p = QUBE2
    f = PRESET_FRICTION["qube2"]
    fp = FrictionParams(stiction=f["friction.stiction"], coulomb=f["friction.coulomb"],
                        zero_velocity_band=f["friction.zero_velocity_band"]).record()
    below = f["friction.stiction"] * 0.95
    x = np.array([math.pi, 0.0, 0.0, 0.0, 0.0])
    traj = _run(x, p, 200, u=below, kind="classical", fp=fp)
    assert np.max(np.abs(traj[:, 2:4])) < 1e-12  # rounding only
    assert np.max(np.abs(traj[:, 0] - math.pi)) < 1e-12
    x = np.array([math.pi, 0.0, 0.0, 0.0, 0.0])
    traj = _run(x, p, 200, u=f["friction.stiction"] * 1.05, kind="classical", fp=fp)
    assert traj[-1, 2] > 0.01
    # and the mean friction the tick reports is the voltage it held
    x = np.array([math.pi, 0.0, 0.0, 0.0, 0.0])
    fmean, _ = tick(x, below, 0.0, 2, 1, H, p.record(), KINDS.index("classical"), fp)
    assert fmean == pytest.approx(below, rel=1e-12)


def test_every_friction_law_runs_in_the_tick_and_takes_energy_out():
    """Each law slows a free swing of the arm (no input) by more than no friction."""
    p = QUBE2
    fp = FrictionParams(stiction=0.2, coulomb=0.15, viscous=0.01, sigma0=300.0, sigma1=1.0,
                        zero_velocity_band=0.02, observer_gain=0.5).record()
    x = np.array([math.pi, 0.0, 0.0, 10.0, 0.0])
    free = _run(x, p, 100)[-1, 3]
    for kind in KINDS[1:]:
        x = np.array([math.pi, 0.0, 0.0, 10.0, 0.0])
        end = _run(x, p, 100, kind=kind, fp=fp, substeps=SUBSTEPS[kind])[-1]
        assert np.all(np.isfinite(end))
        assert abs(end[3]) < abs(free), kind


def test_pendulum_energy_and_the_swing_up_ratio():
    p = QUBE2
    assert pendulum_energy(0.0, 0.0, p) == 0.0
    assert pendulum_energy(math.pi, 0.0, p) == pytest.approx(
        -p.pendulum_mass * p.g * p.pendulum_length)
    j_p, j_0, _, _ = _constants(p)
    # n: the tip acceleration the limit guarantees at every pendulum angle over g
    n = swing_ratio(p)
    assert n == pytest.approx(max_arm_acceleration(p, math.pi / 2) * p.arm_length / p.g)
    assert n == pytest.approx(p.arm_length * p.torque_constant * 10.0
                              / (p.resistance * (j_0 + j_p) * p.g))
    assert n < 4.0 / 3.0  # the QUBE needs more than one swing
    # the voltage's part of the arm's acceleration from rest (gravity's reaction
    # through the coupling aside) is smallest with the pendulum horizontal and
    # largest hanging or upright
    angles = np.linspace(0.0, 2 * math.pi, 73)
    acc = [max_arm_acceleration(p, a) - max_arm_acceleration(p, a, volts=0.0) for a in angles]
    assert min(acc) == pytest.approx(max_arm_acceleration(p, math.pi / 2))
    assert max(acc) == pytest.approx(max_arm_acceleration(p, math.pi))
    assert max_arm_acceleration(p) * p.arm_length / p.g > 4.0 / 3.0  # hanging: 1.59
    assert swing_ratio(HOMEBUILT) > 4.0 / 3.0


def test_presets_and_parameters():
    assert QUBE2.resistance == 8.4 and QUBE2.arm_damping == 0.00027
    assert QUBE2_WORKBOOK.arm_damping == 0.0015 and QUBE2_WORKBOOK.pendulum_damping == 0.0005
    assert QUBE3.resistance == 7.5 and QUBE3.torque_constant == 0.0422
    for name, p in PRESETS.items():
        assert set(PRESET_FRICTION[name]) >= {"friction.coulomb", "friction.stiction"}
        FrictionParams(**{k.split(".")[1]: v for k, v in PRESET_FRICTION[name].items()})
        row = p.record()
        assert row.shape == (len(DCRecord._fields),)
        assert np.all(np.isfinite(row))
    # given inertias replace the rods'
    p = dataclasses.replace(QUBE2, arm_inertia=5.72e-5, pendulum_inertia=1.2e-4)
    assert p.j_p == 1.2e-4
    assert p.j_0 == pytest.approx(5.72e-5 + QUBE2.pendulum_mass * QUBE2.arm_length**2)
    with pytest.raises(ParamError, match=r"plant\.resistance"):
        FurutaDCParams(resistance=0.0)
    with pytest.raises(ParamError, match=r"plant\.pendulum_inertia"):
        FurutaDCParams(pendulum_inertia=1e-6)  # below m_p (L_p/2)^2
    with pytest.raises(ValueError, match="qube2"):
        preset("qube9")
