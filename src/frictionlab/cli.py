"""Command-line interface: ``frictionlab <subcommand>`` (see ``--help``).

Every computing subcommand takes ``--json`` and then prints exactly one JSON
object on stdout; progress and logs go to stderr.  Exit status 0 on success,
2 on bad input with a one-line message on stderr (never a traceback): the
library raises structured errors (:class:`~frictionlab.config.ConfigError`,
:class:`~frictionlab._validation.ParamError`, ``ValueError``, ``OSError``)
and :func:`main` alone turns them into the exit status; the subcommands
check their options and output paths before any work.

Start-up is kept light (docs/cli.md, "Start-up"): a subcommand's parser is
registered with the standard library and the light configuration modules
only, and its implementation (numba kernels, scipy, plotting, Dask, the
console) is imported by its handler.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Callable, Sequence
from contextlib import contextmanager

from .config import (
    COMPENSATOR_KINDS,
    PLANT_FRICTION_KINDS,
    Config,
    ConfigError,
    UnknownKeyError,
    build_config,
    parse_assignment,
)

__all__ = ["main"]


class UsageError(Exception):
    """Bad input: exit status 2."""


class _Formatter(argparse.HelpFormatter):
    """argparse's help layout, with a subcommand's summary on its own line:
    argparse measures subcommand names one indentation level short, and then
    pushes every summary of a long name onto the next line."""

    def add_argument(self, action: argparse.Action) -> None:
        super().add_argument(action)
        if isinstance(action, argparse._SubParsersAction) and action.help != argparse.SUPPRESS:
            longest = max((len(name) for name in action.choices), default=0)
            self._action_max_length = max(self._action_max_length,
                                          longest + self._current_indent + 2)


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line on stderr (exit status 2)."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", _Formatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def check_output_path(path: str | None, exts: tuple[str, ...], option: str) -> None:
    """Refuse, before any work, an output file with a wrong extension, whose
    directory does not exist or cannot be written, or that is a directory."""
    if not path:
        return
    if not path.endswith(exts):
        names = ", ".join(exts[:-1]) + " or " + exts[-1] if len(exts) > 1 else exts[0]
        raise UsageError(f"{option} {path}: the extension must be {names}")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise UsageError(f"{option} {path}: directory {folder} does not exist")
    if os.path.isdir(path):
        raise UsageError(f"{option} {path} is a directory")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise UsageError(f"{option} {path}: directory {folder} is not writable")


def check_output_dir(path: str, option: str) -> None:
    """Refuse, before any work, an output directory that is not a writable
    directory and cannot be created as one (creating it if missing)."""
    if os.path.exists(path) and not os.path.isdir(path):
        raise UsageError(f"{option} {path} exists and is not a directory")
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"{option} {path}: cannot create it ({exc.strerror or exc})") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise UsageError(f"{option} {path}: the directory is not writable")


def finite(option: str, value: float | None, lo: float | None = None,
           lo_open: bool = True, hi: float | None = None) -> None:
    """Refuse a float option that is not finite or outside ``lo``/``hi``
    (``None``, an option not given, passes)."""
    if value is None:
        return
    ok = math.isfinite(value) and (lo is None or value > lo or (not lo_open and value == lo))
    ok = ok and (hi is None or value <= hi)
    if not ok:
        rel = f"{'>' if lo_open else '>='} {lo:g}" if lo is not None else "finite"
        rng = f" and <= {hi:g}" if hi is not None else ""
        raise UsageError(f"{option} must be {rel}{rng}, got {value:g}")


def _clean(obj):
    """JSON-safe copy: NaN/inf become null."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    return obj


def emit_json(obj) -> None:
    sys.stdout.write(json.dumps(_clean(obj)) + "\n")
    sys.stdout.flush()


