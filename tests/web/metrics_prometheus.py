#!/usr/bin/env python3
"""/metrics read by a Prometheus text-format parser not written here (Debian's
python3-prometheus-client), against manikind on the simulated lab, and the console's HTTP rules:
reading needs no token, a foreign Host or Origin is refused. Exit 77 only when the parser is
not installed.

usage: metrics_prometheus.py <manikind binary>
"""
import os
import secrets
import sys
import tempfile
import time
import urllib.error
import urllib.request

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from harness import check, run, start_daemon, stop_daemon, wait_for  # noqa: E402

try:
    from prometheus_client.parser import text_string_to_metric_families
except ImportError:
    print("skipped: python3-prometheus-client is not installed (scripts/setup.sh --tests installs it)")
    sys.exit(77)



def main():
    work = tempfile.mkdtemp(prefix="manikind-metrics-")
    token = secrets.token_hex(32)
    daemon, port = start_daemon([sys.argv[1], "--socket", f"{work}/d.sock", "--database", f"{work}/d.db", "--http",
                                 "127.0.0.1:0", "--speed", "10", "--campaign", "builtin:table-s3"])
    try:
        check(port is not None, "manikind printed its console address")
        base = f"http://127.0.0.1:{port}"

        # Wait (on real samples) until the manikin's zones are in the exposition.
        families = {}
        end = time.monotonic() + 60
        while time.monotonic() < end:
            with urllib.request.urlopen(base + "/metrics", timeout=5) as r:
                content_type = r.headers.get("Content-Type", "")
                text = r.read().decode()
            families = {f.name: f for f in text_string_to_metric_families(text)}
            live = families.get("manikind_live_value")
            if live and sum(1 for s in live.samples if s.labels.get("channel", "").endswith(".skin_temp_c")) == 35:
                break
            time.sleep(0.5)
        check(content_type.startswith("text/plain; version=0.0.4"), f"content type {content_type}")
        for name in ("manikind_device_connected", "manikind_device_severity", "manikind_device_samples",
                     "manikind_device_timeouts", "manikind_live_value", "manikind_live_age_seconds",
                     "manikind_recorder_committed_rows", "manikind_recorder_dropped_rows", "manikind_recorder_queue_rows",
                     "manikind_trial_stage", "manikind_campaign_trials_total"):
            check(name in families, f"family {name} parsed")
        devices = {s.labels["device"] for s in families["manikind_device_connected"].samples}
        check(devices == {"chamber", "datalogger", "manikin", "windsonic", "csat3b"}, f"every device exposed: {sorted(devices)}")
        check(families["manikind_device_samples"].type == "counter", "device samples is a counter")
        skin = [s for s in families["manikind_live_value"].samples if s.labels["channel"].endswith(".skin_temp_c")]
        check(len(skin) == 35 and all(15 < s.value < 45 for s in skin), f"35 skin temperatures in range ({len(skin)})")
        dropped = families["manikind_recorder_dropped_rows"].samples[0].value
        duplicates = families["manikind_recorder_duplicate_rows"].samples[0].value
        check(dropped >= duplicates, f"re-sent duplicates are counted among rows not stored ({duplicates} of {dropped})")
        stages = [s for s in families["manikind_trial_stage"].samples if s.value == 1]
        check(len(stages) == 1, f"exactly one stage is current: {[s.labels['stage'] for s in stages]}")
        total = families["manikind_campaign_trials_total"].samples[0].value
        check(total == 45, f"the Table S3 campaign has 45 trials ({total})")

        try:
            urllib.request.urlopen(urllib.request.Request(base + "/api/status", headers={"Host": "evil.example"}), timeout=5)
            check(False, "a foreign Host header is refused")
        except urllib.error.HTTPError as e:
            check(e.code == 403, f"a foreign Host header is refused ({e.code})")
        req = urllib.request.Request(base + "/api/command", data=b'{"cmd":"pause","token":"' + token.encode() + b'"}',
                                     headers={"Origin": "http://evil.example"}, method="POST")
        try:
            urllib.request.urlopen(req, timeout=5)
            check(False, "a POST from another Origin is refused")
        except urllib.error.HTTPError as e:
            check(e.code == 403, f"a POST from another Origin is refused ({e.code})")
    finally:
        stop_daemon(daemon, work)


if __name__ == "__main__":
    run(main)
