"""``frictionlab design``: the state-feedback and observer gains of a design (Sec. 2.2-2.4,
App. C-D), with the plant's linearisation."""

from __future__ import annotations

from .common import add_config_args, config_from_args, emit_json

__all__ = ["cmd_design", "register_cli"]


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


def register_cli(sub) -> None:
    """Add ``design`` to the ``frictionlab`` subcommands."""
    p = sub.add_parser("design", help="state-feedback and observer gains (Sec. 2.2-2.4)")
    add_config_args(p, friction=False)
    p.add_argument("--method", choices=("closed_form", "numeric"), default="closed_form",
                   help="Appendix C closed form or numerical pole placement "
                        "(default: %(default)s)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_design)
