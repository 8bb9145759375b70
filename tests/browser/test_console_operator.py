"""The console as an operator meets it, in a real browser: one default console (``frictionlab
run``, sim backend, its pendulum upright and balanced at start), one page, in file order.

The address answers when printed; the traces and toggles are told apart; the Adaptive
panel's fields fit; Swing up from a stopped console starts hanging; the status line says
what the pendulum does (never a limit cycle of a hanging pendulum); an experiment in the
operator's words with progress from its start and results with units; Save Data's
recording analyses with no options.  Screenshots are written to the test's folder
(``FRICTIONLAB_SCREENSHOTS`` names another).
"""

from __future__ import annotations

import json
import os
import re
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from inprocess import run_cli_in_process
from playwright.sync_api import expect

from frictionlab.io.logs import read_log

from .conftest import ConsoleProcess, wait_until

pytestmark = [pytest.mark.timeout(300), pytest.mark.slow,
              pytest.mark.xdist_group("browser-operator")]


@pytest.fixture(scope="module")
def console(tmp_path_factory):
    # lockstep: a stall of this shared host pauses the simulated plant with the loop; the
    # safety stops themselves are tested with fake clocks and injected faults
    proc = ConsoleProcess(tmp_path_factory.mktemp("operator-runs"), "--sim-lockstep",
                          "--max-pause", "0.5", "--silent-periods", "100")
    try:
        proc.wait_url()
        yield proc
    finally:
        proc.stop()


@pytest.fixture(scope="module")
def shots(tmp_path_factory) -> Path:
    folder = os.environ.get("FRICTIONLAB_SCREENSHOTS")
    out = Path(folder) if folder else tmp_path_factory.mktemp("screenshots")
    out.mkdir(parents=True, exist_ok=True)
    return out


@pytest.fixture(scope="module")
def page(browser, console):
    ctx = browser.new_context(viewport={"width": 1400, "height": 1100})
    pg = ctx.new_page()
    errors: list[str] = []
    pg.on("pageerror", lambda exc: errors.append(str(exc)))
    pg.goto(console.url)
    expect(pg.locator("#conn")).to_have_text("live", timeout=30_000)
    pg.errors = errors
    yield pg
    assert errors == []
    ctx.close()


def status(page) -> dict:
    return page.evaluate("() => window.__console.status")


def test_the_printed_address_answers_at_once(console):
    """The first request at the address, made as soon as it is printed, is answered (no
    retry): the server printed it once it was serving, the loop already started."""
    with urllib.request.urlopen(console.base + "/api/status", timeout=10) as resp:
        st = json.loads(resp.read())
    assert resp.status == 200 and st["running"]


def test_every_trace_and_toggle_is_told_apart(page, shots):
    # every toggle's drawn line and the plot's series, read in one evaluation; all on
    styles = page.evaluate("""() => Object.fromEntries(
        [...document.querySelectorAll('#signal-toggles button')].map((b) => {
          if (b.getAttribute('aria-pressed') === 'false') b.click();
          const line = b.querySelector('.swatch line');
          const key = b.dataset.signal, plot = window.__console.style(key);
          return [key, {stroke: line.getAttribute('stroke'),
                        dash: line.getAttribute('stroke-dasharray'),
                        color: plot.color, plotDash: plot.dash ? plot.dash.join(' ') : null}];
        }))""")
    pairs = {(v["stroke"], v["dash"]) for v in styles.values()}
    assert len(pairs) == len(styles) == 9, styles  # colour and dash: no two alike
    # the pairs the issue named: the angle and rate estimates, F-hat and u
    assert styles["theta_hat"]["stroke"] != styles["theta_dot_hat"]["stroke"]
    assert styles["theta_hat"]["dash"] != styles["theta_dot_hat"]["dash"]
    assert styles["friction_hat"]["stroke"] != styles["u"]["stroke"]
    assert styles["u"]["dash"] is None and styles["friction_hat"]["dash"]
    for key, v in styles.items():  # the plot draws what the toggles show
        assert (v["color"], v["plotDash"]) == (v["stroke"], v["dash"]), key
    expect(page.locator('#signal-toggles button[aria-pressed="false"]')).to_have_count(0)
    page.wait_for_timeout(1000)  # a second of plot with every trace (for the eye)
    page.locator("#plot-panel").screenshot(path=str(shots / "1-traces.png"))


