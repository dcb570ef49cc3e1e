"""Shared by the console tests: checks that report and count, and manikind as a child process
whose console address is read from its own start-up line."""
import re
import shutil
import subprocess
import sys
import time

failures = []


def check(ok, what):
    print(("ok   " if ok else "FAIL ") + what, flush=True)
    if not ok:
        failures.append(what)


def wait_for(what, predicate, timeout_s=60.0):
    """Polls a condition on real events (page updates, daemon state) until it holds."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(0.2)
    check(False, f"{what} (within {timeout_s:.0f} s)")
    return None


def start_daemon(args):
    """Starts manikind with `args` (which must include --http 127.0.0.1:0 or an [http] listen);
    returns the process and the console's port (None when it never printed one)."""
    daemon = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    for line in daemon.stdout:
        m = re.search(r"console http://127\.0\.0\.1:(\d+)/", line)
        if m:
            return daemon, int(m.group(1))
    return daemon, None


def stop_daemon(daemon, work_dir):
    daemon.terminate()
    try:
        daemon.wait(timeout=30)
    except subprocess.TimeoutExpired:
        daemon.kill()
    shutil.rmtree(work_dir, ignore_errors=True)


def run(main):
    main()
    if failures:
        print(f"{len(failures)} check(s) failed")
        sys.exit(1)
    print("all checks passed")
