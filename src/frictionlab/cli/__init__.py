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
from collections.abc import Sequence

from ..config import UnknownKeyError
from . import (
    compensate,
    design,
    features,
    identify,
    keys,
    predict,
    reproduce,
    run,
    simulate,
    sweep,
)
from .common import Parser, UsageError, error_message, flush_notes
from .simulate import simulate_result

__all__ = ["UsageError", "build_parser", "main", "simulate_result"]


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
    """Every subcommand, one module each (``cli/<name>.py``, ``register_cli``)."""
    for mod in (design, simulate, keys, sweep, features, identify, compensate, run, reproduce,
                predict):
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
