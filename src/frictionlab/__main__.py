"""The ``frictionlab`` executable and ``python -m frictionlab``.

For ``frictionlab run`` the stop signals are caught first
(:func:`frictionlab.startsignals.install`), before the command line, numpy and
the compiled kernels are imported: a signal at any moment of the start-up ends
the run before the motor moves, whatever disposition the process inherited.
"""

import sys


def main() -> int:
    """Run ``frictionlab`` with ``sys.argv``; its exit status."""
    argv = sys.argv[1:]
    interrupted: tuple = ()  # catches nothing
    if argv[:1] == ["run"]:
        # start-up: the stop handler before anything slow is imported (docs/realtime.md)
        from . import startsignals

        interrupted = (startsignals.Interrupted,)
    try:
        if interrupted:
            # inside the try: a signal between two of its handlers' installs raises too
            startsignals.install()
        # start-up: the command line (and what it imports) after the stop handler
        from .cli import main as cli_main

        return cli_main(argv)
    except interrupted as exc:
        # a stop signal while the command line loaded or parsed its arguments: the
        # run had not started (no rig opened, nothing logged, no command written)
        import json

        st = startsignals.not_started(exc.name)
        if "--json" in argv:
            print(json.dumps(startsignals.interface_stats(st)), flush=True)
        print(f"frictionlab run: stopped: signal ({st['stop_detail']})", file=sys.stderr)
        return 0


if __name__ == "__main__":
    sys.exit(main())
