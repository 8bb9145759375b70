"""The emulated rig: the firmware in simavr (libhil.so, firmware/hil/harness.c)
in front of a simulated pendulum, both in this process.

    python firmware/hil/rig.py --lib build/host/libhil.so --elf build/atmega328p/rig.elf

prints ``pty PATH`` when the rig is ready (``frictionlab run --backend
serial://PATH``) and ``released`` when the controller's first COMMAND let the
pendulum go, runs until SIGTERM or SIGINT, then prints the harness's report
(one JSON object).  SIGUSR1 marks "the controller was stopped now"
(``test-hil --stall-at``); SIGUSR2 makes the test build ``rig-hang.elf`` hang
now (``--hang-at S``: S seconds after the pty opened).

Every millisecond of emulated time the loop reads the PWM duty the firmware
drives, steps the plant 1 ms with it (not while the operator's hand holds the
pendulum: until the controller's first COMMAND), and gives the harness the
encoders' counts at the end of that millisecond; the harness spreads their
edges over it.  Emulated time waits for the plant, so the two clocks stay
locked; it runs at wall-clock speed.

The encoders are those of docs/build-a-rig.md: ``COUNTS`` per turn, the
pendulum counting from hanging down (its position at power-up), the arm from
its position at power-up.  The plant law is frictionlab's own.  Plants
(``--plant``): ``furuta-dc`` (the default: the home-built rig of
docs/build-a-rig.md, frictionlab's DC-motor plant with the
:data:`frictionlab.model.plants.furuta_dc.HOMEBUILT` preset and its friction,
:func:`homebuilt_keys`, driven by the H-bridge's voltage V = duty x
plant.voltage_limit, the 12 V supply), ``thesis`` (the thesis's rig,
:class:`frictionlab.model.simulation.SimulatedPlant` of
:func:`frictionlab.runs.simulated_plant`: u = duty / rig.u_scale
in m/s^2) and ``spin`` (no dynamics: the hand turns the arm and the pendulum
at ``--spin-speed`` rad/s for ``--spin-time`` s once released, then holds
them; the lost-count test).  Another plant is one entry in :data:`PLANTS`.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import math
import os
import signal
import sys

COUNTS = 2400  # firmware/src/config.h: PEND_COUNTS, ARM_COUNTS
DT = 1e-3


def counts(theta: float, arm: float) -> tuple[int, int]:
    """Encoder counts of the plant's angles (theta = 0 upright; hanging reads 0)."""
    return (round((theta - math.pi) * COUNTS / (2 * math.pi)),
            round(arm * COUNTS / (2 * math.pi)))


class ThesisPlant:
    """The thesis's plant (frictionlab's SimulatedPlant) driven by the duty:
    u = duty / rig.u_scale (m/s^2)."""

    def __init__(self, args):
        from frictionlab.config import build_config

        cfg = build_config(design=args.design, friction=args.friction,
                           sets=[("design.h", DT), ("sim.substeps", 2),
                                 ("sim.pendulum_steps", 1), *args.set])
        self._start(cfg, 1.0 / cfg.rig.u_scale, args.theta0)

    def _start(self, cfg, u_per_duty: float, theta0: float) -> None:
        from frictionlab.runs import simulated_plant

        self.u_per_duty = u_per_duty
        self.plant = simulated_plant(cfg)
        self.state = self.plant.init(theta0)
        self.plant.step(self.state, 0.0)  # compiled now, not in the real-time loop

    def angles(self) -> tuple[float, float]:
        return float(self.state.x[0]), float(self.state.x[2])

    def step(self, duty: float) -> None:
        self.state = self.plant.step(self.state, duty * self.u_per_duty)


class FurutaDCPlant(ThesisPlant):
    """The home-built rig (``--plant furuta-dc``): frictionlab's DC-motor plant
    with :data:`frictionlab.model.plants.furuta_dc.HOMEBUILT`'s parameters and
    friction (:func:`homebuilt_keys`), the H-bridge's output voltage the duty
    times the supply, V = duty * plant.voltage_limit (12 V)."""

    def __init__(self, args):
        from frictionlab.config import build_config

        cfg = build_config(plant="furuta-dc", friction=args.friction,
                           sets=[*homebuilt_keys(), ("design.h", DT), ("sim.substeps", 2),
                                 *args.set])
        self._start(cfg, cfg.plant.voltage_limit, args.theta0)


class SpinPlant:
    """The hand turns both shafts at a constant speed, then holds them."""

    def __init__(self, args):
        self.speed, self.time, self.t = args.spin_speed, args.spin_time, 0.0
        self.theta0 = args.theta0

    def angles(self) -> tuple[float, float]:
        turned = self.speed * min(self.t, self.time)
        return self.theta0 + turned, turned

    def step(self, duty: float) -> None:
        self.t += DT


#: The plants of ``--plant``.  Another plant is one more entry: a class like
#: ThesisPlant (``angles()``, ``step(duty)``).
PLANTS = {"furuta-dc": FurutaDCPlant, "thesis": ThesisPlant, "spin": SpinPlant}

#: The home-built rig's balancing design: ``design.*`` keys over the
#: furuta-dc plant's defaults (docs/build-a-rig.md, "The balancing design";
#: benchmarks/homebuilt_design.py compares it with the others).
#: The thesis's fast pattern would put the pendulum pair at omega0 (7.9 rad/s) and
#: the observer at 23 and 10 rad/s: with the gear motor's stiction (0.57 V) that
#: falls.  All four observer poles at 60 rad/s follow the encoders closely enough
#: that the stuck arm does not corrupt the estimates; a pendulum pair at 16 rad/s
#: narrows the cycle the friction's dead zone leaves.
HOMEBUILT_DESIGN: dict[str, float] = {
    "design.omega1": 16.0, "design.zeta1": 0.7, "design.omega2": 6.0, "design.zeta2": 0.7,
    "design.observer_omega1": 60.0, "design.observer_zeta1": 0.7,
    "design.observer_omega2": 60.0, "design.observer_zeta2": 0.7,
    # the 4-state predictor it was tuned with: the pendulum observer (the motor
    # plant's default) differences the 10 ms window's velocity, whose count steps
    # kick theta_dot (cycle 0.118 rad against 0.05)
    "design.full_observer": 1}


