"""Run ``frictionlab`` in the test process (see tests/conftest.py, fixture ``cli``)."""

from __future__ import annotations

import contextlib
import io
import os
import shlex
import subprocess

#: The serving bound of a command run in-process (``FRICTIONLAB_SERVE_LIMIT``, seconds):
#: a ``rig-sim``, console or headless ``run`` without ``--duration`` that a test expected
#: to be refused ends after this long with exit status 1 instead of holding the test's
#: process (docs/development.md).  ``env`` may set another.
IN_PROCESS_SERVE_LIMIT = "60"


def run_cli_in_process(argv, cwd: str | os.PathLike | None = None,
                       env: dict | None = None) -> subprocess.CompletedProcess:
    """``frictionlab *argv`` in this process, as a :class:`subprocess.CompletedProcess`.

    ``returncode`` is what the command's process would exit with (``main``'s
    return value, or the status of a ``SystemExit``, e.g. argparse's 2 on bad
    usage); ``stdout``/``stderr`` are the text it wrote.  ``cwd`` and ``env``
    (variables to set) apply for the duration of the call; a command that would
    serve until a signal stops after :data:`IN_PROCESS_SERVE_LIMIT` seconds.
    """
    from frictionlab.cli import main

    argv = [str(a) for a in (shlex.split(argv) if isinstance(argv, str) else argv)]
    out, err = io.StringIO(), io.StringIO()
    old_cwd, old_env = os.getcwd(), dict(os.environ)
    try:
        if cwd is not None:
            os.chdir(cwd)
        os.environ["FRICTIONLAB_SERVE_LIMIT"] = IN_PROCESS_SERVE_LIMIT
        if env:
            os.environ.update(env)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(argv)
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None
                                                                    else 1)
                if not isinstance(exc.code, int | None):
                    print(exc.code, file=err)
    finally:
        os.chdir(old_cwd)
        os.environ.clear()
        os.environ.update(old_env)
    return subprocess.CompletedProcess(["frictionlab", *argv], code or 0, out.getvalue(),
                                       err.getvalue())
