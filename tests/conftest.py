"""Fixtures and hooks shared by the whole suite (docs/development.md, "Tests").

- ``cli``: run ``frictionlab ARGS...`` in this process (no interpreter start-up,
  no imports paid again), with the exit status, stdout and stderr of the real
  command.  Use a subprocess only where the test is about the process itself
  (signals, the installed executable, start-up time, servers).
- Markers set here by node id: ``realtime`` (:data:`REALTIME_MODULES`, UDP tests, not
  :data:`NOT_REALTIME`) and
  ``alone`` (:data:`ALONE`), the phases of ``scripts/test``.
- Tests marked ``slow`` are collected first, so that with pytest-xdist
  (``scripts/test`` runs ``-n auto --dist loadgroup``) the long ones start at
  once and the short ones fill the gaps at the end.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from inprocess import run_cli_in_process

os.environ.setdefault("MPLBACKEND", "Agg")
# the serving bound (docs/development.md): a rig-sim, console or headless run without
# --duration, started by a test in-process or as a process, stops after 30 minutes
# (exit 1, saying so) instead of serving forever; run_cli_in_process: 60 s
os.environ.setdefault("FRICTIONLAB_SERVE_LIMIT", "1800")

ROOT = Path(__file__).resolve().parents[1]


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
#: (marker ``realtime``: scripts/test runs them before the rest, two at a time; tests
#: marked ``realtime`` directly too).
REALTIME_MODULES = ("tests/browser/", "tests/test_realtime_cli.py",
                    "tests/test_rig_experiments_udp.py",
                    "tests/test_console.py::test_connecting_pages_cannot_stall_the_loop",
                    "tests/test_console.py::test_a_first_session_loads_nothing_while_the_loop_runs",
                    "tests/test_console.py::test_idle_connections_cannot_lock_the_operator_out",
                    "tests/test_scripts.py::test_scripts_run_installs_and_serves_the_console")
#: Tests of those modules (or named like UDP tests) that run no real-time loop against
#: another process: the command line's refusals, in-process runs on a fake clock or
#: with the loop replaced, a rig that never answers.  They run with the rest of the
#: suite on every CPU instead of one at a time (a new test of a real-time module is
#: ``realtime`` unless it is named here).
NOT_REALTIME = ("tests/test_realtime_cli.py::"
                "test_the_console_s_signal_handler_stops_the_loop_itself",
                "tests/test_realtime_cli.py::test_bad_input_exits_2_with_a_message",
                "tests/test_realtime_cli.py::test_unreachable_rig_exits_1",
                "tests/test_realtime_cli.py::test_run_without_headless_hands_over_to_the_console",
                "tests/test_realtime_cli.py::test_run_s_signal_handling_before_and_after_the_run",
                "tests/test_realtime_cli.py::test_a_signal_before_the_run_starts_means_no_run",
                "tests/test_realtime_cli.py::test_a_signal_while_the_console_is_being_set_up_ends_run",
                "tests/test_realtime_rigs.py::test_udp_backend_without_a_rig_fails_to_open",
                "tests/test_rig_experiments_udp.py::test_rig_sim_scripted_hand_bad_input")
#: Real-time tests that must have the machine to themselves within the suite (marker
#: ``alone``: scripts/test runs them last, one at a time): a browser beside a console
#: (chromium takes a CPU of its own while it renders), a timing statistic (missed
#: deadlines compared with a quiet period, or at most 1 % of them), and a safety stop
#: whose slack is below half a second (the log's end within 100 ms of a SIGKILL, a
#: pause limit of 0.15 s, the motor at zero two writes after a SIGINT), and the
#: documents' real-time runs as written (the default run's 0.35 rad angle limit over a
#: 0.17 rad cycle: beside another real-time test a stalled host once took it past the
#: limit, after a first try stopped ``paused``).  Two of them,
#: or one beside another real-time test, lost deadlines on a loaded machine
#: (docs/performance.md, "Test suite"); the other realtime tests run two at a time
#: (scripts/test, phase 2).
ALONE = ("tests/browser/",
         "tests/test_console.py::test_connecting_pages_cannot_stall_the_loop",
         "tests/test_firmware_hil.py::"
         "test_the_controller_balances_the_emulated_rig_and_a_stall_zeroes_the_motor",
         "tests/test_qube_acceptance.py::test_sigstop_the_board_watchdog_zeroes_the_motor",
         "tests/test_qube_acceptance.py::"
         "test_sigint_while_balancing_zeroes_the_motor_and_closes_the_board",
         "tests/test_realtime_cli.py::test_sigkill_loses_at_most_the_last_100_ms",
         "tests/test_readme_commands.py::test_documented_real_time_runs_work_as_written")


def pytest_addoption(parser):
    parser.addoption(
        "--realtime-modules", action="store_true",
        help="collect only the test modules that can hold realtime tests (scripts/test's "
             "real-time phases: collecting the whole suite costs about 10 s of CPU)")


def could_hold_realtime(path: Path) -> bool:
    """Whether the test module at ``path`` can hold a ``realtime`` test: it is named in
    :data:`REALTIME_MODULES`, marks tests ``realtime`` itself, or names UDP."""
    rel = path.resolve().relative_to(ROOT).as_posix()
    if rel.startswith(tuple(m.split("::")[0] for m in REALTIME_MODULES)):
        return True
    text = path.read_text()
    return "mark.realtime" in text or "udp" in text.lower()


def pytest_ignore_collect(collection_path, config):
    if (config.getoption("realtime_modules") and collection_path.suffix == ".py"
            and collection_path.name.startswith("test_")
            and not could_hold_realtime(collection_path)):
        return True
    return None


def pytest_collection_modifyitems(config, items):
    """The modules holding slow tests first.

    A stable sort of whole modules: the order within a module is kept (the
    documents' commands run in order) and a module-scoped fixture is set up
    once in a serial run.
    """
    for item in items:
        if ((item.nodeid.startswith(REALTIME_MODULES) or "udp" in item.name)
                and not item.nodeid.startswith(NOT_REALTIME)):
            item.add_marker(pytest.mark.realtime)
        if item.nodeid.startswith(ALONE):
            item.add_marker(pytest.mark.alone)
    if not config.getoption("realtime_modules"):
        # a realtime test in a module the real-time phases do not collect would never run
        lost = sorted({item.nodeid.split("::")[0] for item in items
                       if item.get_closest_marker("realtime")
                       and not could_hold_realtime(Path(item.path))})
        if lost:
            raise pytest.UsageError(f"realtime tests in {lost}: add the module to "
                                    "REALTIME_MODULES (tests/conftest.py)")
    slow = {item.nodeid.split("::")[0] for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: item.nodeid.split("::")[0] not in slow)