def _add_config_args(p: argparse.ArgumentParser, friction: bool = True) -> None:
    p.add_argument("--design", choices=("fast", "slow"), default="fast",
                   help="design preset of Sec. 2.4 (eqs. 13-16), applied before --set "
                        "(default: %(default)s)")
    if friction:
        p.add_argument("--friction", choices=PLANT_FRICTION_KINDS, default="classical",
                       help="friction model of the simulated plant (default: %(default)s)")
        p.add_argument("--compensation", choices=COMPENSATOR_KINDS, default="none",
                       help="friction compensator in the controller (default: %(default)s)")
    p.add_argument("--config", metavar="FILE", help="TOML file with parameter keys")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                   help="override a parameter key (repeatable; later wins); "
                        "see 'frictionlab keys'")


def parse_sets(texts: Sequence[str]) -> list[tuple[str, str]]:
    """The ``--set KEY=VALUE`` options as (key, value) pairs."""
    pairs = []
    for text in texts:
        try:
            pairs.append(parse_assignment(text))
        except ConfigError as exc:
            raise UsageError(f"--set: {exc}") from None
    return pairs


def config_from_args(args) -> Config:
    """Build the run's configuration; note on stderr any given key the chosen
    friction model or compensator ignores."""
    from .config import inert_keys, load_toml

    items = [*(load_toml(args.config) if args.config else []), *parse_sets(args.sets)]
    cfg = build_config(
        design=args.design,
        friction=getattr(args, "friction", "classical"),
        compensation=getattr(args, "compensation", "none"),
        sets=items,
    )
    given = [k for k, _ in items]
    if hasattr(args, "friction"):
        for key in dict.fromkeys(inert_keys(cfg, given)):
            if key.startswith("friction."):
                why = f"with the {cfg.friction_kind!r} plant friction"
            else:
                why = f"with the {cfg.compensation_kind!r} compensator"
            note(args, f"frictionlab: note: {key} has no effect {why}")
    return cfg


def hanging_start(args, cfg: Config) -> Config:
    """With ``--swing-up`` and no ``sim.initial_angle`` given (``--set`` or ``--config``),
    start hanging (pi): a swing-up from the balancing default 0.05 rad would be none."""
    from .config import load_toml

    if not getattr(args, "swing_up", False):
        return cfg
    items = [*(load_toml(args.config) if getattr(args, "config", None) else []),
             *parse_sets(args.sets)]
    if any(k == "sim.initial_angle" for k, _ in items):
        return cfg
    return cfg.with_values({"sim.initial_angle": math.pi})


def note(args, text: str) -> None:
    """Queue a note for stderr.  Notes wait until the input has been checked
    (:func:`flush_notes`), so that bad input gets its one line alone."""
    vars(args).setdefault("_notes", []).append(text)


def flush_notes(args) -> None:
    """Print the queued notes: a handler calls this once its input is checked,
    before the work; :func:`main` prints any left after a successful run."""
    for text in vars(args).pop("_notes", []):
        print(text, file=sys.stderr)


#: Most local worker processes a command starts.
MAX_WORKERS = 256


def check_workers(value: int | None, option: str = "--workers") -> None:
    """Refuse a worker count outside 1..:data:`MAX_WORKERS` (None: automatic)."""
    if value is not None and not 1 <= value <= MAX_WORKERS:
        raise UsageError(f"{option} must be in 1..{MAX_WORKERS}, got {value}")


@contextmanager
def progress_bar(label: str, enabled: bool = True):
    """A rich progress bar on stderr; yields ``update(fraction)``."""
    if not enabled:
        yield lambda f: None
        return
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    console = Console(stderr=True)
    with Progress(TextColumn(label), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                  TimeRemainingColumn(), console=console, transient=True) as prog:
        task = prog.add_task(label, total=1.0)
        yield lambda f: prog.update(task, completed=f)


# ---------------------------------------------------------------------------
# subcommands
# ---------------------------------------------------------------------------


def cmd_design(args) -> int:
    from .design import design

    cfg = config_from_args(args)
    d = design(cfg.design, cfg.plant, method=args.method)
    out = d.to_json()
    if args.json:
        emit_json(out)
    else:
        print(f"design {args.design}: h = {cfg.design.h} s, omega0 = {cfg.design.omega0} rad/s")
        print("L = [" + ", ".join(f"{v:.6g}" for v in out["L"]) + "]")
        print("K = [" + ", ".join(f"{v:.6g}" for v in out["K"]) + "]")
        print("closed-loop poles (z): " + ", ".join(
            f"{re:.6f}{im:+.6f}j" for re, im in out["poles"]))
        print("observer poles (z):    " + ", ".join(
            f"{re:.6f}{im:+.6f}j" for re, im in out["observer_poles"]))
    return 0


