"""What every subcommand shares: the usage error (exit status 2), the
parameter options (``--design``, ``--friction``, ``--compensation``,
``--config``, ``--set``), option and output-path checks, JSON output and the
progress bar.  Imports the configuration layer only.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Sequence
from contextlib import contextmanager

from ..config import (
    COMPENSATOR_KINDS,
    PLANT_FRICTION_KINDS,
    PLANT_NAMES,
    Config,
    ConfigError,
    UnknownKeyError,
    build_config,
    parse_assignment,
)
from ..io.jsonsafe import json_safe
from ..model.params import ParamError


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


class Parser(argparse.ArgumentParser):
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


def parse_number(text: str, what: str) -> float:
    """``text`` as a finite float; a :class:`UsageError` naming ``what`` otherwise."""
    try:
        v = float(text)
    except ValueError:
        raise UsageError(f"{what}: {text!r} is not a number") from None
    if not math.isfinite(v):
        raise UsageError(f"{what}: {text!r} must be finite")
    return v


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


def check_window(window: float | None, duration: float, duration_name: str = "--duration"
                 ) -> None:
    """Refuse a ``--window`` that is not a positive finite number or is longer than
    the run it analyses (``duration`` s, given by ``duration_name``: an option or a
    key), naming both values (``None``, the default window, passes)."""
    finite("--window", window, 0.0)
    if window is not None and window > duration * (1.0 + 1e-12):
        raise UsageError(f"--window {window:g} s is longer than the run ({duration_name} "
                         f"{duration:g} s); give a window of at most {duration:g} s")


_clean = json_safe  # the one sanitiser (frictionlab.io.jsonsafe)

#: Library argument names (a :class:`~frictionlab.model.params.ParamError`'s
#: ``field``) that are this command line's options: only the command line names
#: its options; the library names its arguments.
OPTIONS = {"vary": "--vary", "mode": "--mode", "dask": "--dask", "backend": "--backend",
           "token": "--token", "fit": "--fit", "weights": "--weights", "bounds": "--bounds",
           "search_duration": "--search-duration", "search_window": "--search-window",
           "stiction_above_coulomb": "--allow-stiction-below-coulomb",
           "duration": "--duration", "window": "--window"}


def _hinted(obj, options: dict[str, str] = OPTIONS) -> str:
    """``obj``'s text, followed by the options of the arguments it names as
    ``hints`` (the ones that would address it), e.g. ``... (--bounds)``."""
    named = [options[h] for h in getattr(obj, "hints", ()) if h in options]
    return f"{obj} ({', '.join(named)})" if named else str(obj)


def error_message(exc: BaseException) -> str:
    """The message of an error, a refused argument named by its option
    (``--vary: friction.coulomb: empty value in the list``), and the options
    that would lift it (its ``hints``) after it."""
    field = getattr(exc, "field", None)
    if isinstance(exc, ParamError | UnknownKeyError) and field in OPTIONS:
        return f"{OPTIONS[field]}: {_hinted(exc)}"
    return _hinted(exc)


def note_text(note: str, options: dict[str, str] = OPTIONS) -> str:
    """A library warning as the command line prints it: the options of the
    arguments it names as ``hints`` (a :class:`~frictionlab.io.notes.Note`)
    after it (``... (--bounds)``); ``options`` maps arguments to options."""
    return _hinted(note, options)


#: The ``safety.*`` fields the real-time commands take as options.
SAFETY_OPTIONS = {"safety.angle_limit": "--angle-limit",
                  "safety.start_tolerance": "--start-tolerance",
                  "safety.gain_transition": "--gain-transition",
                  "safety.compensation_transition": "--compensation-transition",
                  "safety.silent_periods": "--silent-periods",
                  "safety.max_pause": "--max-pause"}


def add_stall_args(p) -> None:
    """The real-time loop's stall limits and its priority, as ``run`` and ``identify
    experiment --backend`` take them (``--silent-periods``, ``--max-pause``,
    ``--no-realtime``); :func:`safety_from_args` reads them."""
    p.add_argument("--silent-periods", type=int, default=2, metavar="N",
                   help="stop (rig_silent, motor zeroed) after N consecutive sample periods "
                        "with nothing from the rig, or 5N (at least 10) ticks whose replies "
                        "all came too late (default 2; raise it only for a rig or host known "
                        "to stall, e.g. an emulator on a loaded machine)")
    p.add_argument("--max-pause", type=float, default=0.05, metavar="S",
                   help="stop (paused, motor zeroed) when the loop did not run for longer "
                        "than S seconds (a suspended process, a stalled host; default 0.05)")
    p.add_argument("--no-realtime", action="store_true",
                   help="do not ask for SCHED_FIFO priority")


def safety_from_args(args, **limits):
    """The loop's :class:`~frictionlab.realtime.Safety` from :func:`add_stall_args`'s
    options and ``limits`` (more ``Safety`` fields); a refused value is named by
    its option (:data:`SAFETY_OPTIONS`)."""
    from ..realtime import Safety

    try:
        return Safety(silent_periods=args.silent_periods,
                      unread_limit=max(10, 5 * args.silent_periods),
                      max_pause=args.max_pause, **limits)
    except ParamError as exc:
        option = SAFETY_OPTIONS.get(exc.field)
        if option is None:
            raise
        raise UsageError(str(exc).replace(exc.field, option, 1)) from None


#: Units of the limit-cycle features a plain-text output prints (as in ``--json``: SI).
FEATURE_UNITS = {"peak1": "rad", "peak2": "rad", "valley": "rad", "period": "s",
                 "max_u": "m/s^2", "max_arm_velocity": "rad/s", "peak_to_peak": "rad"}


def feature_lines(features: dict, u_unit: str | None = None) -> list[str]:
    """The plain-text lines of limit-cycle ``features``: name, value, unit
    (``max_u`` in ``u_unit``, default the thesis plant's m/s^2; V on a motor plant)."""
    units = {**FEATURE_UNITS, **({"max_u": u_unit} if u_unit else {})}
    return [f"  {k:18s} {'-' if v is None else f'{v:.4g}'} {units.get(k, '')}".rstrip()
            for k, v in features.items()]


def emit_json(obj) -> None:
    sys.stdout.write(json.dumps(_clean(obj)) + "\n")
    sys.stdout.flush()


def add_plant_arg(p: argparse.ArgumentParser, backend: bool = False,
                  default_from: str | None = None) -> None:
    """``--plant NAME``: the plant simulated and designed for (docs/cli.md);
    ``backend``: its default is the plant ``--backend`` implies
    (:func:`plant_from_args`); ``default_from``: its default (None) is found by the
    command, as this text says."""
    default = ("the plant of --backend: qube2 for qube2://, qube3 for qube3://, else "
               "thesis" if backend else default_from or "%(default)s")
    unset = backend or default_from is not None
    p.add_argument("--plant", choices=PLANT_NAMES, default=None if unset else "thesis",
                   help="the plant: 'thesis' (eq. 6, u the arm's acceleration), "
                        "'furuta-dc' or 'qube2' (the QUBE-Servo 2: a DC motor, u in volts, "
                        "friction in volts), 'qube3' (the QUBE-Servo 3); its presets are "
                        f"the plant.*, friction.* and rig.* defaults (default: {default})")


#: The plant a ``--backend`` scheme implies (a QUBE-Servo board is its own plant).
BACKEND_PLANTS = {"qube2": "qube2", "qube3": "qube3"}


def plant_from_args(args) -> str:
    """The run's plant: ``--plant``, else the one ``--backend`` implies
    (:data:`BACKEND_PLANTS`; for a parser whose ``--plant`` defaults to None,
    :func:`add_plant_arg`), else ``thesis``.  Another motor plant than the
    board's is run as asked, with a note (e.g. ``furuta-dc`` with a rig's own
    ``plant.*``); ``thesis`` too (its controller's u taken as volts through
    ``rig.u_scale``: the identification experiments' way, docs/qube.md)."""
    plant = getattr(args, "plant", "thesis")
    spec = getattr(args, "backend", None)
    scheme = spec.partition(":")[0] if isinstance(spec, str) else ""
    implied = BACKEND_PLANTS.get(scheme)
    if implied is None:
        return plant or "thesis"
    if plant is None:
        return implied
    if plant not in ("thesis", implied):
        note(args, f"frictionlab: note: --plant {plant} on a {implied} board ({spec}): its "
                   "model and controller, the board's channels")
    return plant


def add_config_args(p: argparse.ArgumentParser, friction: bool = True,
                    backend: bool = False) -> None:
    p.add_argument("--design", choices=("fast", "slow"), default="fast",
                   help="design preset of Sec. 2.4 (eqs. 13-16), applied before --set "
                        "(default: %(default)s)")
    add_plant_arg(p, backend)
    if friction:
        p.add_argument("--friction", choices=PLANT_FRICTION_KINDS, default="classical",
                       help="friction model of the simulated plant (default: %(default)s)")
        p.add_argument("--compensation", choices=COMPENSATOR_KINDS, default="none",
                       help="friction compensator in the controller (default: %(default)s)")
    add_key_args(p)


def add_key_args(p, applies_to: str = "") -> None:
    """``--config FILE`` and ``--set KEY=VALUE`` (repeatable): parameter keys from a
    TOML file, then the ``--set`` ones over them, later winning (``applies_to``:
    what they set, for the help, e.g. "all experiments")."""
    where = f" of {applies_to}" if applies_to else ""
    p.add_argument("--config", metavar="FILE", help=f"TOML file with parameter keys{where}")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                   help=f"override a parameter key{where} (repeatable; later wins); "
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
    from ..config import inert_keys, load_toml

    plant = plant_from_args(args)
    items = [*backend_rig_items(args), *(load_toml(args.config, plant) if args.config else []),
             *parse_sets(args.sets)]
    cfg = build_config(
        design=args.design,
        friction=getattr(args, "friction", "classical"),
        compensation=getattr(args, "compensation", "none"),
        sets=items,
        plant=plant,
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


def backend_rig_items(args) -> list[tuple[str, float]]:
    """The ``rig.*`` values ``--backend`` implies, applied before ``--config`` and
    ``--set`` (a QUBE-Servo's: u in volts, its encoders' channels; none for the others)."""
    spec = getattr(args, "backend", None)
    if not isinstance(spec, str) or not spec.startswith(("qube2:", "qube3:")):
        return []
    # start-up time: the real-time package is imported only when a QUBE is named
    from ..realtime.qube import QUBE_RIG

    return list(QUBE_RIG.items())


def hanging_start(args, cfg: Config) -> Config:
    """With ``--swing-up`` and no ``sim.initial_angle`` given (``--set`` or ``--config``),
    start hanging (pi): a swing-up from the balancing default 0.05 rad would be none."""
    from ..config import load_toml

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


def add_engine_args(p) -> None:
    """``--workers`` and ``--dask`` of the commands that run the sweep engine
    (``sweep``, ``reproduce``, ``identify limit-cycle``, ``compensate tune``);
    :func:`check_engine_args` checks them."""
    p.add_argument("--workers", type=int, default=None,
                   help="threads of the sweep engine (default: all cores; 1 = the calling "
                        "thread); with --dask local, the number of Dask workers")
    p.add_argument("--dask", metavar="local|tcp://HOST:PORT", default=None,
                   help="run on Dask: start a LocalCluster, or join a running scheduler")


def check_engine_args(args) -> None:
    """Refuse, before any work, a worker count or a Dask address that cannot be used."""
    check_workers(args.workers)
    if args.dask is not None:
        from ..studies.sweep import check_dask_address

        check_dask_address(args.dask)


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
