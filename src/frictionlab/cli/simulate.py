"""``frictionlab simulate``: a closed-loop simulation and its limit-cycle features."""

from __future__ import annotations

from collections.abc import Callable

from ..config import Config
from .common import (
    UsageError,
    add_config_args,
    check_output_path,
    check_window,
    config_from_args,
    emit_json,
    feature_lines,
    flush_notes,
    hanging_start,
    note,
    progress_bar,
)

__all__ = ["cmd_simulate", "register_cli", "simulate_result"]


def simulate_result(cfg: Config, duration: float | None, window: float | None,
                    progress: Callable[[float], None] | None = None,
                    open_loop: bool = False):
    from ..model.limit_cycles import trajectory_features
    from ..runs import simulate_config

    traj = simulate_config(cfg, duration, progress=progress, open_loop=open_loop)
    feats = trajectory_features(traj, window)
    status = "fell" if traj.status == "fell" else feats.status
    return traj, feats, status


def cmd_simulate(args) -> int:
    cfg = hanging_start(args, config_from_args(args))
    if args.duration is not None:
        try:
            cfg = cfg.with_values({"sim.duration": args.duration})
        except ValueError as exc:
            raise UsageError(f"--duration: {exc}") from None
    check_window(args.window, cfg.sim.duration,
                 "--duration" if args.duration is not None else "sim.duration")
    check_output_path(args.save, (".dat", ".csv"), "--save")
    check_output_path(args.plot, (".png", ".pdf", ".svg"), "--plot")
    if args.open_loop and args.swing_up:
        raise UsageError("--open-loop holds u at 0: it cannot be given with --swing-up")
    if (not args.swing_up and not args.open_loop
            and abs(cfg.sim.initial_angle) > cfg.sim.fall_angle):
        note(args, f"frictionlab simulate: note: sim.initial_angle = "
                   f"{cfg.sim.initial_angle:g} rad is beyond sim.fall_angle "
                   f"({cfg.sim.fall_angle:g} rad): the run falls at once; --swing-up swings "
                   "the pendulum up first")
    flush_notes(args)
    duration = cfg.sim.duration
    long_run = duration > 200 or args.progress
    swing = None
    if args.swing_up:
        from ..studies.swingup_sim import simulate_swingup, swingup_outcome

        swing = simulate_swingup(cfg, duration)
        traj = swing.trajectory
        status, feats = swingup_outcome(swing, args.window)
    else:
        with progress_bar("simulating", long_run) as upd:
            traj, feats, status = simulate_result(cfg, duration, args.window,
                                                  upd if long_run else None,
                                                  open_loop=args.open_loop)
    if args.save:
        traj.save(args.save)
    if args.plot:
        from ..plotting import plot_trajectory

        plot_trajectory(traj, args.plot, window=args.window, period=feats.period)
    out = {
        "status": status,
        "features": feats.interface_dict(),
        "symmetry": {"neg_peak1": feats.neg_peak1, "neg_peak2": feats.neg_peak2,
                     "neg_valley": feats.neg_valley},
        "cycles": feats.cycles,
        "duration": len(traj) * traj.h,
    }
    if swing is not None:
        out["swing_up_time"] = swing.swing_up_time
        out["swing_up"] = {"catches": swing.catches, "stop_reason": swing.stop_reason or None,
                           "max_u_swinging": swing.max_u_swinging}
    if args.save:
        out["saved"] = args.save
    if args.plot:
        out["plot"] = args.plot
    if args.json:
        emit_json(out)
    else:
        print(f"status: {status}  ({out['duration']:.2f} s simulated)")
        if swing is not None:
            when = ("never caught" if swing.swing_up_time is None
                    else f"{swing.swing_up_time:.2f} s")
            print(f"  swing_up_time      {when} ({swing.catches} catch(es)"
                  + (f", stopped: {swing.stop_reason})" if swing.stop_reason else ")"))
        for line in feature_lines(feats.interface_dict(), cfg.plant_model.u_unit):
            print(line)
    return 0


def register_cli(sub) -> None:
    """Add ``simulate`` to the ``frictionlab`` subcommands."""
    p = sub.add_parser("simulate", help="closed-loop simulation and limit-cycle features")
    add_config_args(p)
    p.add_argument("--duration", type=float, default=None,
                   help="simulated time in s (default: sim.duration = 40)")
    p.add_argument("--window", type=float, default=None,
                   help="analyse the last S seconds (default: the last half)")
    p.add_argument("--save", metavar="FILE", help="save signals to FILE.dat or FILE.csv")
    p.add_argument("--plot", metavar="FILE", help="plot the limit cycle to FILE.png")
    p.add_argument("--progress", action="store_true", help="always show progress on stderr")
    p.add_argument("--swing-up", action="store_true",
                   help="start from sim.initial_angle (pi = hanging unless set) and swing up by "
                        "energy control (swingup.* keys) before balancing; the JSON adds "
                        "swing_up_time")
    p.add_argument("--open-loop", action="store_true",
                   help="hold u at 0 (0 V for a motor plant) for the whole run and never stop "
                        "for a fall: a free swing from sim.initial_angle")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_simulate)
