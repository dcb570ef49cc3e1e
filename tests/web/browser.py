"""Headless Chromium for the console tests (Debian's chromium + chromium-driver, python3-selenium):
importing this module exits 77 (skipped) where they are not installed."""
import json
import os
import sys
import urllib.request

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
try:
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.by import By  # noqa: F401 (for the tests)
except ImportError:
    print("skipped: python3-selenium is not installed (scripts/setup.sh --tests installs it)")
    sys.exit(77)
if not (os.path.exists(CHROMIUM) and os.path.exists(CHROMEDRIVER)):
    print("skipped: chromium / chromium-driver not installed (scripts/setup.sh --tests installs them)")
    sys.exit(77)


def make_driver(work, width, height, performance_log=False):
    """A headless browser window of width x height px, its profile in `work`."""
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for a in ("--headless=new", "--no-sandbox", "--disable-gpu", f"--window-size={width},{height}",
              f"--user-data-dir={work}/chromium"):
        opts.add_argument(a)
    if performance_log:
        opts.set_capability("goog:loggingPrefs", {"performance": "ALL"})
    return webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)


def get_json(url):
    with urllib.request.urlopen(url, timeout=5) as r:
        return json.load(r)


def post_command(base, body):
    """POST /api/command; returns the daemon's JSON answer."""
    data = json.dumps(body).encode()
    with urllib.request.urlopen(urllib.request.Request(base + "/api/command", data=data, method="POST"), timeout=10) as r:
        return json.load(r)
