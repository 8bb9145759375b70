"""``frictionlab features``: the limit-cycle features of a run log, as an experiment
of ``identify limit-cycle --measured``, with the plant the run controlled.

The plant (``thesis``, ``furuta-dc``, ``qube2``, ``qube3``) and the unit of u
(``m/s^2``, or ``V`` on a motor plant: ``max_u`` is in it) come from the run's
sidecar; ``--plant`` names them for a log without one.  ``identify limit-cycle``
reads the plant back from such a file, so a QUBE log is fitted on the QUBE's
model without ``--plant`` (docs/identification.md).
"""

from __future__ import annotations

import os
import sys

from ..config import PLANT_NAMES, plant_model
from ..model.params import ParamError
from .common import (
    UsageError,
    check_window,
    emit_json,
    feature_lines,
    finite,
    parse_number,
    parse_sets,
)

__all__ = ["design_h", "log_experiment", "register_cli"]


def design_h(sets) -> float | None:
    """The last ``design.h`` of ``--set`` items (the period of a ``.dat`` without
    its sidecar), else None."""
    for key, value in reversed(parse_sets(sets)):
        if key == "design.h":
            return parse_number(value, "--set design.h")
    return None


#: How each command gives what a run log may lack (a ParamError's ``field``).
_LOG_HINTS = {
    "features:": {"design": "--design fast|slow", "h": "--set design.h=SECONDS"},
    "--measured": {"design": "measure its features with 'frictionlab features --design "
                             "fast|slow'", "h": "--set design.h=SECONDS"},
}


def log_experiment(path: str, h: float | None, window: float | None = None,
                   design: str | None = None, what: str = "--measured",
                   plant: str | None = None) -> dict:
    """The features of the run log ``path``
    (:func:`frictionlab.io.runlog.run_log_features`) with its plant checked.

    ``plant`` names the plant of a log whose sidecar does not (a log without
    one); a sidecar that names another plant, or a plant no command knows, is
    refused.  ``u_unit`` is filled in from the plant when the sidecar lacks it.
    ``what`` (``"--measured"`` or ``"features:"``) is how a refusal names the
    file's option.
    """
    from ..io.runlog import run_log_features

    # `frictionlab features: error: ...` names the command already; --measured is an option
    label = "" if what == "features:" else f"{what} "
    if not os.path.isfile(path):  # the missing file, before any sidecar or design
        raise UsageError(f"{label}{path}: no such file")
    try:
        out = run_log_features(path, window=window, h=h, design=design)
    except ParamError as exc:
        hint = _LOG_HINTS[what].get(exc.field)
        raise UsageError(f"{label}{exc}" + (f" ({hint})" if hint else "")) from None
    except ValueError as exc:
        text = str(exc)
        raise UsageError(f"{label}{text if text.startswith(path) else f'{path}: {text}'}"
                         ) from None
    recorded = out["plant"]
    if recorded is not None and recorded not in PLANT_NAMES:
        raise UsageError(f"{label}{path}: the sidecar names the plant {recorded[:40]!r}; "
                         f"known plants: {', '.join(PLANT_NAMES)}")
    if plant is not None and recorded is not None and plant != recorded:
        raise UsageError(f"{label}{path}: the run's sidecar says the {recorded} plant, not "
                         f"--plant {plant}; drop --plant")
    out["plant"] = recorded or plant
    if out["plant"] is not None and out["u_unit"] is None:
        out["u_unit"] = plant_model(out["plant"]).u_unit
    return out


def cmd_features(args) -> int:
    if args.window is not None:
        finite("--window", args.window, 0.0)
    h = design_h(args.sets)
    for key, _ in parse_sets(args.sets):
        if key != "design.h":
            raise UsageError(f"--set {key}: features takes only design.h (the period of a "
                             ".dat without its sidecar)")
    out = log_experiment(args.log, h, args.window, args.design, what="features:",
                         plant=args.plant)
    if args.window is not None and out["window"] < args.window:  # the log is shorter
        check_window(args.window, out["window"], f"the log {args.log} holds")
    if args.json:
        emit_json(out)
        return 0
    for note in out["notes"]:
        print(f"frictionlab features: note: {note}", file=sys.stderr)
    plant = (f"{out['plant']} plant, u in {out['u_unit']}" if out["plant"] is not None
             else "plant not recorded (no sidecar names it; --plant)")
    print(f"{out['name']}: {out['design']} design, {out['status']} "
          f"(last {out['window']:.3g} s); {plant}")
    for line in feature_lines(out["features"], out["u_unit"]):
        print(line)
    return 0


def register_cli(sub) -> None:
    """Add ``frictionlab features`` to the parser."""
    p = sub.add_parser(
        "features", help="limit-cycle features of a run log (for identify limit-cycle)",
        description="The limit-cycle features 'frictionlab simulate' reports, measured on a "
                    "'frictionlab run' log (its .csv, or its .dat), with the design, the "
                    "plant and u's unit from the run's sidecar: one experiment as "
                    "'identify limit-cycle --measured' takes it (docs/identification.md).")
    p.add_argument("log", metavar="LOG", help="the run's .csv or .dat")
    p.add_argument("--window", type=float, default=None, metavar="S",
                   help="analyse the last S seconds (default: the last half of the log)")
    p.add_argument("--design", choices=("fast", "slow"), default=None,
                   help="the run's design preset (default: the sidecar's; required for a "
                        "log without a sidecar)")
    p.add_argument("--plant", choices=PLANT_NAMES, default=None,
                   help="the plant the run controlled, for a log without a sidecar (default: "
                        "the sidecar's; one that names another plant is refused)")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                   help="design.h=SECONDS: the sampling period of a .dat without a sidecar")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_features)
