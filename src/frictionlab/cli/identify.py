"""``frictionlab identify ...``: the command line of the identification package."""

from __future__ import annotations

import json
import signal
import sys

from ..config import PLANT_FRICTION_KINDS, PLANT_NAMES, build_config, load_toml
from ..model.limit_cycles import FEATURES
from ..model.params import ParamError
from ..studies.identification.experiments import EXPERIMENTS, IdentificationError
from .common import (
    UsageError,
    add_config_args,
    add_engine_args,
    add_key_args,
    add_plant_arg,
    add_stall_args,
    backend_rig_items,
    check_engine_args,
    check_output_dir,
    check_output_path,
    check_window,
    emit_json,
    error_message,
    finite,
    note_text,
    parse_number,
    parse_sets,
    progress_bar,
    safety_from_args,
)
from .features import design_h, log_experiment

__all__ = ["parse_bounds", "parse_weights", "register_cli"]


def parse_bounds(items: list[str]) -> dict[str, tuple[float, float]]:
    """``KEY=LO:HI`` items -> {key: (lo, hi)} (checked against the fitted keys later)."""
    out = {}
    for item in items:
        if "=" not in item or ":" not in item.split("=", 1)[1]:
            raise UsageError(f"--bounds expects KEY=LO:HI, got {item!r}")
        key, rng = item.split("=", 1)
        lo_s, hi_s = rng.split(":", 1)
        lo, hi = parse_number(lo_s, f"--bounds {key}"), parse_number(hi_s, f"--bounds {key}")
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
        value = parse_number(w, f"--weights {name}")
        if value < 0:
            raise UsageError(f"--weights {name}: weight must be >= 0, got {value:g}")
        out[name] = value
    return out


#: Largest ``--measured`` file read (bytes); a file of features is a few kB.
MAX_MEASURED_BYTES = 16 << 20


#: The fields of a ``frictionlab features`` object that make an experiment.
_EXPERIMENT_FIELDS = ("design", "set", "features", "name")


def _as_experiment(obj: dict) -> dict:
    """The experiment in a ``frictionlab features`` object (its extra fields dropped)."""
    return {k: obj[k] for k in _EXPERIMENT_FIELDS if k in obj}


def load_measured(paths, sets=()) -> list:
    """The experiments of every ``--measured`` file (:func:`read_measured`)."""
    return read_measured(paths, sets)[0]


def _named_plant(obj: dict, where: str) -> str | None:
    """The ``"plant"`` an experiment or a file names (None: not said)."""
    plant = obj.get("plant")
    if plant is None:
        return None
    if plant not in PLANT_NAMES:
        raise UsageError(f"--measured {where}: \"plant\" {str(plant)[:40]!r} is not one of "
                         f"{', '.join(PLANT_NAMES)}")
    return plant


def read_measured(paths, sets=()) -> tuple[list, list[tuple[str, str | None]]]:
    """The experiments of every ``--measured`` file, and the plant each names.

    A file is a JSON object ``{"experiments": [...]}`` (an optional ``"plant"``
    for all its experiments, or one per experiment), one ``frictionlab
    features`` object (its ``"plant"``, from the run's sidecar), or a run log
    (``.csv``/``.dat``, its features over the last half and the plant of its
    sidecar; a ``.dat`` takes ``design.h`` from ``sets`` when it has no sidecar).

    Returns
    -------
    (experiments, plants)
        The validated experiments, and ``(file, plant)`` for each experiment
        (``plant`` None where the file does not say).
    """
    from ..studies.identification.limit_cycle import parse_experiments

    items: list = []
    plants: list[tuple[str, str | None]] = []
    for path in [paths] if isinstance(paths, str) else paths:
        if path.endswith((".csv", ".dat")):
            feats = log_experiment(path, design_h(sets))
            if feats["status"] == "fell":
                raise UsageError(f"--measured {path}: the run fell (stop reason "
                                 f"{feats['stop_reason']}); it has no limit cycle")
            items.append(_as_experiment(feats))
            plants.append((path, feats["plant"]))
            continue
        obj = _load_json(path)
        if isinstance(obj, dict) and "experiments" not in obj and "features" in obj:
            items.append(_as_experiment(obj))
            plants.append((path, _named_plant(obj, path)))
        elif isinstance(obj, dict) and isinstance(obj.get("experiments"), list):
            common = _named_plant(obj, path)
            for e in obj["experiments"]:
                own = _named_plant(e, path) if isinstance(e, dict) else None
                if own is not None and common is not None and own != common:
                    raise UsageError(f"--measured {path}: an experiment of the {own} plant "
                                     f"in a file of the {common} plant")
                if isinstance(e, dict) and ("status" in e or "plant" in e):
                    e = _as_experiment(e)
                items.append(e)
                plants.append((path, own or common))
        else:
            parse_experiments(obj)  # says what is wrong
            items.append(obj)
            plants.append((path, None))
    return parse_experiments({"experiments": items}), plants


