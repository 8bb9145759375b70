"""Fixtures and hooks shared by the whole suite (docs/development.md, "Tests").

- ``cli``: run ``frictionlab ARGS...`` in this process (no interpreter start-up,
  no imports paid again), with the exit status, stdout and stderr of the real
  command.  Use a subprocess only where the test is about the process itself
  (signals, the installed executable, start-up time, servers).
- Tests marked ``slow`` are collected first, so that with pytest-xdist
  (``scripts/test`` runs ``-n auto --dist loadgroup``) the long ones start at
  once and the short ones fill the gaps at the end.
"""

from __future__ import annotations

import os

import pytest
from inprocess import run_cli_in_process

os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(scope="session")
def fast_design():
    from frictionlab.model.design import design

    return design("fast")


@pytest.fixture
def cli():
    """``cli(*args, cwd=None, env=None)``: ``frictionlab ARGS`` in-process
    (:func:`inprocess.run_cli_in_process`); ``.returncode``, ``.stdout``, ``.stderr``."""

    def run(*args, cwd=None, env=None):
        return run_cli_in_process(list(args), cwd=cwd, env=env)

    return run


#: Modules whose tests drive a real-time loop in real time against another process
#: (marker ``realtime``: scripts/test runs them one at a time after the rest).
REALTIME_MODULES = ("tests/browser/", "tests/test_realtime_cli.py",
                    "tests/test_rig_experiments_udp.py",
                    "tests/test_console.py::test_connecting_pages_cannot_stall_the_loop")


def pytest_collection_modifyitems(config, items):
    """The modules holding slow tests first.

    A stable sort of whole modules: the order within a module is kept (the
    documents' commands run in order) and a module-scoped fixture is set up
    once in a serial run.
    """
    for item in items:
        if item.nodeid.startswith(REALTIME_MODULES) or "udp" in item.name:
            item.add_marker(pytest.mark.realtime)
    slow = {item.nodeid.split("::")[0] for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: item.nodeid.split("::")[0] not in slow)

