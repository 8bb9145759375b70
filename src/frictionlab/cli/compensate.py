"""``frictionlab compensate tune|compare``: friction compensation on the command line (Sec. 6).

``tune`` searches compensator parameters (:func:`frictionlab.studies.compensation.tune`,
through the sweep engine); ``compare`` runs one configuration with and
without its compensator (:func:`frictionlab.studies.compensation.compare`).  This
module parses the command line, prints the results and draws the
before/after figure (cf. the thesis's Figs. 25-30).
"""

from __future__ import annotations

import sys
import time

from ..config import COMPENSATOR_KINDS, SimParams
from .common import (
    UsageError,
    add_config_args,
    add_engine_args,
    check_engine_args,
    check_output_path,
    check_window,
    config_from_args,
    emit_json,
    finite,
    flush_notes,
    progress_bar,
)

__all__ = ["plot_before_after", "register_cli"]


def plot_before_after(traj_off, traj_on, path: str, window: float | None = None,
                      title: str | None = None, dpi: int = 100, what: str = "compensate") -> str:
    """Limit cycle without (left) and with (right) compensation.

    Rows: measured pendulum angle, measured arm velocity, control signal,
    friction (the plant's true friction dotted, the compensator's estimate
    dashed), over the last ``window`` seconds of each run (default: the last
    half, at most 10 s).  Both columns share the y axes, so the reduction is
    visible at a glance.  The title (default
    :func:`frictionlab.plotting.config_title` of the compensated run, headed
    ``what``) names the design, the friction, the compensator and their
    parameters; the path is printed on stderr.
    """
    import matplotlib.pyplot as plt
    import numpy as np

    from ..plotting import TRACES, axis_label, config_title, save_figure

    fig, axes = plt.subplots(4, 2, figsize=(11, 9), sharex="col", sharey="row")
    for col, (traj, name) in enumerate(((traj_off, "without compensation"),
                                        (traj_on, "with compensation"))):
        t = traj.t
        if len(t) == 0:
            raise ValueError(f"empty trajectory ({name}): nothing to plot")
        span = min(window if window is not None else 0.5 * t[-1], 10.0, t[-1])
        m = t >= t[-1] - span
        tt = t[m] - t[m][0]
        ax = axes[0, col]
        ax.plot(tt, traj["theta_m"][m], label=r"measured $\theta$", **TRACES["measured"])
        ptp = np.ptp(traj["theta_m"][m])
        ax.set_title(f"{name}  (raw peak-to-peak {ptp:.3f} rad)", fontsize=9)
        axes[1, col].plot(tt, traj["arm_dot_m"][m], label=r"measured $\dot\Omega$",
                          **TRACES["measured"])
        axes[2, col].plot(tt, traj["u"][m], label="control $u$", **TRACES["control"])
        ax = axes[3, col]
        ax.plot(tt, traj["friction"][m], label="friction (plant, true)", **TRACES["true"])
        if np.any(traj["friction_hat"][m] != 0):
            ax.plot(tt, traj["friction_hat"][m], label="estimate (compensator)",
                    **TRACES["estimated"])
        ax.legend(loc="upper right", fontsize=7)
        ax.set_xlabel(axis_label("time in the window", "s"))
    axes[0, 0].set_ylabel(axis_label(r"$\theta_m$", "rad"))
    axes[1, 0].set_ylabel(axis_label(r"$\dot\Omega_m$", "rad/s"))
    axes[2, 0].set_ylabel(axis_label("$u$", "m/s^2"))
    axes[3, 0].set_ylabel(axis_label("friction", "m/s^2"))
    for a in axes.flat:
        a.grid(alpha=0.3)
    if title is None and traj_on.config is not None:
        c = traj_on.config
        title = config_title(c, what, width=150) + f"\nh = {c.design.h:g} s"
    if title:
        fig.suptitle(title, fontsize=9)
    return save_figure(fig, path, dpi=dpi)


def register_cli(sub) -> None:
    """Add ``frictionlab compensate`` (``tune``, ``compare``) to the CLI."""
    p = sub.add_parser("compensate",
                       help="friction compensation: tune, or compare with/without (Sec. 6)")
    csub = p.add_subparsers(dest="compensate_command", metavar="ACTION")
    csub.required = True
    c = csub.add_parser(
        "compare", help="one configuration with and without its compensator",
        description="Simulate the configuration with its compensator and with "
                    "compensation none; report both runs' limit-cycle features and chatter "
                    "(sign reversals per second of the friction estimate, u roughness) and "
                    "the reduction of the peak-to-peak.")
    add_config_args(c)
    c.set_defaults(compensation="lugre")
    c.add_argument("--duration", type=float, default=30.0,
                   help="simulated time in s (default 30)")
    c.add_argument("--window", type=float, default=None,
                   help="analyse the last S seconds (default: the last half)")
    c.add_argument("--plot", metavar="FILE.png", help="before/after figure (cf. Figs. 25-30)")
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(func=cmd_compare)
    t = csub.add_parser(
        "tune", help="search compensator parameters minimising the limit cycle",
        description="Run a grid of compensation.* values, and the loop without compensation, "
                    "through the sweep engine, each run reduced to the peak-to-peak of the "
                    "measured pendulum angle and its control chatter (sign reversals per "
                    "second of the friction estimate); report the best score peak_to_peak * "
                    "(1 + W * reversals/s), with the reduction against no compensation.")
    add_config_args(t)
    t.set_defaults(compensation="lugre")
    t.add_argument("--vary", action="append", default=[], metavar="KEY=V1,V2,...",
                   help="values of a compensation.* key (list or START:STOP:N); repeatable; "
                        "default: a grid per compensator around the thesis's settings")
    t.add_argument("--duration", type=float, default=30.0,
                   help="simulated time per run in s (default 30)")
    t.add_argument("--window", type=float, default=None,
                   help="analyse the last S seconds of each run (default: the last half)")
    t.add_argument("--chatter-weight", type=float, default=0.05, metavar="W",
                   help="penalty weight in s (default 0.05: 20 reversals/s double the score)")
    add_engine_args(t)
    t.add_argument("--plot", metavar="FILE.png",
                   help="before/after figure of the best setting (cf. Figs. 25-30)")
    t.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    t.add_argument("--json", action="store_true", help="print one JSON object")
    t.set_defaults(func=cmd_tune)


