#!/usr/bin/env python3
"""The operator prompt in a real browser (issue 64): a clothing campaign on the simulated lab whose
operator waits ([simulation] operator_prompts = "wait"): the console's header shows what to put on,
on the first screen at 800x600, the trial stays in configuring, and "Done: continue" with the
token lets it go on. Then a physiological trial: the model's core and mean skin drawn as a trend,
its phase with the time in it; then a comfort-mode trial, named with its equation. Exit 77 (skipped) only when the browser or selenium is
not installed.

usage: operator_prompt_browser.py <manikind binary> [--screenshot PATH]
"""
import os
import secrets
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from harness import check, run, start_daemon, stop_daemon, wait_for  # noqa: E402
from browser import By, get_json, make_driver, post_command  # noqa: E402 (exits 77 without the browser)


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

        status = lambda: get_json(base + "/api/status")
        driver = make_driver(work, 800, 600)
        driver.get(base + "/")
        banner_hidden = lambda: driver.execute_script("return document.getElementById('operator-banner').hidden;")
        wait_for("the page receives updates", lambda: int(driver.find_element(By.TAG_NAME, "body").get_attribute("data-updates") or 0) >= 1, 20)
        check(banner_hidden(), "no campaign: no operator banner")
        started = post_command(base, {"cmd": "start_campaign", "token": token, "plan_toml": plan})
        check(started.get("ok") is True, "the clothing campaign was started through POST /api/command")
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

        # A physiological trial next: its model is watched as a trend (core and mean skin) with its
        # phase and how long it has run, where a constant-skin trial shows its steady-state bar.
        def next_campaign(running, plan_toml, what):
            """Aborts the campaign running (by its name, as abort asks) and starts the next."""
            aborted = post_command(base, {"cmd": "abort", "token": token, "reason": f"next: {what}", "confirm": running})
            check(aborted.get("ok") is True, f"the {running} campaign was aborted ({aborted})")
            started = post_command(base, {"cmd": "start_campaign", "token": token, "plan_toml": plan_toml})
            check(started.get("ok") is True, f"the {what} campaign was started ({started})")

        physio = ('name = "model"\nreplicates = 1\nsettle_window_min = 0\nsettle_band_c = 10\nsettle_tolerance_c = 10\n'
                  'settle_tolerance_rh_pct = 50\n[[cases]]\nid = 1\nchamber_temp_c = 41\nchamber_rh_pct = 20\n'
                  'control = "physiological"\n[cases.model]\nname = "stolwijk-2026"\nmetabolic_met = 1.5\nduration_min = 30\n')
        next_campaign("dressing", physio, "physiological")
        trend = wait_for("the model's trend draws core and mean skin", lambda: driver.execute_script(
            "const p = document.getElementById('model-panel'); if (p.hidden) return 0;"
            "return document.querySelectorAll('#chart-model polyline').length;") >= 2, 90)
        check(bool(trend), "the model panel draws two trend lines (core, mean skin)")
        phase = driver.execute_script("return document.getElementById('model-phase').textContent;")
        check("min" in phase and ("before fallback" in phase or "running" in phase),
              f"the phase says how long it has run (and when preconditioning falls back): {phase}")
        check(driver.execute_script("return document.getElementById('steady-section').hidden;"),
              "a physiological trial shows no steady-state bar")
        control_text = lambda: driver.execute_script(
            "const c = document.getElementById('control-mode'); return c.hidden ? '' : c.textContent;")
        check("thermoregulation model" in control_text(), f"the console says how the zones are driven: {control_text()}")
        if screenshot:
            driver.set_window_size(1500, 1300)
            driver.execute_script("document.getElementById('model-panel').scrollIntoView();")
            driver.save_screenshot(screenshot.replace(".png", "-model.png"))
        # Comfort mode (issue 65): the console names the mode and its equation, not a skin setpoint.
        comfort = ('name = "comfort"\nreplicates = 1\nsettle_window_min = 0\nsettle_band_c = 10\nsettle_tolerance_c = 10\n'
                   'settle_tolerance_rh_pct = 50\ntrial_duration_min = 30\n[[cases]]\nid = 1\nchamber_temp_c = 22\n'
                   'chamber_rh_pct = 40\ncontrol = "comfort"\n')
        next_campaign("model", comfort, "comfort")
        shown = wait_for("the console names comfort mode", lambda: "comfort mode" in control_text() and control_text(), 60)
        check(bool(shown) and "36.4" in shown and "0.054" in shown, f"comfort mode with its equation: {shown}")
    finally:
        if driver:
            driver.quit()
        stop_daemon(daemon, work)


if __name__ == "__main__":
    run(main)