def measured_plant(plants: list[tuple[str, str | None]], given: str | None) -> str:
    """The plant to fit on: ``--plant`` (``given``), else the one the measured files
    name (:func:`read_measured`), else ``thesis``.

    Raises
    ------
    UsageError
        Files of different plants, or a ``--plant`` that contradicts them.
    """
    named: dict[str, str] = {}
    for path, plant in plants:
        if plant is not None:
            named.setdefault(plant, path)
    if len(named) > 1:
        which = ", ".join(f"{path} the {plant}" for plant, path in named.items())
        raise UsageError(f"--measured: the files are of different plants ({which}); fit "
                         "the experiments of one plant at a time")
    if named:
        (plant, path), = named.items()
        if given is not None and given != plant:
            raise UsageError(f"--plant {given}: the measured experiments are of the {plant} "
                             f"plant ({path}); drop --plant or give --plant {plant}")
        return plant
    return given or "thesis"


def _load_json(path: str):
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
    return obj


#: Largest ``--maxiter`` and ``--popsize`` (per fitted key) of ``identify limit-cycle``:
#: the population is held in memory, and 1000 generations of 100 per key is
#: already hours of simulation.
MAX_ITER, MAX_POPSIZE = 100_000, 1000

#: The fields of ``identify limit-cycle --json`` (docs/cli.md); the rest of
#: :meth:`FitResult.to_json` goes to ``--report FILE.json``.
PUBLIC_FIELDS = ("estimate", "stderr", "residuals", "cost")


def _write_report(path: str, obj: dict) -> None:
    from ..io.jsonsafe import json_safe

    try:
        with open(path, "w") as fh:
            json.dump(json_safe(obj), fh, indent=1)
            fh.write("\n")
    except OSError as exc:
        raise UsageError(f"cannot write --report {path}: {exc.strerror}") from None


def _never(*args, **kwargs):  # pragma: no cover - validation only
    raise AssertionError("validation must not simulate")


