#!/usr/bin/env python3
"""The operator prompt in a real browser (issue 64): a clothing campaign on the simulated lab whose
operator waits ([simulation] operator_prompts = "wait"): the console's header shows what to put on,
on the first screen at 800x600, the trial stays in configuring, and "Done: continue" with the
token lets it go on, recorded with who. Exit 77 (skipped) only when the browser or selenium is
not installed.

usage: operator_prompt_browser.py <manikind binary> [--screenshot PATH]
"""
import json
import os
import secrets
import sys
import tempfile
import urllib.request

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from harness import check, run, start_daemon, stop_daemon, wait_for  # noqa: E402

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
try:
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.by import By
except ImportError:
    print("skipped: python3-selenium is not installed (scripts/setup.sh --tests installs it)")
    sys.exit(77)
if not (os.path.exists(CHROMIUM) and os.path.exists(CHROMEDRIVER)):
    print("skipped: chromium / chromium-driver not installed (scripts/setup.sh --tests installs them)")
    sys.exit(77)


def main():
    daemon_bin = sys.argv[1]
    screenshot = sys.argv[sys.argv.index("--screenshot") + 1] if "--screenshot" in sys.argv else None
    work = tempfile.mkdtemp(prefix="manikind-prompt-")
    token = secrets.token_hex(32)
    cfg = os.path.join(work, "lab.toml")
    with open(cfg, "w") as f:
        f.write(f'[lab]\ndatabase = "{work}/d.db"\n[api]\nsocket = "{work}/d.sock"\ntoken = "{token}"\n'
                f'[http]\nlisten = "127.0.0.1:0"\n[simulation]\nruntime_dir = "{work}/sim"\noperator_prompts = "wait"\n')
    os.chmod(cfg, 0o600)
    plan = ('name = "dressing"\nreplicates = 1\ntrial_duration_min = 40\n[ensembles.coverall]\n'
            'description = "cotton coverall"\n[[cases]]\nid = 1\nchamber_temp_c = 20\nchamber_rh_pct = 50\n'
            'enclosure_temp_c = 20\nenclosure_rh_pct = 50\nskin_setpoint_c = 35\nensemble = "coverall"\ntest = "insulation"\n')
    daemon, port = start_daemon([daemon_bin, "--config", cfg, "--speed", "10"])
    driver = None
    try:
        if port is None:
            check(False, "manikind printed its console address")
            return
        base = f"http://127.0.0.1:{port}"

        def status():
            with urllib.request.urlopen(base + "/api/status", timeout=5) as r:
                return json.load(r)

        opts = webdriver.ChromeOptions()
        opts.binary_location = CHROMIUM
        for a in ("--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=800,600", f"--user-data-dir={work}/chromium"):
            opts.add_argument(a)
        driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
        driver.get(base + "/")
        banner_hidden = lambda: driver.execute_script("return document.getElementById('operator-banner').hidden;")
        wait_for("the page receives updates", lambda: int(driver.find_element(By.TAG_NAME, "body").get_attribute("data-updates") or 0) >= 1, 20)
        check(banner_hidden(), "no campaign: no operator banner")
        body = json.dumps({"cmd": "start_campaign", "token": token, "plan_toml": plan}).encode()
        with urllib.request.urlopen(urllib.request.Request(base + "/api/command", data=body, method="POST"), timeout=10) as r:
            check(json.load(r).get("ok") is True, "the clothing campaign was started through POST /api/command")
        shown = wait_for("the header says what the operator must do", lambda: not banner_hidden() and driver.execute_script(
            "return document.getElementById('operator-banner').textContent;"), 30)
        check(bool(shown) and "dress the manikin in 'coverall' for the insulation test" in shown,
              f"the banner names the ensemble and the test: {' '.join((shown or '').split())[:160]}")
        # On the first screen at 800x600, with its button.
        rect = driver.execute_script("const r = document.getElementById('operator-continue').getBoundingClientRect();"
                                     "return [r.top, r.bottom, r.left, r.right, window.innerHeight, window.innerWidth];")
        check(rect[0] >= 0 and rect[1] <= rect[4] and rect[3] <= rect[5], f"the Continue button is on the first screen at 800x600 ({rect})")
        if screenshot:
            driver.save_screenshot(screenshot)
        check(status().get("stage") == "configuring", "the trial waits in configuring")
        driver.find_element(By.ID, "token").send_keys(token)
        driver.find_element(By.ID, "operator-continue").click()
        wait_for("the banner goes once the operator said done", banner_hidden, 15)
        moved = wait_for("the trial goes on to chamber settling", lambda: status().get("stage") not in (None, "configuring", "idle"), 30)
        check(bool(moved), f"after Continue the trial left configuring ({status().get('stage')})")
        check(status().get("awaiting_operator") is None, "nothing waits for the operator any more")
    finally:
        if driver:
            driver.quit()
        stop_daemon(daemon, work)


if __name__ == "__main__":
    run(main)
