"""scripts/test's real-time phases collect only the modules that can hold realtime tests
(``--realtime-modules``, tests/conftest.py), and a realtime test anywhere else stops the
full collection instead of never running."""

from __future__ import annotations

import types
from pathlib import Path

import conftest
import pytest

TESTS = Path(__file__).resolve().parent


def test_the_real_time_modules_are_kept_and_the_others_left_out():
    # named in REALTIME_MODULES, marked in the module, a UDP test's module
    for name in ("browser/test_console_browser.py", "test_console.py", "test_scripts.py",
                 "test_firmware_hil.py", "test_readme_commands.py",
                 "test_rig_experiments_udp.py", "test_swingup.py"):
        assert conftest.could_hold_realtime(TESTS / name), name
    for name in ("test_friction.py", "test_batch.py", "test_sensor.py"):
        assert not conftest.could_hold_realtime(TESTS / name), name


class _Item:
    def __init__(self, nodeid: str, realtime: bool):
        self.nodeid, self.name = nodeid, nodeid.split("::")[-1]
        self.path = TESTS.parent / nodeid.split("::")[0]
        self.marks = {"realtime"} if realtime else set()

    def add_marker(self, mark):
        self.marks.add(mark.name)

    def get_closest_marker(self, name):
        return name if name in self.marks else None


def _config(realtime_modules: bool):
    return types.SimpleNamespace(getoption=lambda name: realtime_modules)


def test_a_realtime_test_the_real_time_phases_would_not_collect_is_refused():
    items = [_Item("tests/test_friction.py::test_x", realtime=True)]
    with pytest.raises(pytest.UsageError, match="REALTIME_MODULES"):
        conftest.pytest_collection_modifyitems(_config(False), items)
    # in a module the phases collect it is marked and sorted as usual
    ok = [_Item("tests/test_realtime_cli.py::test_headless_x", realtime=False),
          _Item("tests/test_friction.py::test_y", realtime=False)]
    conftest.pytest_collection_modifyitems(_config(False), ok)
    assert ok[0].get_closest_marker("realtime") and not ok[1].get_closest_marker("realtime")
    assert ok[0].get_closest_marker("alone") is None


def test_the_collection_hook_ignores_only_other_test_modules():
    on, off = _config(True), _config(False)
    assert conftest.pytest_ignore_collect(TESTS / "test_friction.py", on) is True
    assert conftest.pytest_ignore_collect(TESTS / "test_console.py", on) is None
    assert conftest.pytest_ignore_collect(TESTS / "inprocess.py", on) is None
    assert conftest.pytest_ignore_collect(TESTS / "test_friction.py", off) is None