def test_balancing_shows_the_limit_cycle_figures(page):
    expect(page.locator("#limit-cycle")).to_have_attribute("data-pendulum", "balancing",
                                                           timeout=30_000)
    expect(page.locator("#lc-figures")).to_be_visible()
    expect(page.locator("#lc-ptp")).not_to_have_text("-")


def test_the_adaptive_panel_fields_fit(page, shots):
    page.locator("#friction-type").select_option("adaptive")
    expect(page.locator('#friction-fields input[data-field="adaptation_max_innovation"]')
           ).to_be_visible()
    # every row's label ends before its input, every input inside the panel
    rows = page.evaluate("""() => {
        const panel = document.querySelector('#friction-panel').getBoundingClientRect();
        return [...document.querySelectorAll('#friction-fields .field')]
          .filter((r) => !r.hidden && r.querySelector('input')).map((r) => {
            const l = r.querySelector('label').getBoundingClientRect();
            const i = r.querySelector('input').getBoundingClientRect();
            return {field: r.querySelector('input').dataset.field, labelEnd: l.right,
                    inputStart: i.left, inputEnd: i.right, panelStart: panel.left,
                    panelEnd: panel.right};
          });
    }""")
    assert len(rows) >= 10 and "adaptation_max_innovation" in [r["field"] for r in rows]
    for r in rows:
        assert r["labelEnd"] <= r["inputStart"] + 0.5, r
        assert r["panelStart"] <= r["inputStart"] and r["inputEnd"] <= r["panelEnd"] + 0.5, r
    page.locator("#friction-panel").screenshot(path=str(shots / "2-adaptive-panel.png"))
    page.locator("#friction-type").select_option("lugre")


def test_swing_up_from_a_stopped_console_starts_hanging(console, page, shots):
    expect(page.locator("#start")).to_have_text("Stop")
    page.locator("#start").click()
    expect(page.locator("#run-state")).to_have_text("stopped: user", timeout=10_000)
    page.locator("#swingup").click()
    seen = set()

    def balancing():
        st = console.get("/api/status")[1]
        sw = st.get("swing_up")
        if sw is None:
            return False
        lc = st["console"]["limit_cycle"]
        seen.add((sw["phase"], lc.get("pendulum")))
        # while swinging up, never a limit cycle
        assert lc.get("pendulum") == "balancing" or lc["status"] != "limit_cycle", lc
        if not st["running"]:
            raise AssertionError(f"stopped: {st['stop_reason']} {st.get('stop_detail')}")
        return st if sw["phase"] == "balancing" and st["t"] > sw["swing_up_time"] + 1 else None

    st = wait_until(balancing, 120.0, what="the swing-up balancing")
    assert st["swing_up"]["swing_up_time"] >= 0.3
    log = read_log(st["log"], st["h"])
    assert abs(log["theta_m"][0]) > 2.5  # the run starts with the pendulum hanging
    expect(page.locator("#swing-phase")).to_have_attribute("data-phase", "balancing",
                                                           timeout=10_000)
    page.locator("#statusbar").screenshot(path=str(shots / "3-swung-up.png"))


