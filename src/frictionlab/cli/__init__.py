"""Command-line interface: ``frictionlab <subcommand>`` (see ``--help``).

Every computing subcommand takes ``--json`` and then prints exactly one JSON
object on stdout; progress and logs go to stderr.  Exit status 0 on success,
2 on bad input with a one-line message on stderr (never a traceback): the
library raises structured errors (:class:`~frictionlab.config.ConfigError`,
:class:`~frictionlab.model.params.ParamError`, ``ValueError``, ``OSError``)
and :func:`main` alone turns them into the exit status and names the option
of a refused argument (:data:`.common.OPTIONS`); the subcommands
check their options and output paths before any work.

Start-up is kept light (docs/cli.md, "Start-up"): a subcommand's parser is
registered with the standard library and the light configuration modules
only, and its implementation (numba kernels, scipy, plotting, Dask, the
console) is imported by its handler.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

from ..config import (
    COMPENSATOR_KINDS,
    PLANT_FRICTION_KINDS,
    Config,
    UnknownKeyError,
    build_config,
)
from . import compensate, identify, predict, reproduce, run, sweep
from .common import (
    Parser,
    UsageError,
    add_config_args,
    add_plant_arg,
    check_output_path,
    check_window,
    config_from_args,
    emit_json,
    error_message,
    feature_lines,
    flush_notes,
    hanging_start,
    note,
    progress_bar,
)

__all__ = ["UsageError", "build_parser", "main", "simulate_result"]


# ---------------------------------------------------------------------------
# subcommands
# ---------------------------------------------------------------------------


def cmd_design(args) -> int:
    from ..runs import linearization_json, plant_design

    cfg = config_from_args(args)
    d = plant_design(cfg, method=args.method)
    out = d.to_json()
    out["linearization"] = linearization_json(cfg)
    if args.json:
        emit_json(out)
    else:
        print(f"design {args.design} (plant {cfg.plant_kind}): h = {cfg.design.h} s, "
              f"omega0 = {d.spec.omega0:.6g} rad/s")
        print("L = [" + ", ".join(f"{v:.6g}" for v in out["L"]) + "]")
        K = [v for row in out["K"] for v in (row if isinstance(row, list) else [row])]
        print("K = [" + ", ".join(f"{v:.6g}" for v in K) + "]")
        print("closed-loop poles (z): " + ", ".join(
            f"{re:.6f}{im:+.6f}j" for re, im in out["poles"]))
        print("observer poles (z):    " + ", ".join(
            f"{re:.6f}{im:+.6f}j" for re, im in out["observer_poles"]))
    return 0


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
    if args.swing_up and cfg.motor:
        raise UsageError(f"--swing-up: the swing-up of the {cfg.plant_kind!r} plant within "
                         "its voltage limit is not implemented yet (docs/qube.md)")
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
        for line in feature_lines(feats.interface_dict()):
            print(line)
    return 0


def cmd_keys(args) -> int:
    """``frictionlab keys``: every parameter key with its default, range, unit and meaning."""
    from ..config import describe_keys

    cfg = build_config(design=args.design, friction=args.friction,
                       compensation=args.compensation, plant=args.plant)
    rows = [{"key": key, "default": cfg.get(key), "range": rng, "unit": unit, "doc": doc}
            for key, doc, unit, rng in describe_keys(args.plant)]
    if args.json:
        emit_json({"design": args.design, "friction": args.friction,
                   "compensation": args.compensation, "plant": args.plant, "keys": rows})
        return 0
    print(f"defaults for --plant {args.plant} --design {args.design} --friction "
          f"{args.friction} --compensation {args.compensation}; set with --set KEY=VALUE or "
          "a --config TOML file")
    width = max(len(r["key"]) for r in rows)
    print(f"{'key':{width}s}  {'default':>9s}  {'allowed':20s}  {'unit':14s}  meaning")
    for r in rows:
        d = "-" if r["default"] is None else f"{r['default']:g}"
        print(f"{r['key']:{width}s}  {d:>9s}  {r['range']:20s}  {r['unit']:14s}  {r['doc']}")
    return 0


# ---------------------------------------------------------------------------
# parser
# ---------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="frictionlab",
        description="Rotary inverted pendulum with arm friction: design, simulate, sweep, "
                    "identify, compensate, and run the real-time controller.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    p = sub.add_parser("design", help="state-feedback and observer gains (Sec. 2.2-2.4)")
    add_config_args(p, friction=False)
    p.add_argument("--method", choices=("closed_form", "numeric"), default="closed_form",
                   help="Appendix C closed form or numerical pole placement "
                        "(default: %(default)s)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_design)

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

    p = sub.add_parser("keys", help="every parameter key: default, range, unit, meaning")
    p.add_argument("--design", choices=("fast", "slow"), default="fast",
                   help="show the design.* defaults of this preset (default: %(default)s)")
    p.add_argument("--friction", choices=PLANT_FRICTION_KINDS, default="classical",
                   help="show the friction.* defaults of this plant model "
                        "(default: %(default)s)")
    p.add_argument("--compensation", choices=COMPENSATOR_KINDS, default="none",
                   help="show the compensation.* defaults of this compensator (default: "
                        "%(default)s, whose values are the LuGre compensator's)")
    add_plant_arg(p)
    p.add_argument("--json", action="store_true",
                   help='print one JSON object {"keys": [{"key", "default", "range", "unit", '
                        '"doc"}, ...]}')
    p.set_defaults(func=cmd_keys)

    _register_subcommands(sub)
    _describe_subcommands(parser)
    return parser


def _describe_subcommands(parser: argparse.ArgumentParser) -> None:
    """Give every subcommand (at any depth) its one-line summary as the
    description of its own ``--help`` when it has none."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
            for name, sub in action.choices.items():
                if sub.description is None and helps.get(name):
                    sub.description = helps[name][0].upper() + helps[name][1:] + "."
                _describe_subcommands(sub)


def _register_subcommands(sub) -> None:
    """The subcommands that live beside the numerics they drive."""
    for mod in (sweep, identify, compensate, run, reproduce, predict):
        mod.register_cli(sub)


def _one_line(exc: BaseException) -> str:
    text = " ".join(error_message(exc).split()) or type(exc).__name__
    return text if len(text) <= 800 else text[:797] + "..."


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status (0, 2 on bad input, 130 on
    Ctrl-C; ``run`` also 1 after a safety stop)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 0
    prog = " ".join(["frictionlab", args.command,
                     *(v for k, v in vars(args).items() if k.endswith("_command") and v)])
    try:
        rc = int(args.func(args) or 0)
        flush_notes(args)
        return rc
    except UnknownKeyError as exc:
        hint = "" if exc.suggestions else "; 'frictionlab keys' lists them"
        print(f"{prog}: error: {_one_line(exc)}{hint}", file=sys.stderr)
        return 2
    except (UsageError, ValueError, OSError) as exc:
        # bad input: a bad value (ConfigError, ParamError and the library's
        # other ValueErrors), an unreadable or unwritable file (OSError)
        print(f"{prog}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
