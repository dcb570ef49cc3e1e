#!/usr/bin/env python3
"""Receivers the notification tests send to, not written in this project's C++: Python's own
HTTP server for webhooks, and aiosmtpd (a real SMTP server) for e-mail.

    notify_peers.py http COUNT [FAIL_FIRST]   print "port N", then one JSON line per POST received
                                              (answering 500 to the first FAIL_FIRST), exit after COUNT
    notify_peers.py smtp COUNT                 print "port N", then one JSON line per message, exit after COUNT

Each exits after 120 s whatever happened, so a broken test cannot leave it running. Exit 77 when
aiosmtpd is missing (scripts/setup.sh --tests installs python3-aiosmtpd).
"""
import json
import socket
import sys
import threading
import time

mode, count = sys.argv[1], int(sys.argv[2])
fail_first = int(sys.argv[3]) if len(sys.argv) > 3 else 0
received = 0
done = threading.Event()
lock = threading.Lock()


def emit(obj):
    global received
    with lock:
        print(json.dumps(obj), flush=True)
        received += 1
        if received >= count:
            done.set()


if mode == "http":
    from http.server import BaseHTTPRequestHandler, HTTPServer

    answered = 0

    class Handler(BaseHTTPRequestHandler):
        def do_POST(self):
            global answered
            body = self.rfile.read(int(self.headers.get("Content-Length", "0"))).decode("utf-8")
            answered += 1
            if answered <= fail_first:
                self.send_response(500)
                self.end_headers()
                return
            self.send_response(200)
            self.end_headers()
            emit({"path": self.path, "content_type": self.headers.get("Content-Type"),
                  "title": self.headers.get("Title"), "body": json.loads(body)})

        def log_message(self, *args):
            pass

    server = HTTPServer(("127.0.0.1", 0), Handler)
    print(f"port {server.server_address[1]}", flush=True)
    threading.Thread(target=server.serve_forever, daemon=True).start()
elif mode == "smtp":
    try:
        from aiosmtpd.controller import Controller
    except ImportError:
        print("SKIP: python3-aiosmtpd is not installed (scripts/setup.sh --tests installs it)", flush=True)
        sys.exit(77)

    class Sink:
        async def handle_DATA(self, server, session, envelope):
            emit({"from": envelope.mail_from, "to": envelope.rcpt_tos,
                  "data": envelope.content.decode("utf-8", errors="replace")})
            return "250 OK"

    with socket.socket() as s:  # a free port for the controller
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    controller = Controller(Sink(), hostname="127.0.0.1", port=port)
    controller.start()
    print(f"port {port}", flush=True)
else:
    sys.exit(f"unknown mode {mode}")

done.wait(120)
time.sleep(0.1)  # let the last answer reach the client before the server goes
sys.exit(0 if done.is_set() else 1)