def test_a_saved_recording_analyses_with_no_options(console, page):
    # balancing after the swing-up: record 3 s
    page.locator("#save").click()
    expect(page.locator("#save")).to_have_attribute("aria-pressed", "true", timeout=10_000)
    t0 = status(page)["t"]
    wait_until(lambda: status(page)["t"] > t0 + 3, 90.0, what="3 s recorded")
    page.locator("#save").click()
    expect(page.locator("#save-prompt")).to_be_visible(timeout=10_000)
    page.locator("#save-name").fill("trial1")
    page.locator("#save-write").click()
    expect(page.locator("#save-links")).to_contain_text("trial1.dat", timeout=10_000)
    folder = console.log_dir
    assert (folder / "trial1.json").is_file()
    res = run_cli_in_process(["features", "trial1.dat", "--json"], cwd=folder)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert out["design"] == "fast" and np.isfinite(out["features"]["max_u"])
    missing = run_cli_in_process(["features", "nope.csv"], cwd=folder)
    assert missing.returncode == 2
    assert missing.stderr.strip() == "frictionlab features: error: nope.csv: no such file"


def test_an_experiment_in_the_operator_s_words(console, page, shots):
    page.locator("#start").click()  # Stop
    expect(page.locator("#run-state")).to_contain_text("stopped", timeout=10_000)
    page.locator("#experiment-name").select_option("free-oscillation")
    page.locator("#experiment-options").fill('{"duration": 4}')
    # the panel's fields fit: the experiment's name and the options' text shown whole
    fit = page.evaluate("""() => {
        const panel = document.querySelector('#experiment-panel').getBoundingClientRect();
        const sel = document.querySelector('#experiment-name');
        const opt = document.querySelector('#experiment-options');
        const canvas = document.createElement('canvas').getContext('2d');
        canvas.font = getComputedStyle(sel).font;
        const name = canvas.measureText(sel.options[sel.selectedIndex].text).width;
        return {panelEnd: panel.right, selEnd: sel.getBoundingClientRect().right,
                selWidth: sel.clientWidth, nameWidth: name,
                optEnd: opt.getBoundingClientRect().right,
                optScroll: opt.scrollWidth, optClient: opt.clientWidth};
    }""")
    assert fit["selEnd"] <= fit["panelEnd"] and fit["optEnd"] <= fit["panelEnd"], fit
    assert fit["nameWidth"] + 20 <= fit["selWidth"], fit  # the name and the arrow
    assert fit["optScroll"] <= fit["optClient"], fit
    page.locator("#experiment-run").click()
    dialog = page.locator("#confirm")
    expect(dialog).to_be_visible()
    text = page.locator("#confirm-text").inner_text()
    assert "arm will move" in text and "Stop sets the motor to zero" in text
    assert "confirm" not in text.lower() and "request" not in text.lower()
    page.locator("#confirm").screenshot(path=str(shots / "4-experiment-dialog.png"))
    page.locator("#confirm-apply").click()
    # progress from the start: the phase and the seconds it has run
    expect(page.locator("#experiment-msg")).to_contain_text(
        re.compile(r"free-oscillation running \(\d+ % done, \d+ s\): \w"), timeout=30_000)
    expect(page.locator("#experiment-progress")).to_be_visible()
    # the pendulum hangs: never a limit cycle, no figures
    expect(page.locator("#limit-cycle")).not_to_have_attribute("data-pendulum", "balancing")
    expect(page.locator("#lc-figures")).to_be_hidden()
    page.locator("#experiment-panel").screenshot(path=str(shots / "5-experiment-running.png"))
    expect(page.locator("#experiment-msg")).to_contain_text("free-oscillation: done",
                                                            timeout=120_000)
    expect(page.locator("#experiment-result")).to_contain_text(
        re.compile(r"omega0 = [\d.]+ rad/s"))
    # after it: the pendulum hangs and the status says so
    expect(page.locator("#limit-cycle")).to_have_attribute("data-pendulum", "hanging",
                                                           timeout=10_000)
    expect(page.locator("#lc-status")).to_contain_text("pendulum hanging")
    assert status(page)["console"]["limit_cycle"]["peak_to_peak"] is None
    # the result (the log's long path included) wraps inside the panel
    assert page.evaluate("""() => { const r = document.querySelector('#experiment-result');
        return r.scrollWidth <= r.clientWidth; }""")
    page.locator("#experiment-panel").screenshot(path=str(shots / "6-experiment-done.png"))
    page.locator("#statusbar").screenshot(path=str(shots / "7-hanging-status.png"))