def cmd_limit_cycle(args) -> int:
    from ..studies.identification.limit_cycle import (
        LimitCycleProblem,
        check_fit_keys,
        fit_limit_cycle,
        search_settings,
    )

    experiments, plants = read_measured(args.measured, args.sets)
    given = args.plant
    args.plant = measured_plant(plants, given)
    keys = check_fit_keys([k.strip() for k in args.fit.split(",") if k.strip()], args.plant)
    bounds = parse_bounds(args.bounds)
    weights = parse_weights(args.weights)
    check_output_path(args.plot, (".png", ".pdf", ".svg"), "--plot")
    check_output_path(args.report, (".json",), "--report")
    check_engine_args(args)
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

        sets = [*load_toml(args.config, args.plant), *sets]
    # validate the whole problem (settings, bounds, run length) before any
    # output or simulation: bad input exits 2 with a single stderr line
    constrained = not args.allow_stiction_below_coulomb
    check_window(args.window, args.duration)
    LimitCycleProblem(experiments, keys, friction=args.friction, sets=sets, bounds=bounds,
                      weights=weights, duration=args.duration, window=args.window,
                      evaluate=_never, stiction_above_coulomb=constrained, plant=args.plant)
    finite("--search-duration", args.search_duration, 0.0)
    search_settings(args.duration, args.window, args.search_duration, args.search_window)
    err = sys.stderr
    source = " (from the measured files)" if given is None and args.plant != "thesis" else ""
    print(f"identify limit-cycle: {len(experiments)} experiment(s) on the {args.plant} "
          f"plant{source}, fitting {', '.join(keys)} ({args.friction} friction, "
          f"{args.duration:g} s runs)", file=err)
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
                search_window=args.search_window, plant=args.plant)
    finally:
        signal.signal(signal.SIGTERM, previous)
    for w in result.warnings:
        print(f"warning: {note_text(w)}", file=err)
    print(f"done in {result.seconds:.1f} s: {result.evaluations} parameter sets, "
          f"{result.generations} generations, cost {result.cost:.4g}", file=err)
    if args.plot:
        from ..runs import simulate_config
        from ..studies.identification.limit_cycle import experiment_config
        from ..studies.identification.plots import plot_limit_cycle_fit

        trajs = [simulate_config(experiment_config(result, i), args.duration)
                 for i in range(len(experiments))]
        plot_limit_cycle_fit(result, trajs, args.plot, args.window)
    if args.report:
        report = result.to_json()
        report["warnings"] = [note_text(w) for w in report["warnings"]]
        _write_report(args.report, report)
        print(f"full report: {args.report}", file=err)
    if args.json:
        emit_json({k: result.to_json()[k] for k in PUBLIC_FIELDS})
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
                     "free-oscillation": "classical", "control-scaling": "classical",
                     "velocity-scale": "classical", "angle-scales": "classical"}


def _float_list(text: str, what: str) -> list[float]:
    vals = [parse_number(x, what) for x in text.split(",") if x.strip()]
    if not vals:
        raise UsageError(f"{what}: give at least one value")
    return vals


def _limits(args):
    from ..realtime.experiment import Limits

    # a refused limit is a ParamError named after its option by _experiment_entry
    return Limits(max_speed=args.max_speed, max_travel=args.max_travel, max_u_da=args.max_u_da)


def _rig_options(args) -> dict:
    """The experiment options of the command line for the loop's experiments."""
    name = args.experiment
    if name == "stiction":
        opts = {"step": args.step, "hold": args.hold, "slide": args.slide, "push": args.push}
        if args.coulomb_levels:
            opts["coulomb_levels"] = _float_list(args.coulomb_levels, "--coulomb-levels")
        return opts
    if name in ("stribeck", "velocity-scale"):
        opts = {"gain": args.gain, "hold": args.hold}
        if args.references:
            opts["references"] = _float_list(args.references, "--references")
        return opts
    if name == "free-oscillation":
        return {"amplitude": args.amplitude if args.amplitude_given else None,
                "duration": args.duration}
    if name == "angle-scales":
        return {"wait": args.wait}
    levels = _float_list(args.levels, "--levels") if args.levels else None
    return {"levels": levels}


def _run_experiment(exp, cfg, backend, log_dir, args, clock=None):
    """Run ``exp`` through the loop with progress on stderr; (log, run summary).

    A run that does not finish (a fault, a limit, a signal) is reported and
    ends the command with exit status 1; its log is kept.
    """
    from ..io.logs import read_log
    from ..realtime import RigError
    from ..studies.identification.onrig import run_on_rig
    from .run import RunSignals, interface_stats

    safety = safety_from_args(args)  # a refused value exits 2 before the announcement
    err = sys.stderr
    lim = exp.limits
    if clock is None:
        print(f"identify experiment {exp.name} on {backend}: the motor will move the arm "
              f"(limits: arm speed {lim.max_speed:g} rad/s, travel {lim.max_travel:g} rad, "
              f"|u_DA| {lim.max_u_da:g}); Ctrl-C stops it with the motor at zero",
              file=err)
    tty = err.isatty() and not args.quiet
    last = [None]

    def poll(e, upd=None):
        if upd is not None:
            upd(e.progress)
        elif e.phase != last[0] and not args.quiet:
            last[0] = e.phase
            print(f"  {100 * e.progress:3.0f} %  {e.phase}", file=err)

    with RunSignals() as signals, progress_bar(exp.name, tty and clock is None) as upd:
        def on_start(ctl):
            signals.ctl = ctl

        try:
            st = run_on_rig(exp, cfg, backend, log_dir=log_dir, clock=clock,
                            realtime=not args.no_realtime, on_start=on_start,
                            poll=lambda e: poll(e, upd if tty else None),
                            on_prompt=lambda p: print(f">>> {p['text']}", file=err),
                            hand=args.hand, safety=safety)
        except (RigError, OSError, RuntimeError) as exc:
            print(f"frictionlab identify experiment: error: {exc}", file=err)
            raise SystemExit(1) from None
    summary = interface_stats(st)
    summary["stop_detail"] = st.get("stop_detail")
    if st["stop_reason"] != "finished":
        print(f"frictionlab identify experiment: {exp.name} stopped before it finished: "
              f"{st['stop_reason']} ({st.get('stop_detail') or ''}); the motor was set to "
              f"zero; log kept: {st['log']}", file=err)
        raise SystemExit(1)
    if clock is None:
        print(f"  done: {st['ticks']} ticks, {st['missed']} missed; log {st['log']}", file=err)
    return read_log(st["log"], cfg.design.h), summary


