#!/bin/sh
# Runs the given test program where a PostgreSQL 15 server can be started for it (Debian's
# postgresql package; scripts/setup.sh --tests installs it); elsewhere exits 77, which CTest
# reports as skipped rather than passed. As root the server runs as nobody (initdb refuses root),
# which needs setpriv (util-linux).
bin=/usr/lib/postgresql/15/bin
for tool in initdb pg_ctl postgres; do
  if [ ! -x "$bin/$tool" ]; then
    echo "skipped: $bin/$tool not found (Debian package postgresql-15)"
    exit 77
  fi
done
if [ "$(id -u)" -eq 0 ] && { ! command -v setpriv >/dev/null || ! getent passwd nobody >/dev/null; }; then
  echo "skipped: running as root, and setpriv or the user nobody is missing to run the server unprivileged"
  exit 77
fi
exec "$@"