def simulate_result(cfg: Config, duration: float | None, window: float | None,
                    progress: Callable[[float], None] | None = None):
    from .limit_cycles import trajectory_features
    from .simulation import simulate_config

    traj = simulate_config(cfg, duration, progress=progress)
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
    finite("--window", args.window, 0.0)
    check_output_path(args.save, (".dat", ".csv"), "--save")
    check_output_path(args.plot, (".png", ".pdf", ".svg"), "--plot")
    if not args.swing_up and abs(cfg.sim.initial_angle) > cfg.sim.fall_angle:
        note(args, f"frictionlab simulate: note: sim.initial_angle = "
                   f"{cfg.sim.initial_angle:g} rad is beyond sim.fall_angle "
                   f"({cfg.sim.fall_angle:g} rad): the run falls at once; --swing-up swings "
                   "the pendulum up first")
    flush_notes(args)
    duration = cfg.sim.duration
    long_run = duration > 200 or args.progress
    swing = None
    if args.swing_up:
        from .swingup_sim import simulate_swingup, swingup_outcome

        swing = simulate_swingup(cfg, duration)
        traj = swing.trajectory
        status, feats = swingup_outcome(swing, args.window)
    else:
        with progress_bar("simulating", long_run) as upd:
            traj, feats, status = simulate_result(cfg, duration, args.window,
                                                  upd if long_run else None)
    if args.save:
        traj.save(args.save)
    if args.plot:
        from .plotting import plot_trajectory

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
            when = ("never" if swing.swing_up_time is None
                    else f"at {swing.swing_up_time:.2f} s")
            print(f"  swing-up: caught {when}, {swing.catches} catch(es)"
                  + (f", stopped: {swing.stop_reason}" if swing.stop_reason else ""))
        for k, v in feats.interface_dict().items():
            print(f"  {k:18s} {'-' if v is None else f'{v:.4g}'}")
    return 0


def cmd_keys(args) -> int:
    """``frictionlab keys``: every parameter key with its default, range, unit and meaning."""
    from .config import _CLASSES, _SECTIONS

    cfg = build_config(design=args.design, friction=args.friction,
                       compensation=args.compensation)
    rows = []
    for section in _SECTIONS:
        for name, doc, unit, rng in _CLASSES[section].describe():
            key = f"{section}.{name}"
            rows.append({"key": key, "default": cfg.get(key), "range": rng, "unit": unit,
                         "doc": doc})
    if args.json:
        emit_json({"design": args.design, "friction": args.friction,
                   "compensation": args.compensation, "keys": rows})
        return 0
    print(f"defaults for --design {args.design} --friction {args.friction} --compensation "
          f"{args.compensation}; set with --set KEY=VALUE or a --config TOML file")
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
    parser = _Parser(
        prog="frictionlab",
        description="Rotary inverted pendulum with arm friction: design, simulate, sweep, "
                    "identify, compensate, and run the real-time controller.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    p = sub.add_parser("design", help="state-feedback and observer gains (Sec. 2.2-2.4)")
    _add_config_args(p, friction=False)
    p.add_argument("--method", choices=("closed_form", "numeric"), default="closed_form",
                   help="Appendix C closed form or numerical pole placement "
                        "(default: %(default)s)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_design)

    p = sub.add_parser("simulate", help="closed-loop simulation and limit-cycle features")
    _add_config_args(p)
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
    from . import (
        compensation_cli,
        identification,
        predict_cli,
        realtime_cli,
        reproduce_cli,
        sweep_cli,
    )

    for mod in (sweep_cli, identification, compensation_cli, realtime_cli, reproduce_cli,
                predict_cli):
        mod.register_cli(sub)


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
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