def _compensated_config(args):
    """The configuration of ``compensate compare``/``tune``, checked: it has a
    compensator, and the run's length, window and figure path are usable."""
    cfg = config_from_args(args)
    if cfg.compensation_kind == "none":
        kinds = [k for k in COMPENSATOR_KINDS if k != "none"]
        raise UsageError(f"--compensation must be {', '.join(kinds[:-1])} or {kinds[-1]}")
    _check_run_args(args)
    return cfg


def _check_run_args(args):
    hi = SimParams.__dataclass_fields__["duration"].metadata["hi"]
    finite("--duration", args.duration, 0.0, hi=hi)
    check_window(args.window, args.duration)
    check_output_path(args.plot, (".png", ".pdf", ".svg"), "--plot")


def cmd_compare(args) -> int:
    """``frictionlab compensate compare``."""
    from ..studies.compensation import compare

    cfg = _compensated_config(args)
    flush_notes(args)
    res, traj_on, traj_off = compare(cfg, args.duration, args.window,
                                     return_trajectories=True)
    out = {"compensation": cfg.compensation_kind, "design": args.design,
           "friction": cfg.friction_kind, **res.as_dict()}
    if args.plot:
        plot_before_after(traj_off, traj_on, args.plot, args.window,
                          what="compensate compare")
        out["plot"] = args.plot
    if args.json:
        emit_json(out)
    else:
        for name, st, f, ch in (("without", res.baseline_status, res.baseline_features,
                                 res.baseline_chatter),
                                ("with", res.status, res.features, res.chatter)):
            print(f"{name:7s} compensation: {st:11s} peak-to-peak {_fmt(f['peak_to_peak'])} "
                  f"rad, period {_fmt(f['period'])} s, {ch.reversals_per_s:.2f} "
                  f"reversals/s, u roughness {ch.u_roughness:.3g}")
        red = res.reduction
        print(f"reduction: {'-' if red is None else f'{red:.2f}x'}")
    return 0


def cmd_tune(args) -> int:
    """``frictionlab compensate tune``."""
    from ..studies.compensation import check_grid, default_grid, tune
    from ..studies.sweep import parse_vary

    t0 = time.perf_counter()
    cfg = _compensated_config(args)
    finite("--chatter-weight", args.chatter_weight, 0.0, lo_open=False)
    check_engine_args(args)
    grid = [parse_vary(v, args.plant) for v in args.vary] or default_grid(cfg)
    n = len(check_grid(cfg, grid))  # every point validated before anything runs
    flush_notes(args)
    print(f"frictionlab compensate tune: {cfg.compensation_kind} compensator, {n} points, "
          f"{args.design} design, {cfg.friction_kind} plant friction", file=sys.stderr)
    with progress_bar(f"tune {n} points", not args.no_progress) as upd:
        res = tune(cfg, grid, duration=args.duration, window=args.window,
                   chatter_weight=args.chatter_weight, workers=args.workers, dask=args.dask,
                   progress=lambda done, total: upd(done / total),
                   return_trajectories=bool(args.plot))
    if args.plot:
        res, traj_on, traj_off = res
        plot_before_after(traj_off, traj_on, args.plot, args.window,
                          what="compensate tune, best setting")
    out = {"compensation": cfg.compensation_kind, "design": args.design,
           "friction": cfg.friction_kind, **res.as_dict(),
           "seconds": round(time.perf_counter() - t0, 3)}
    if args.plot:
        out["plot"] = args.plot
    if args.json:
        emit_json(out)
    else:
        print(f"best {cfg.compensation_kind} settings ({args.design} design, "
              f"{cfg.friction_kind} plant):")
        for k, v in res.best.items():
            print(f"  {k:34s} {v:g}")
        red = res.reduction
        print(f"peak-to-peak {res.peak_to_peak:.4g} rad (without compensation "
              f"{_fmt(res.baseline_peak_to_peak)}): reduction "
              f"{'-' if red is None else f'{red:.2f}x'}")
        print(f"chatter: {res.chatter.reversals_per_s:.2f} reversals/s of the estimate, "
              f"u roughness {res.chatter.u_roughness:.3g} m/s^2 per sample")
        print(f"{res.evaluated} points, {res.failed} fell or failed; "
              f"{out['seconds']:.1f} s" + (f"; plot {args.plot}" if args.plot else ""))
    return 0


def _fmt(v) -> str:
    return "-" if v is None else f"{v:.4g}"
