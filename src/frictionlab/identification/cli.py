"""``frictionlab identify ...``: the command line of the identification package."""

from __future__ import annotations

import json
import math
import signal
import sys

from .._validation import ParamError
from ..cli import (
    UsageError,
    _add_config_args,
    check_output_path,
    check_workers,
    emit_json,
    finite,
    parse_sets,
    progress_bar,
)
from ..config import PLANT_FRICTION_KINDS, build_config
from ..limit_cycles import FEATURES
from .experiments import EXPERIMENTS, IdentificationError

__all__ = ["parse_bounds", "parse_weights", "register_cli"]


def _float(text: str, what: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise UsageError(f"{what}: {text!r} is not a number") from None
    if not math.isfinite(v):
        raise UsageError(f"{what}: {text!r} must be finite")
    return v


def parse_bounds(items: list[str]) -> dict[str, tuple[float, float]]:
    """``KEY=LO:HI`` items -> {key: (lo, hi)} (checked against the fitted keys later)."""
    out = {}
    for item in items:
        if "=" not in item or ":" not in item.split("=", 1)[1]:
            raise UsageError(f"--bounds expects KEY=LO:HI, got {item!r}")
        key, rng = item.split("=", 1)
        lo_s, hi_s = rng.split(":", 1)
        lo, hi = _float(lo_s, f"--bounds {key}"), _float(hi_s, f"--bounds {key}")
        if not lo < hi:
            raise UsageError(f"--bounds {key}: lower bound {lo:g} must be below upper {hi:g}")
        out[key.strip()] = (lo, hi)
    return out


def parse_weights(items: list[str]) -> dict[str, float]:
    out = {}
    for item in items:
        if "=" not in item:
            raise UsageError(f"--weights expects FEATURE=W, got {item!r}")
        name, w = item.split("=", 1)
        name = name.strip()
        if name not in FEATURES:
            raise UsageError(f"--weights: unknown feature {name!r}; known features: "
                             f"{', '.join(FEATURES)}")
        value = _float(w, f"--weights {name}")
        if value < 0:
            raise UsageError(f"--weights {name}: weight must be >= 0, got {value:g}")
        out[name] = value
    return out


#: Largest ``--measured`` file read (bytes); a file of features is a few kB.
MAX_MEASURED_BYTES = 16 << 20


def _load_measured(path: str):
    from .limit_cycle import parse_experiments

    try:
        with open(path, "rb") as fh:
            raw = fh.read(MAX_MEASURED_BYTES + 1)
    except OSError as exc:
        raise UsageError(f"cannot read --measured {path}: {exc.strerror or exc}") from None
    if len(raw) > MAX_MEASURED_BYTES:
        raise UsageError(f"--measured {path} is larger than {MAX_MEASURED_BYTES >> 20} MB; "
                         "it is not a file of measured features")
    try:
        obj = json.loads(raw)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise UsageError(f"--measured {path} is not valid JSON: {exc}") from None
    except RecursionError:
        raise UsageError(f"--measured {path} is not valid JSON: nested too deeply") from None
    return parse_experiments(obj)


#: Largest ``--maxiter`` and ``--popsize`` (per fitted key) of ``identify limit-cycle``:
#: the population is held in memory, and 1000 generations of 100 per key is
#: already hours of simulation.
MAX_ITER, MAX_POPSIZE = 100_000, 1000

#: The fields of ``identify limit-cycle --json`` (INTERFACE.md); the rest of
#: :meth:`FitResult.to_json` goes to ``--report FILE.json``.
INTERFACE_FIELDS = ("estimate", "stderr", "residuals", "cost")


def _write_report(path: str, obj: dict) -> None:
    from ..cli import _clean

    try:
        with open(path, "w") as fh:
            json.dump(_clean(obj), fh, indent=1)
            fh.write("\n")
    except OSError as exc:
        raise UsageError(f"cannot write --report {path}: {exc.strerror}") from None


def _never(*args, **kwargs):  # pragma: no cover - validation only
    raise AssertionError("validation must not simulate")


def cmd_limit_cycle(args) -> int:
    from .limit_cycle import (
        LimitCycleProblem,
        check_fit_keys,
        fit_limit_cycle,
        search_settings,
    )

    experiments = _load_measured(args.measured)
    keys = check_fit_keys([k.strip() for k in args.fit.split(",") if k.strip()])
    bounds = parse_bounds(args.bounds)
    weights = parse_weights(args.weights)
    check_output_path(args.plot, (".png", ".pdf", ".svg"), "--plot")
    check_output_path(args.report, (".json",), "--report")
    check_workers(args.workers)
    if args.dask is not None:
        from ..sweep import _check_dask_address

        _check_dask_address(args.dask)
    if not 1 <= args.maxiter <= MAX_ITER:
        raise UsageError(f"--maxiter must be in 1..{MAX_ITER}, got {args.maxiter}")
    if not 2 <= args.popsize <= MAX_POPSIZE:
        raise UsageError(f"--popsize must be in 2..{MAX_POPSIZE}, got {args.popsize}")
    if not 0 <= args.seed < 2**32:
        raise UsageError(f"--seed must be in 0..{2**32 - 1}, got {args.seed}")
    if not 1e-5 <= args.rel_step <= 0.2:
        raise UsageError(f"--rel-step must be in [1e-5, 0.2], got {args.rel_step:g}")
    sets = parse_sets(args.sets)
    if args.config:
        from ..config import load_toml

        sets = [*load_toml(args.config), *sets]
    # validate the whole problem (settings, bounds, run length) before any
    # output or simulation: bad input exits 2 with a single stderr line
    constrained = not args.allow_stiction_below_coulomb
    LimitCycleProblem(experiments, keys, friction=args.friction, sets=sets, bounds=bounds,
                      weights=weights, duration=args.duration, window=args.window,
                      evaluate=_never, stiction_above_coulomb=constrained)
    search_settings(args.duration, args.window, args.search_duration, args.search_window)
    err = sys.stderr
    print(f"identify limit-cycle: {len(experiments)} experiment(s), fitting "
          f"{', '.join(keys)} ({args.friction} friction, {args.duration:g} s runs)", file=err)
    tty = err.isatty()
    last = [-1]

    def on_term(signum, frame):
        raise KeyboardInterrupt  # main() says "interrupted" in one line, exit 130

    previous = signal.signal(signal.SIGTERM, on_term)
    try:
        with progress_bar("fitting", tty and not args.quiet) as upd:
            def progress(stage: str, frac: float, cost: float) -> None:
                upd(0.9 * frac if stage == "global" else 0.9 + 0.1 * frac)
                if tty or args.quiet:
                    return
                # not a terminal (a log file): a line per 10 % of the global search
                step = int(10 * frac) if stage == "global" else 10 + int(frac)
                if step > last[0]:
                    last[0] = step
                    what = ("global search" if stage == "global" else "least-squares polish")
                    print(f"{what}: {100 * frac:3.0f} %, best cost {cost:.4g}", file=err)

            result = fit_limit_cycle(
                experiments, keys, friction=args.friction, sets=sets, bounds=bounds,
                weights=weights, duration=args.duration, window=args.window,
                workers=args.workers, dask=args.dask, seed=args.seed, maxiter=args.maxiter,
                popsize=args.popsize, rel_step=args.rel_step, progress=progress,
                stiction_above_coulomb=constrained, search_duration=args.search_duration,
                search_window=args.search_window)
    finally:
        signal.signal(signal.SIGTERM, previous)
    for w in result.warnings:
        print(f"warning: {w}", file=err)
    print(f"done in {result.seconds:.1f} s: {result.evaluations} parameter sets, "
          f"{result.generations} generations, cost {result.cost:.4g}", file=err)
    if args.plot:
        from ..simulation import simulate_config
        from .limit_cycle import experiment_config
        from .plots import plot_limit_cycle_fit

        trajs = [simulate_config(experiment_config(result, i), args.duration)
                 for i in range(len(experiments))]
        plot_limit_cycle_fit(result, trajs, args.plot, args.window)
    if args.report:
        _write_report(args.report, result.to_json())
        print(f"full report: {args.report}", file=err)
    if args.json:
        emit_json({k: result.to_json()[k] for k in INTERFACE_FIELDS})
    else:
        print("estimate:")
        for k, v in result.estimate.items():
            se = result.stderr.get(k)
            print(f"  {k:28s} {v:10.5g}  +- {'-' if se is None else f'{se:.3g}'}")
        print(f"cost {result.cost:.4g}; relative residuals (simulated - measured)/measured:")
        for label, res in result.residuals.items():
            cells = "  ".join(f"{f} {'-' if r is None else f'{r:+.3f}'}" for f, r in res.items())
            print(f"  {label:8s} {cells}")
    return 0


# ---------------------------------------------------------------------------
# simple experiments
# ---------------------------------------------------------------------------

_DEFAULT_FRICTION = {"stiction": "classical", "stribeck": "lugre",
                     "free-oscillation": "classical", "control-scaling": "classical"}


def _float_list(text: str, what: str) -> list[float]:
    vals = [_float(x, what) for x in text.split(",") if x.strip()]
    if not vals:
        raise UsageError(f"{what}: give at least one value")
    return vals


def cmd_experiment(args) -> int:
    from . import experiments as ex

    name = args.experiment
    friction = args.friction or _DEFAULT_FRICTION[name]
    cfg = build_config(design=args.design, friction=friction, config_file=args.config,
                       sets=parse_sets(args.sets))
    check_output_path(args.save, (".dat", ".csv"), "--save")
    check_output_path(args.plot, (".png", ".pdf", ".svg"), "--plot")
    if args.log and args.save:
        raise UsageError("--save only applies to --simulate runs")
    warnings: list[str] = []
    if args.log:
        from .logs import log_warnings, read_log

        log = read_log(args.log, cfg.design.h)
        warnings += log_warnings(args.log)
        source = args.log
    else:
        if name == "stiction":
            log = ex.simulate_stiction(cfg, step=args.step, hold=args.hold)
        elif name == "stribeck":
            refs = (_float_list(args.references, "--references") if args.references
                    else ex.STRIBECK_REFERENCES)
            log = ex.simulate_stribeck(cfg, references=refs, gain=args.gain, hold=args.hold)
        elif name == "free-oscillation":
            log = ex.simulate_free_oscillation(cfg, amplitude=args.amplitude,
                                               duration=args.duration or 12.0)
        else:
            levels = (_float_list(args.levels, "--levels") if args.levels
                      else ex.SCALING_LEVELS)
            log = ex.simulate_control_scaling(cfg, levels=levels)
        source = "simulated"
        if args.save:
            log.save(args.save)
    ku = cfg.plant.input_gain
    try:
        if name == "stiction":
            res = ex.analyse_stiction(log, input_gain=ku, arm_length=cfg.plant.arm_length)
        elif name == "stribeck":
            res = ex.analyse_stribeck(log, input_gain=ku)
        elif name == "free-oscillation":
            res = ex.analyse_free_oscillation(log, max_amplitude=args.max_amplitude)
        else:
            res = ex.analyse_control_scaling(log, coulomb=cfg.friction.coulomb,
                                             arm_length=cfg.plant.arm_length)
    except IdentificationError as exc:
        raise UsageError(f"{name}: {exc}") from None
    if args.plot:
        from . import plots

        appendix = {"stiction": "App. E.1", "stribeck": "App. E.2",
                    "free-oscillation": "App. A", "control-scaling": "App. B.4"}[name]
        title = plots.experiment_title(
            f"identify experiment {name} ({appendix})",
            f"log {args.log}" if args.log else "simulated rig", None if args.log else cfg)
        if name == "stiction":
            plots.plot_stiction(log, res, args.plot, title)
        elif name == "stribeck":
            plots.plot_stribeck(res, args.plot, title)
        elif name == "free-oscillation":
            plots.plot_free_oscillation(log, res, args.plot, title)
        else:
            plots.plot_control_scaling(log, res, args.plot, title)
    warnings += res.get("warnings", [])
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    out = dict(res)
    out["warnings"] = warnings
    out["source"] = source
    if args.save:
        out["saved"] = args.save
    if args.plot:
        out["plot"] = args.plot
    if args.json:
        emit_json(out)
    else:
        print(f"{name} ({source}):")
        for k, v in ex.estimates_only(res).items():
            print(f"  {k:28s} {v:.5g}")
    return 0


def register_cli(sub) -> None:
    """Add ``identify limit-cycle`` and ``identify experiment`` to the parser."""
    p = sub.add_parser("identify", help="friction and process identification (Sec. 5, "
                                        "App. A, B, E)")
    isub = p.add_subparsers(dest="identify_command", metavar="METHOD")
    p.set_defaults(func=lambda a: (p.print_help(), 0)[1])

    q = isub.add_parser(
        "limit-cycle", help="fit parameter keys to measured limit-cycle features",
        description="Fit parameter keys to measured limit-cycle features of one or more "
                    "experiments (differential evolution, then least squares).")
    q.add_argument("--measured", required=True, metavar="FILE.json",
                   help='{"experiments": [{"design": "fast"|"slow", "set": {...}, '
                        '"features": {"peak1": ..., ...}}, ...]} (see examples/table1.json)')
    q.add_argument("--friction", choices=PLANT_FRICTION_KINDS, default="classical",
                   help="plant friction model of the simulations (default: classical)")
    q.add_argument("--fit", required=True, metavar="KEY[,KEY...]",
                   help="keys to estimate, e.g. friction.coulomb,plant.omega0")
    q.add_argument("--config", metavar="FILE", help="TOML file with parameter keys")
    q.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                   help="setting common to all experiments (repeatable)")
    q.add_argument("--bounds", action="append", default=[], metavar="KEY=LO:HI",
                   help="search bounds of a fitted key (repeatable; defaults per key)")
    q.add_argument("--weights", action="append", default=[], metavar="FEATURE=W",
                   help="weight of a feature's relative error (repeatable; default 1)")
    q.add_argument("--duration", type=float, default=30.0,
                   help="simulated seconds per run (default 30)")
    q.add_argument("--window", type=float, default=20.0,
                   help="features over the last S seconds (default 20)")
    q.add_argument("--search-duration", type=float, default=None, metavar="S",
                   help="simulated seconds per run of the global search only (default: "
                        "--duration); the polish and standard errors use --duration")
    q.add_argument("--search-window", type=float, default=None, metavar="S",
                   help="feature window of the global search (default: --window scaled "
                        "by --search-duration / --duration)")
    q.add_argument("--workers", type=int, default=None,
                   help="threads of the sweep engine (default: all cores; 1 = the "
                        "calling thread); with --dask, the number of Dask workers")
    q.add_argument("--dask", metavar="local|tcp://HOST:PORT", default=None,
                   help="evaluate on a Dask cluster")
    q.add_argument("--allow-stiction-below-coulomb", action="store_true",
                   help="when friction.stiction and friction.coulomb (or their _negative "
                        "pair) are both fitted, also search stiction < Coulomb level (by "
                        "default the fit keeps stiction >= Coulomb, as the classical and "
                        "LuGre models assume)")
    q.add_argument("--seed", type=int, default=0, help="seed of the global search (default 0)")
    q.add_argument("--maxiter", type=int, default=40,
                   help="generations of differential evolution (default 40)")
    q.add_argument("--popsize", type=int, default=8,
                   help="population per fitted key (default 8)")
    q.add_argument("--rel-step", type=float, default=0.01,
                   help="relative finite-difference step of the Jacobian (default 0.01)")
    q.add_argument("--plot", metavar="FILE.png", help="overlay measured and fitted features")
    q.add_argument("--report", metavar="FILE.json",
                   help="write the full result (simulated features, warnings, singular "
                        "values, correlation, bounds, timing) to FILE.json")
    q.add_argument("--quiet", action="store_true", help="no progress bar")
    q.add_argument("--json", action="store_true", help="print one JSON object")
    q.set_defaults(func=cmd_limit_cycle)

    e = isub.add_parser(
        "experiment", help="the simple experiments of App. A, B.4 and E",
        description="Run a simple identification experiment of App. A, B.4 or E on the "
                    "simulated rig (--simulate, the default) or analyse a recorded log.")
    e.add_argument("experiment", choices=EXPERIMENTS)
    src = e.add_mutually_exclusive_group()
    src.add_argument("--log", metavar="FILE", help="analyse a recorded log (.csv or .dat)")
    src.add_argument("--simulate", action="store_true",
                     help="run the experiment on the simulated rig (default)")
    _add_config_args(e, friction=False)
    e.add_argument("--friction", choices=PLANT_FRICTION_KINDS, default=None,
                   help="friction of the simulated rig (default: classical; lugre for "
                        "stribeck)")
    e.add_argument("--save", metavar="FILE", help="save the simulated log (.csv or .dat)")
    e.add_argument("--plot", metavar="FILE.png", help="plot the experiment (Figs. 33, 37, 38)")
    e.add_argument("--step", type=float, default=0.02,
                   help="stiction: staircase step of u (default 0.02)")
    e.add_argument("--hold", type=float, default=None,
                   help="seconds per level (stiction 0.25, stribeck 2)")
    e.add_argument("--references", metavar="V1,V2,...",
                   help="stribeck: velocity references in rad/s (both signs are run)")
    e.add_argument("--gain", type=float, default=20.0,
                   help="stribeck: P gain of the velocity loop (default 20)")
    e.add_argument("--amplitude", type=float, default=0.25,
                   help="free-oscillation: initial deflection in rad (default 0.25)")
    e.add_argument("--max-amplitude", type=float, default=0.15,
                   help="free-oscillation: peaks above this are not used (default 0.15)")
    e.add_argument("--duration", type=float, default=None,
                   help="free-oscillation: recorded seconds (default 12)")
    e.add_argument("--levels", metavar="U1,U2,...",
                   help="control-scaling: constant u values (default 3,4,5,7,9)")
    e.add_argument("--json", action="store_true", help="print one JSON object")
    e.set_defaults(func=_experiment_entry)


#: The options of ``identify experiment`` that set an experiment's argument of
#: the same name (its :class:`ParamError` names the option).
_EXPERIMENT_OPTIONS = {"step": "--step", "hold": "--hold", "gain": "--gain",
                       "amplitude": "--amplitude", "duration": "--duration",
                       "references": "--references", "levels": "--levels",
                       "max_amplitude": "--max-amplitude"}


def _experiment_entry(args) -> int:
    if args.hold is None:
        args.hold = 2.0 if args.experiment == "stribeck" else 0.25
    finite("--step", args.step, 0.0)
    finite("--gain", args.gain, 0.0)
    finite("--amplitude", args.amplitude)
    finite("--max-amplitude", args.max_amplitude, 0.0)
    finite("--hold", args.hold, 0.0)
    finite("--duration", args.duration, 0.0)
    try:
        return cmd_experiment(args)
    except ParamError as exc:
        option = _EXPERIMENT_OPTIONS.get(exc.field)
        if option is None:
            raise
        raise UsageError(str(exc).replace(exc.field, option, 1)) from None
    except IdentificationError as exc:
        raise UsageError(str(exc)) from None
