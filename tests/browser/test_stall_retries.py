"""The browser tests' retry policy (``conftest.retry_host_stalls``): only the loop's
host-stall stops are run again, at most twice, each with a warning; any other stop, the
safety stop a test checks included, fails at once.  No browser: plain functions."""

from __future__ import annotations

import pytest

from .conftest import (
    HOST_STALL_STOPS,
    MAX_STALL_RETRIES,
    HostStallWarning,
    LoopStopped,
    check_running,
    retry_host_stalls,
)


def trial_stopping(reasons):
    """A trial that stops with each of ``reasons`` in turn, then returns "done"."""
    left = list(reasons)
    calls = []

    def trial():
        calls.append(1)
        if left:
            raise LoopStopped(left.pop(0), "injected")
        return "done"

    return trial, calls


@pytest.mark.parametrize("reason", HOST_STALL_STOPS)
def test_a_host_stall_is_run_again_with_a_warning(reason):
    trial, calls = trial_stopping([reason])
    restarts = []
    with pytest.warns(HostStallWarning, match=f"the trial: a stalled host stopped the loop "
                                              f"\\({reason}"):
        assert retry_host_stalls(trial, lambda: restarts.append(1), "the trial") == "done"
    assert len(calls) == 2 and len(restarts) == 1


def test_host_stalls_are_retried_at_most_twice():
    trial, calls = trial_stopping(["paused"] * (MAX_STALL_RETRIES + 1))
    with pytest.warns(HostStallWarning), pytest.raises(LoopStopped) as info:
        retry_host_stalls(trial, lambda: None, "the trial")
    assert info.value.reason == "paused" and len(calls) == MAX_STALL_RETRIES + 1


@pytest.mark.parametrize("reason", ["angle_limit", "bad_reading", "nonfinite_u", "user",
                                    "exception", None])
def test_any_other_stop_fails_at_once(reason, recwarn):
    trial, calls = trial_stopping([reason])
    with pytest.raises(LoopStopped) as info:
        retry_host_stalls(trial, lambda: pytest.fail("restarted"), "the trial")
    assert info.value.reason == reason and len(calls) == 1
    assert not [w for w in recwarn if issubclass(w.category, HostStallWarning)]


def test_a_stopped_loop_is_reported_with_its_reason():
    st = {"running": True, "t": 1.0}
    assert check_running(st) is st
    with pytest.raises(LoopStopped, match="the loop stopped: angle_limit") as info:
        check_running({"running": False, "stop_reason": "angle_limit",
                       "stop_detail": "|theta| = 0.4 rad"})
    assert info.value.reason == "angle_limit"
