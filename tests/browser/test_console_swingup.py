"""The console's Swing up button in a real browser: the pendulum starts hanging.

``frictionlab run`` on the sim backend with ``sim.initial_angle`` = pi: the
automatic start refuses the hanging pendulum (``not_upright``), Swing up swings
it up, and the status line shows the phases.
"""

from __future__ import annotations

import pytest
from playwright.sync_api import expect

from .conftest import ConsoleProcess, LoopStopped, retry_host_stalls, wait_until

pytestmark = [pytest.mark.timeout(180), pytest.mark.slow]


@pytest.fixture(scope="module")
def console(tmp_path_factory):
    proc = ConsoleProcess(tmp_path_factory.mktemp("swingup-runs"),
                          "--set", "sim.initial_angle=3.141592653589793",
                          "--sim-lockstep")  # a host stall pauses the simulated plant too
    try:
        proc.wait_url()
        yield proc
    finally:
        proc.stop()


def test_swing_up_button_and_phase(browser, console):
    page = browser.new_page()
    try:
        page.goto(console.url)
        expect(page.locator("#conn")).to_have_text("live", timeout=30_000)
        # the automatic start refused the hanging pendulum (no swing-up asked)
        expect(page.locator("#run-state")).to_have_text("stopped: not_upright",
                                                        timeout=60_000)
        phase = page.locator("#swing-phase")
        expect(page.locator("#swingup")).to_be_enabled()
        page.locator("#swingup").click()
        seen = set()

        def balancing():
            st = console.get("/api/status")[1]
            if st.get("swing_up") is None:
                # the page's request has not started the swing-up run yet: this is still
                # the status of the refused automatic start (stop_reason not_upright)
                return False
            sw = st["swing_up"]
            seen.add(sw.get("phase"))
            if not st.get("running") and st.get("stop_reason"):
                # only a host stall on this shared machine is run again (retry_host_stalls)
                raise LoopStopped(st["stop_reason"], st.get("stop_detail"))
            return sw.get("phase") == "balancing"

        def again():
            code, body = console.post("/api/swingup", {})
            assert code == 200, (code, body)

        retry_host_stalls(lambda: wait_until(balancing, 90.0, what="the swing-up balancing"),
                          again, "the swing-up")
        assert "swinging" in seen or "caught" in seen
        expect(phase).to_have_attribute("data-phase", "balancing", timeout=10_000)
        expect(phase).to_contain_text("caught at")
        expect(page.locator("#swingup")).to_be_disabled()
        page.locator("#start").click()  # Stop
        expect(page.locator("#run-state")).to_have_text("stopped: user", timeout=10_000)
    finally:
        page.close()
