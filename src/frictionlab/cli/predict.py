"""``frictionlab predict``: the friction limit cycle without a long run.

Registration only; python-control and the numerics are imported when the
command runs (:mod:`frictionlab.studies.predict`).
"""

from __future__ import annotations

import sys

__all__ = ["register_cli"]


def cmd_predict(args) -> int:
    from ..studies.predict import predict
    from .common import check_output_path, config_from_args, emit_json, feature_lines

    cfg = config_from_args(args)
    check_output_path(args.plot, (".png", ".pdf", ".svg"), "--plot")
    result = predict(cfg)
    for note in result.notes:
        print(f"frictionlab predict: note: {note}", file=sys.stderr)
    out = result.interface_dict()
    if args.plot:
        from ..studies.predict import plot_prediction

        plot_prediction(cfg, result, args.plot)  # prints the path on stderr
        out["plot"] = args.plot
    if args.json:
        emit_json(out)
        return 0
    po, df = result.periodic_orbit, result.describing_function
    print("periodic orbit: " + ("found" if po.found else "not found")
          + ("" if po.stable is None else (", stable" if po.stable else ", UNSTABLE"))
          + (f" ({po.message})" if po.message else ""))
    if po.found:
        for line in feature_lines(po.features.interface_dict(), cfg.plant_model.u_unit):
            print(line)
        mods = ", ".join(f"{abs(m):.3g}" for m in po.floquet_multipliers[:3])
        print(f"  |Floquet multipliers| {mods}{' ...' if len(po.floquet_multipliers) > 3 else ''}")
    print(f"describing function ({df.nonlinearity or '-'}):")
    if df.amplitude is None:
        print(f"  no stable cycle predicted ({df.message})")
    else:
        print(f"  arm-velocity amplitude {df.amplitude:.4g} rad/s, period {df.period:.4g} s, "
              f"pendulum amplitude {df.pendulum_amplitude:.4g} rad")
    return 0


def register_cli(sub) -> None:
    """Add ``predict`` to the ``frictionlab`` subcommands."""
    from .common import add_config_args

    p = sub.add_parser(
        "predict",
        help="predict the friction limit cycle: exact periodic orbit and describing function",
        description="Predict the loop's friction limit cycle two ways: the exact periodic "
                    "orbit (a fixed point of the sampled loop's period map, with its features "
                    "and Floquet multipliers) and the describing function of the friction "
                    "against the linearised loop (docs/predict.md).")
    add_config_args(p)
    p.add_argument("--plot", metavar="FILE",
                   help="draw the Nyquist curve with -1/N(A) and the orbit to FILE.png")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_predict)
