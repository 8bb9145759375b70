r"""The home-built rig's closed loop in simulated time, through the firmware's
sensors: what ``firmware/test-hil`` runs in the emulator, without the
emulator (benchmarks/homebuilt_design.py, tests/test_firmware_plant.py).

* The plant is the emulated rig's (``rig.py --plant furuta-dc``): the
  :data:`~frictionlab.model.plants.furuta_dc.HOMEBUILT` preset with its
  classical friction, stepped 1 ms at a time with the voltage duty x 12 V held.
* The controller is frictionlab's compiled step
  (:func:`frictionlab.model.controller.controller_step_rows`, the 200 Hz
  loop's call) with the configuration ``frictionlab run`` gets from
  ``test-hil`` (:func:`rig.homebuilt_keys`); it samples every 5 ms and its
  command acts ``latency_ms`` later (the wire and the host: about 1 ms,
  docs/build-a-rig.md, "Timing").
* The readings are the firmware's: both angles in whole encoder counts
  (:func:`rig.counts`, 2400 a turn), the arm's velocity the count
  difference over the last ``VEL_WINDOW_MS`` = 10 ms, read at the last 1 ms
  tick, clipped at ``VEL_FULL_SCALE`` = 40 rad/s (firmware/src/config.h).
  Through the rig.* scales of docs/build-a-rig.md the firmware's channels
  are exactly these values.  ``ideal``: the true angles and velocity instead.
"""

from __future__ import annotations

import math

import numpy as np
import rig as R  # firmware/hil/rig.py: the emulated rig's plant and encoders

H_MS = 5           # the controller's period (ms)
WINDOW_MS = 10     # firmware/src/config.h: VEL_WINDOW_MS
FULL_SCALE = 40.0  # VEL_FULL_SCALE (rad/s)


def closed_loop(design: dict[str, float] | None = None, duration: float = 20.0,
                theta0: float = 0.05, latency_ms: int = 1, ideal: bool = False,
                plant_sets=(), trace: list | None = None) -> dict:
    """One run from ``theta0`` (rad) for ``duration`` s.

    Parameters
    ----------
    design : dict, optional
        ``design.*`` keys (default :data:`rig.HOMEBUILT_DESIGN`).
    plant_sets : sequence of (key, value)
        Keys of the plant only (the controller keeps the preset's): a rig
        that differs from its model.
    trace : list, optional
        Gets ``(t, theta, u)`` arrays at the controller's ticks appended.

    Returns
    -------
    dict
        ``{"fell_at": t}`` when |theta| passed 1 rad, else ``amplitude``
        (largest |theta| over the second half, rad), ``period`` (s, from
        theta's upward zero crossings; None without two) and ``max_u`` (V).
    """
    from frictionlab.config import build_config
    from frictionlab.model.controller import controller_step_rows, gains_row, state_vector
    from frictionlab.model.friction import friction_row
    from frictionlab.runs import make_controller, simulated_plant

    keys = R.homebuilt_keys(design)
    plant = simulated_plant(build_config(plant="furuta-dc", sets=[
        *keys, ("design.h", R.DT), ("sim.substeps", 2), *plant_sets]), duration)
    cfg = build_config(plant="furuta-dc", sets=keys)
    ctrl = make_controller(cfg)
    gp, cp = ctrl.record()
    g_row, c_row = gains_row(gp), friction_row(cp)
    sx = state_vector(ctrl.init(theta0))
    supply = cfg.plant.voltage_limit
    st = plant.init(theta0)
    hist = [0] * (WINDOW_MS + 1)  # the arm's count at each 1 ms tick
    step = 2 * math.pi / R.COUNTS
    duty, pending = 0.0, []       # commands on their way: (ms it acts, duty)
    theta, us = [], []
    for ms in range(round(duration * 1000)):
        th, arm = float(st.x[0]), float(st.x[2])
        if ms % H_MS == 0:
            if ideal:
                th_m, arm_m, armd_m = th, arm, float(st.x[3])
            else:
                c_p, c_a = R.counts(th, arm)
                th_m = math.remainder(math.pi + c_p * step, 2 * math.pi)
                arm_m = c_a * step
                armd_m = (hist[-1] - hist[0]) * step / (WINDOW_MS * 1e-3)
                armd_m = min(max(armd_m, -FULL_SCALE), FULL_SCALE)
            u, _, _ = controller_step_rows(sx, g_row, c_row, th_m, arm_m, armd_m)
            pending.append((ms + latency_ms, u / supply))
            theta.append(th)
            us.append(u)
            if abs(th) > 1.0:
                return {"fell_at": ms / 1000}
        while pending and pending[0][0] <= ms:
            duty = pending.pop(0)[1]
        st = plant.step(st, duty * supply)
        hist = [*hist[1:], R.counts(float(st.x[0]), float(st.x[2]))[1]]
    if trace is not None:
        trace.append((np.arange(len(theta)) * H_MS / 1000, np.array(theta), np.array(us)))
    late = np.array(theta[len(theta) // 2:])
    y0, y1 = late[:-1], late[1:]
    i = np.where((y0 < 0) & (y1 >= 0))[0]
    t = (i + y0[i] / (y0[i] - y1[i])) * H_MS / 1000
    return {"amplitude": float(np.max(np.abs(late))),
            "period": float(np.mean(np.diff(t))) if len(t) > 1 else None,
            "max_u": float(np.max(np.abs(us)))}