def _save_sidecar(log_path: str, name: str, marks: dict) -> None:
    """Beside a saved simulated log, the sidecar a rig run writes for the analysis
    (``<log>.json``: the experiment's name and marks), so that ``--log`` on the file
    cuts the free oscillation where its free decay starts."""
    from pathlib import Path

    Path(log_path).with_suffix(".json").write_text(
        json.dumps({"experiment": {"name": name, "marks": marks}}) + "\n")


def cmd_experiment(args) -> int:
    from ..studies.identification import experiments as ex

    name = args.experiment
    friction = args.friction or _DEFAULT_FRICTION[name]
    cfg = build_config(design=args.design, friction=friction,
                       sets=[*backend_rig_items(args),
                             *(load_toml(args.config) if args.config else []),
                             *parse_sets(args.sets)])
    check_output_path(args.save, (".dat", ".csv"), "--save")
    check_output_path(args.plot, (".png", ".pdf", ".svg"), "--plot")
    if args.plot and name in ("velocity-scale", "angle-scales"):
        raise UsageError(f"--plot: no figure for {name}")
    if args.log and args.save:
        raise UsageError("--save only applies to --simulate runs")
    if args.backend and args.save:
        raise UsageError("--save only applies to --simulate runs (a --backend run is logged "
                         "in --log-dir)")
    warnings: list[str] = []
    run_info = None
    marks: dict = {}
    if args.log:
        from ..io.logs import log_warnings, read_log
        from ..studies.identification.onrig import experiment_marks

        log = read_log(args.log, cfg.design.h)
        warnings += log_warnings(args.log)
        marks = experiment_marks(args.log)
        source = args.log
    elif name == "angle-scales" and not args.backend:
        raise UsageError("angle-scales needs --backend (a rig, or rig-sim over UDP with "
                         "--hand) or --log: its laps are turned by hand")
    elif args.backend or name == "velocity-scale":
        from ..studies.identification.onrig import make_rig_experiment

        if args.backend not in (None, "sim"):
            from ..realtime.api import check_backend

            try:
                check_backend(args.backend)
            except ValueError as exc:
                raise UsageError(error_message(exc)) from None
        if args.backend is None and args.save and not args.save.endswith(".csv"):
            raise UsageError("--save: a simulated velocity-scale run is saved as .csv")
        try:
            exp = make_rig_experiment(name, cfg, _limits(args), **_rig_options(args))
        except ParamError:
            raise  # named after its option by _experiment_entry
        except ValueError as exc:
            raise UsageError(f"{name}: {exc}") from None
        if args.backend is None:
            # --simulate: the same loop on the simulated rig, on a fake clock (no waiting)
            import tempfile

            from ..realtime import FakeClock

            with tempfile.TemporaryDirectory() as tmp:
                log, run_info = _run_experiment(exp, cfg, "sim", tmp, args, clock=FakeClock())
                if args.save:
                    import shutil

                    shutil.copyfile(run_info["log"], args.save)
                run_info["log"] = None
            source = "simulated"
        else:
            check_output_dir(args.log_dir, "--log-dir")
            log, run_info = _run_experiment(exp, cfg, args.backend, args.log_dir, args)
            source = args.backend
        marks = dict(exp.marks)
    else:
        # the rig's schedule (its options and limits) on the simulated rig, in-process
        log = ex.simulate_experiment(name, cfg, _limits(args), **_rig_options(args))
        marks = dict(log.meta["marks"])
        source = "simulated"
        if args.save:
            log.save(args.save)
            _save_sidecar(args.save, name, marks)
    from ..studies.identification.onrig import analyse_log

    try:
        res = analyse_log(name, log, cfg, marks=marks, max_amplitude=args.max_amplitude)
    except IdentificationError as exc:
        where = f" (log kept: {run_info['log']})" if run_info and run_info.get("log") else ""
        raise UsageError(f"{name}: {exc}{where}") from None
    if args.plot:
        from ..studies.identification import plots

        appendix = {"stiction": "App. E.1", "stribeck": "App. E.2",
                    "free-oscillation": "App. A", "control-scaling": "App. B.4",
                    "velocity-scale": "App. B.3", "angle-scales": "App. B.1-B.2"}[name]
        title = plots.experiment_title(
            f"identify experiment {name} ({appendix})",
            f"log {args.log}" if args.log else "simulated rig", None if args.log else cfg)
        if name == "stiction":
            plots.plot_stiction(log, res, args.plot, title)
        elif name == "stribeck":
            plots.plot_stribeck(res, args.plot, title)
        elif name == "free-oscillation":
            plots.plot_free_oscillation(log, res, args.plot, title)
        elif name == "control-scaling":
            plots.plot_control_scaling(log, res, args.plot, title)
        else:
            raise UsageError(f"--plot: no figure for {name}")
    warnings += [note_text(w, _EXPERIMENT_OPTIONS) for w in res.get("warnings", [])]
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    out = dict(res)
    out["warnings"] = warnings
    out["source"] = source
    if args.save:
        out["saved"] = args.save
    if run_info is not None:
        out["run"] = run_info
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
    q.add_argument("--measured", required=True, action="append", metavar="FILE",
                   help='{"experiments": [{"design": "fast"|"slow", "set": {...}, '
                        '"features": {"peak1": ..., ...}}, ...]} (see examples/table1.json), '
                        "the output of 'frictionlab features', or a run log (.csv, or .dat "
                        "with its sidecar or --set design.h) whose features are measured over "
                        "its last half; repeatable, the experiments of all are fitted together")
    q.add_argument("--friction", choices=PLANT_FRICTION_KINDS, default="classical",
                   help="plant friction model of the simulations (default: classical)")
    q.add_argument("--fit", required=True, metavar="KEY[,KEY...]",
                   help="keys to estimate, e.g. friction.coulomb,plant.omega0")
    add_plant_arg(q, default_from="the plant the --measured files name (a run log's "
                                  "sidecar, 'frictionlab features'), else thesis")
    add_key_args(q, "all experiments")
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
    add_engine_args(q)
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
        "experiment", help="the simple experiments of App. A, B and E",
        description="Run a simple identification experiment of App. A, B or E on the "
                    "simulated rig (--simulate, the default), on a rig through the real-time "
                    "loop (--backend), or analyse a recorded log (--log).  Exit status 1 "
                    "when a --backend run stops before it finished (a fault, a limit, a "
                    "signal; the motor is zeroed and the log kept).")
    e.add_argument("experiment", choices=EXPERIMENTS)
    src = e.add_mutually_exclusive_group()
    src.add_argument("--log", metavar="FILE", help="analyse a recorded log (.csv or .dat)")
    src.add_argument("--simulate", action="store_true",
                     help="run the experiment on the simulated rig (default)")
    src.add_argument("--backend", default=None,
                     metavar="sim|udp://HOST:PORT|serial://DEVICE|qube2://ID|qube3://ID",
                     help="run the experiment on a rig through the real-time loop (the loop "
                          "of `frictionlab run`: same timing, safety and logging), then "
                          "analyse its log")
    add_config_args(e, friction=False)
    e.add_argument("--friction", choices=PLANT_FRICTION_KINDS, default=None,
                   help="friction of the simulated rig (default: classical; lugre for "
                        "stribeck)")
    e.add_argument("--save", metavar="FILE", help="save the simulated log (.csv or .dat)")
    e.add_argument("--plot", metavar="FILE.png", help="plot the experiment (Figs. 33, 37, 38)")
    e.add_argument("--step", type=float, default=0.02,
                   help="stiction: staircase step of u (default 0.02)")
    e.add_argument("--hold", type=float, default=None,
                   help="seconds per level (stiction 0.25, stribeck and velocity-scale 2)")
    e.add_argument("--references", metavar="V1,V2,...",
                   help="stribeck, velocity-scale: velocity references in rad/s (both signs "
                        "are run)")
    e.add_argument("--gain", type=float, default=20.0,
                   help="stribeck, velocity-scale: P gain of the velocity loop (default 20)")
    e.add_argument("--amplitude", type=float, default=None,
                   help="free-oscillation: the swing in rad the excitation reaches before "
                        "the free decay (default 0.12)")
    e.add_argument("--max-amplitude", type=float, default=0.15,
                   help="free-oscillation: peaks above this are not used (default 0.15)")
    e.add_argument("--duration", type=float, default=None,
                   help="free-oscillation: recorded seconds of free decay (default 12)")
    e.add_argument("--levels", metavar="U1,U2,...",
                   help="control-scaling: constant u values (default 3,4,5,7,9; their "
                        "signs alternate)")
    e.add_argument("--coulomb-levels", metavar="F1,F2,...",
                   help="stiction: fractions of the breakaway u held while the arm "
                        "slides (default 0.3,0.4,...,0.9)")
    e.add_argument("--slide", type=float, default=0.8,
                   help="stiction: seconds each Coulomb level is held (default 0.8)")
    e.add_argument("--push", type=float, default=1.5,
                   help="stiction: arm speed in rad/s of the motor's push before a "
                        "slide (default 1.5)")
    g = e.add_argument_group("limits (every run) and the rig (--backend)")
    g.add_argument("--log-dir", default="runs",
                   help="where the run is logged (default ./runs)")
    g.add_argument("--max-speed", type=float, default=15.0, metavar="RAD/S",
                   help="stop when the arm is faster than this (default 15)")
    g.add_argument("--max-travel", type=float, default=60.0, metavar="RAD",
                   help="stop when the arm is farther than this from its start (default 60)")
    g.add_argument("--max-u-da", type=float, default=0.5, metavar="U_DA",
                   help="largest |u_DA| commanded, u is clipped (default 0.5)")
    add_stall_args(g)
    g.add_argument("--hand", action="store_true",
                   help="angle-scales: let rig-sim (over UDP) play the operator's hand for "
                        "the laps it asks for")
    g.add_argument("--wait", type=float, default=120.0, metavar="S",
                   help="angle-scales: longest wait for the operator per step (default 120)")
    e.add_argument("--quiet", action="store_true", help="no progress on stderr")
    e.add_argument("--json", action="store_true", help="print one JSON object")
    e.set_defaults(func=_experiment_entry)


#: The options of ``identify experiment`` that set an experiment's argument of
#: the same name (its :class:`ParamError` names the option).
_EXPERIMENT_OPTIONS = {"step": "--step", "hold": "--hold", "gain": "--gain",
                       "amplitude": "--amplitude", "duration": "--duration",
                       "references": "--references", "levels": "--levels",
                       "max_amplitude": "--max-amplitude", "slide": "--slide",
                       "push": "--push", "coulomb_levels": "--coulomb-levels",
                       "wait": "--wait", "limits.max_speed": "--max-speed",
                       "limits.max_travel": "--max-travel", "limits.max_u_da": "--max-u-da"}


def _experiment_entry(args) -> int:
    if args.hold is None:
        args.hold = 2.0 if args.experiment in ("stribeck", "velocity-scale") else 0.25
    args.amplitude_given = args.amplitude is not None
    finite("--slide", args.slide, 0.0)
    finite("--push", args.push, 0.0)
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