def homebuilt_keys(design: dict[str, float] | None = None) -> list[tuple[str, float]]:
    """The configuration keys of the home-built rig for ``--plant furuta-dc``
    (whose defaults are the QUBE-Servo 2's): every ``plant.*`` field of
    :data:`~frictionlab.model.plants.furuta_dc.HOMEBUILT`, its friction
    (``PRESET_FRICTION["homebuilt"]``) and its design (``design``, default
    :data:`HOMEBUILT_DESIGN`).  The emulated rig's plant and ``test-hil``'s
    controller both take them."""
    import dataclasses

    from frictionlab.model.plants.furuta_dc import HOMEBUILT, PRESET_FRICTION

    keys = [(f"plant.{f.name}", getattr(HOMEBUILT, f.name))
            for f in dataclasses.fields(HOMEBUILT) if getattr(HOMEBUILT, f.name) is not None]
    keys += list(PRESET_FRICTION["homebuilt"].items())
    keys += list((HOMEBUILT_DESIGN if design is None else design).items())
    return keys


def _set(text: str) -> tuple[str, str]:
    key, sep, value = text.partition("=")
    if not sep:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    return key, value


def load(path: str) -> ctypes.CDLL:
    lib = ctypes.CDLL(path)
    lib.hil_open.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_int32,
                             ctypes.c_int32, ctypes.c_long, ctypes.c_double]
    lib.hil_pty.restype = lib.hil_error.restype = ctypes.c_char_p
    lib.hil_duty.restype = lib.hil_time_ms.restype = ctypes.c_double
    lib.hil_set_counts.argtypes = [ctypes.c_int32, ctypes.c_int32]
    lib.hil_report.argtypes = [ctypes.c_char_p, ctypes.c_int]
    return lib


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--lib", required=True, help="libhil.so")
    p.add_argument("--elf", required=True, help="the firmware")
    p.add_argument("--mcu", default="atmega328p")
    p.add_argument("--plant", choices=sorted(PLANTS), default="furuta-dc")
    p.add_argument("--design", default="fast", help="--plant thesis: its design preset")
    p.add_argument("--friction", default="classical")
    p.add_argument("--set", action="append", type=_set, default=[], metavar="KEY=VALUE",
                   help="configuration keys of the plant, after its own (plant.*, "
                        "friction.*; thesis: rig.u_scale)")
    p.add_argument("--theta0", type=float, default=0.05, help="start angle (rad)")
    p.add_argument("--spin-speed", type=float, default=100.0, help="rad/s (--plant spin)")
    p.add_argument("--spin-time", type=float, default=0.5, help="s (--plant spin)")
    p.add_argument("--hand-edge-us", type=int, default=20,
                   help="edge spacing while the hand raises the pendulum (us)")
    p.add_argument("--hang-at", type=float, default=-1.0,
                   help="with rig-hang.elf: the firmware hangs S seconds after the pty opened")
    p.add_argument("--no-realtime", action="store_true",
                   help="normal priority (default: SCHED_FIFO on another CPU than the "
                        "controller's loop)")
    args = p.parse_args(argv)
    plant = PLANTS[args.plant](args)
    # simavr prints on stdout: this process's own lines go to the real stdout
    out = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)
    lib = load(args.lib)
    stop = []
    # end with the process that started this one (a killed test or test-hil)
    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    signal.signal(signal.SIGUSR1, lambda *_: lib.hil_mark())
    signal.signal(signal.SIGUSR2, lambda *_: lib.hil_hang())
    if not args.no_realtime:  # before the clock starts: the import takes a while
        # SCHED_FIFO like rig-sim, but on another CPU than the controller's loop (which
        # takes the last one), so that the loop's own work never holds the emulation
        # back; it needs about 5 % of that CPU (docs/performance.md)
        from frictionlab.realtime.osrt import default_cpu, try_realtime_priority

        last = default_cpu()
        cpus = sorted(os.sched_getaffinity(0))
        cpu = next((c for c in cpus if c != last), last)
        note = try_realtime_priority(40, cpu)
        if note:
            print(f"rig.py: {note}", file=sys.stderr)
    c = counts(*plant.angles())
    if lib.hil_open(args.elf.encode(), args.mcu.encode(), c[0], c[1], args.hand_edge_us,
                    args.hang_at):
        print(f"rig.py: {lib.hil_error().decode()}", file=sys.stderr)
        return 1
    print("pty", lib.hil_pty().decode(), file=out, flush=True)
    duty, held, set_counts, run_ms = lib.hil_duty, lib.hil_held, lib.hil_set_counts, lib.hil_run_ms
    was_held = True
    while not stop:
        d = duty()
        if not held():
            if was_held:  # the controller's first COMMAND: its run's t = 0
                print("released", file=out, flush=True)
                was_held = False
            plant.step(d)
        set_counts(*counts(*plant.angles()))
        if run_ms():
            print(f"rig.py: {lib.hil_error().decode()}", file=sys.stderr)
            break
    buf = ctypes.create_string_buffer(1024)
    lib.hil_report(buf, len(buf))
    print(json.dumps(json.loads(buf.value)), file=out, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
