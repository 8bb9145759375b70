"""Take the README's screenshot of the operator console (docs/figures/console.png).

Starts ``frictionlab run`` on loopback port 0 (the port the kernel picked is
read from the printed address; sim backend, fast design, classical friction),
opens the console in headless chromium, turns on the estimated pendulum angle,
lets the limit cycle fill the plot window and saves a screenshot, then presses
Exit.

    .venv/bin/python docs/scripts/console_screenshot.py [OUT.png]
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

from playwright.sync_api import sync_playwright

CHROMIUM_ARGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]
OUT = Path(__file__).resolve().parents[1] / "figures" / "console.png"


def main() -> int:
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else OUT
    out.parent.mkdir(parents=True, exist_ok=True)
    env = {k: v for k, v in os.environ.items() if k != "FRICTIONLAB_TOKEN"}
    proc = subprocess.Popen([sys.executable, "-m", "frictionlab", "run", "--port", "0",
                             "--log-dir", tempfile.mkdtemp(prefix="frictionlab-shot-")],
                            stdout=subprocess.PIPE, text=True, env=env)
    url, port = next((m.group(1), m.group(2)) for line in proc.stdout
                     if (m := re.search(r"frictionlab console: (http://127\.0\.0\.1:(\d+)/)",
                                        line)))
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path="/usr/bin/chromium", args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.goto(url)
            page.wait_for_selector("#conn.live", timeout=60_000)
            page.click('#signal-toggles button[data-signal="theta_hat"]')
            while True:  # a full 10 s plot window of the running loop
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/status") as r:
                    st = json.loads(r.read())
                if st["t"] >= 12 or not st["running"]:
                    break
                time.sleep(0.2)
            page.screenshot(path=str(out), full_page=True)
            browser.close()
    finally:
        req = urllib.request.Request(f"http://127.0.0.1:{port}/api/exit", data=b"{}",
                                     method="POST", headers={"Content-Type": "application/json"})
        urllib.request.urlopen(req, timeout=30).read()
        proc.wait(30)
    print(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
