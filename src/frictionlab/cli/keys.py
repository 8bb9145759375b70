"""``frictionlab keys``: every parameter key with its default, range, unit and meaning."""

from __future__ import annotations

from ..config import COMPENSATOR_KINDS, PLANT_FRICTION_KINDS, build_config
from .common import add_plant_arg, emit_json

__all__ = ["cmd_keys", "register_cli"]


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


def register_cli(sub) -> None:
    """Add ``keys`` to the ``frictionlab`` subcommands."""
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
