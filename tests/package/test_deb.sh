#!/usr/bin/env bash
# The Debian package in a clean Debian 12 root (issue 62; docs/daemon.md, "The Debian package"):
# debootstrap --variant=minbase bookworm from the mirror this machine's apt uses, then
#   install  apt-get install ./manikind_<v>.deb (its dependencies from the mirror): files,
#            modes, the user, the enabled unit, `manikin` on the PATH, the configuration checks;
#            the daemon started as systemd would start it (the unit's ExecStart, User, Group,
#            SupplementaryGroups, WorkingDirectory, UMask, RuntimeDirectory; no systemd runs in a
#            chroot), `manikin status` on /run/manikind/manikind.sock, stopped with SIGTERM; a
#            campaign template recorded into /var/lib/manikind/manikind.db (--virtual);
#   upgrade  a second .deb with a higher version: the database and an edit in /etc stay;
#   purge    apt-get purge: programs, configuration and unit gone, recordings and user kept.
# usage: test_deb.sh <source dir> <build dir>. Exit 77 = skipped (not root, no debootstrap, the
# mirror unreachable). Nothing is cached: the root is made in a temporary folder and removed.
set -euo pipefail
src=$(cd "${1:?usage: test_deb.sh <source dir> <build dir>}" && pwd)
build=$(cd "${2:?usage: test_deb.sh <source dir> <build dir>}" && pwd)
skip() { echo "SKIP: $*"; exit 77; }
fail() { echo "FAIL: $*"; exit 1; }
step() { printf '[%3d s] %s\n' "$SECONDS" "$*"; }

[ "$(id -u)" -eq 0 ] || skip "needs root (debootstrap, chroot, mounts)"
command -v debootstrap >/dev/null || skip "debootstrap is not installed (scripts/setup.sh --tests installs it)"

# The Debian mirror of this machine's apt sources: deb822 files first, then sources.list lines.
mirror=$(
  { for f in /etc/apt/sources.list.d/*.sources; do [ -f "$f" ] && cat "$f" && echo; done; } 2>/dev/null |
    awk 'BEGIN { RS = ""; FS = "\n" }
         { uris = ""; suites = ""; enabled = "yes"
           for (i = 1; i <= NF; i++) {
             if ($i ~ /^URIs:/) { uris = $i; sub(/^URIs:[ \t]*/, "", uris) }
             if ($i ~ /^Suites:/) { suites = " " $i " "; sub(/^Suites:/, "", suites) }
             if ($i ~ /^Enabled:[ \t]*no/) enabled = "no" }
           if (enabled == "yes" && suites ~ /[ \t]bookworm[ \t]/) { split(uris, u, /[ \t]+/); print u[1]; exit } }'
)
if [ -z "$mirror" ] && [ -f /etc/apt/sources.list ]; then
  mirror=$(sed 's/\[[^]]*\]//' /etc/apt/sources.list | awk '$1 == "deb" && $3 == "bookworm" { print $2; exit }')
fi
mirror=${mirror:-http://deb.debian.org/debian}
mirror=${mirror%/}
step "mirror $mirror"
if command -v curl >/dev/null; then
  curl -fsS -o /dev/null --max-time 20 "$mirror/dists/bookworm/Release" || skip "the mirror $mirror does not answer"
elif command -v wget >/dev/null; then
  wget -q -O /dev/null --timeout=20 "$mirror/dists/bookworm/Release" || skip "the mirror $mirror does not answer"
fi

work=$(mktemp -d "${TMPDIR:-/var/tmp}/manikind-deb-test.XXXXXX")
root=$work/root
daemon_pid=
cleanup() {
  status=$?
  step "cleanup"
  [ -n "$daemon_pid" ] && kill "$daemon_pid" 2>/dev/null && wait "$daemon_pid" 2>/dev/null || true
  for m in "$root/dev/pts" "$root/dev" "$root/proc"; do
    mountpoint -q "$m" 2>/dev/null && umount -l "$m" || true
  done
  # Never delete through a mount still in place (/dev is the host's own).
  if [ -n "$(findmnt -rn -o TARGET | awk -v r="$root" 'index($0, r) == 1')" ]; then
    echo "cleanup: mounts left under $root; not removing $work"
  else
    rm -rf --one-file-system "$work"
  fi
  # The upgrade's .deb is the test's own: no one should install it from build/ by mistake.
  [ -n "${deb2:-}" ] && rm -f "$deb2"
  step "done"
  exit "$status"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

step "building the two packages"
deb1=$(MANIKIND_BUILD_DIR="$build" "$src/scripts/package.sh" | tail -n 1)
version1=$(dpkg-deb -f "$deb1" Version)
version2="$version1+upgradetest1"
deb2=$(MANIKIND_BUILD_DIR="$build" "$src/scripts/package.sh" "$version2" | tail -n 1)
dpkg --compare-versions "$version2" gt "$version1" || fail "$version2 is not above $version1"
step "$(basename "$deb1"), $(basename "$deb2"): depends $(dpkg-deb -f "$deb1" Depends)"

step "debootstrap --variant=minbase bookworm"
debootstrap --variant=minbase bookworm "$root" "$mirror" >"$work/debootstrap.log" 2>&1 \
  || { tail -n 30 "$work/debootstrap.log"; fail "debootstrap failed"; }
mount -t proc proc "$root/proc"
mount --bind /dev "$root/dev"
mount --bind /dev/pts "$root/dev/pts"  # the simulated lab puts its serial instruments on pseudo-terminals
in_root() { chroot "$root" /usr/bin/env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin LANG=C.UTF-8 "$@"; }
[ ! -e "$root/run/systemd/system" ] || fail "the root looks like a running systemd"
cp "$deb1" "$deb2" "$root/tmp/"

step "install $(basename "$deb1")"
in_root apt-get update -qq >"$work/apt.log" 2>&1 || { cat "$work/apt.log"; fail "apt-get update in the root"; }
DEBIAN_FRONTEND=noninteractive in_root apt-get install -y -qq --no-install-recommends "/tmp/$(basename "$deb1")" \
  >>"$work/apt.log" 2>&1 || { tail -n 40 "$work/apt.log"; fail "apt-get install of $(basename "$deb1")"; }
[ "$(in_root dpkg-query -W -f='${Status} ${Version}' manikind)" = "install ok installed $version1" ] || fail "manikind $version1 is not installed"

for f in /usr/bin/manikin /usr/bin/manikind /usr/lib/manikind/libmanikind-hdf5.so /usr/lib/manikind/libmanikind-pq.so \
         /usr/lib/manikind/libmanikind-curl.so /usr/lib/manikind/libmanikind-crypto.so /etc/manikind/manikind.toml \
         /usr/lib/systemd/system/manikind.service /usr/share/manikind/chamber_registers.toml \
         /usr/share/manikind/datalogger_registers.toml /usr/share/manikind/andi35_zone_map.csv \
         /usr/share/manikind/real-lab.toml /usr/share/manikind/campaign-example.toml /usr/share/doc/manikind/README.md \
         /usr/share/doc/manikind/daemon.md; do
  [ -f "$root$f" ] || fail "$f is not installed"
done
in_root dpkg-query --control-show manikind conffiles | grep -qx '/etc/manikind/manikind.toml' \
  || in_root sh -c "dpkg-query -W -f='\${Conffiles}' manikind | grep -q '/etc/manikind/manikind.toml'" \
  || fail "/etc/manikind/manikind.toml is not a conffile"
passwd=$(in_root getent passwd manikind) || fail "no user manikind"
uid=$(echo "$passwd" | cut -d: -f3)
[ "$uid" -lt 1000 ] || fail "manikind is not a system user (uid $uid)"
[ "$(echo "$passwd" | cut -d: -f7)" = /usr/sbin/nologin ] || fail "manikind has a login shell: $passwd"
in_root getent group manikind >/dev/null || fail "no group manikind"
[ "$(in_root stat -c '%U:%G %a' /var/lib/manikind)" = "manikind:manikind 750" ] || fail "/var/lib/manikind: $(in_root stat -c '%U:%G %a' /var/lib/manikind)"
[ "$(in_root stat -c '%U:%G %a' /etc/manikind)" = "root:manikind 750" ] || fail "/etc/manikind: $(in_root stat -c '%U:%G %a' /etc/manikind)"
[ "$(in_root stat -c '%U:%G %a' /etc/manikind/manikind.toml)" = "root:manikind 640" ] || fail "manikind.toml: $(in_root stat -c '%U:%G %a' /etc/manikind/manikind.toml)"
[ -L "$root/etc/systemd/system/multi-user.target.wants/manikind.service" ] || fail "the unit is not enabled"
in_root sh -c 'command -v manikin' | grep -qx /usr/bin/manikin || fail "manikin is not on the PATH"
in_root manikin --help >"$work/help.txt" 2>&1 || { cat "$work/help.txt"; fail "manikin --help"; }
in_root manikin config check /etc/manikind/manikind.toml >"$work/check.txt" 2>&1 || { cat "$work/check.txt"; fail "manikin config check on the installed configuration"; }

# The unit as systemd reads it: the first value of each key in [Service].
unit_value() { awk -v k="$1" -F= '/^\[/ { s = ($0 == "[Service]") } s && $1 == k { sub(/^[^=]*=/, ""); print; exit }' "$root/usr/lib/systemd/system/manikind.service"; }
exec_start=$(unit_value ExecStart) user=$(unit_value User) group=$(unit_value Group)
supplementary=$(unit_value SupplementaryGroups) workdir=$(unit_value WorkingDirectory) umask_value=$(unit_value UMask)
runtime_dir=/run/$(unit_value RuntimeDirectory) runtime_mode=$(unit_value RuntimeDirectoryMode)
[ "$exec_start" = "/usr/bin/manikind --config /etc/manikind/manikind.toml" ] || fail "ExecStart=$exec_start"
# systemd's part, by hand: the runtime directory, then the program as the unit's user and groups.
start_daemon() {
  in_root install -d -m "$runtime_mode" -o "$user" -g "$group" "$runtime_dir"
  local gids
  gids=$(for g in $supplementary; do in_root getent group "$g" | cut -d: -f3; done | paste -sd, -)
  chroot "$root" /usr/bin/env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin LANG=C.UTF-8 \
    setpriv --reuid="$user" --regid="$group" --groups="$gids" --inh-caps=-all --bounding-set=-all --no-new-privs \
    sh -c "umask $umask_value && cd $workdir && exec $exec_start" >>"$work/daemon.log" 2>&1 &
  daemon_pid=$!
  local waited_s=0
  # The packaged socket is the CLI's own fallback (no ./manikind.sock here): asked without --socket.
  local where=(--socket "$1")
  [ "$1" = /run/manikind/manikind.sock ] && where=()
  until in_root manikin status "${where[@]}" >"$work/status.txt" 2>&1; do
    kill -0 "$daemon_pid" 2>/dev/null || { cat "$work/daemon.log"; fail "the daemon exited"; }
    [ "$waited_s" -lt 120 ] || { cat "$work/daemon.log" "$work/status.txt"; fail "no answer on $1 in 120 s"; }
    sleep 1; waited_s=$((waited_s + 1))
  done
}
stop_daemon() {
  kill -TERM "$daemon_pid"
  local rc=0
  wait "$daemon_pid" || rc=$?
  daemon_pid=
  [ "$rc" -eq 0 ] || { cat "$work/daemon.log"; fail "the daemon exited $rc on SIGTERM"; }
}

step "the daemon as the unit starts it"
start_daemon /run/manikind/manikind.sock
grep -q 'simulated lab' "$work/status.txt" || { cat "$work/status.txt"; fail "manikin status names no simulated lab"; }
[ "$(in_root stat -c '%U:%G' /var/lib/manikind/manikind.db)" = "manikind:manikind" ] || fail "the database is not the daemon user's"
[ "$(( $(in_root stat -c '%a' /var/lib/manikind/manikind.db) & 7 ))" -eq 0 ] || fail "the database is world-accessible (UMask=$umask_value)"
stop_daemon

step "a campaign recorded into /var/lib/manikind/manikind.db"
chroot "$root" /usr/bin/env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin LANG=C.UTF-8 \
  setpriv --reuid="$user" --regid="$group" --clear-groups sh -c "umask $umask_value && cd $workdir && \
  exec $exec_start --virtual --campaign /usr/share/manikind/campaign-example.toml --exit-when-done" >>"$work/daemon.log" 2>&1 \
  || { tail -n 30 "$work/daemon.log"; fail "the campaign on the installed configuration"; }
campaign=$(awk -F'"' '/^name =/ { print $2; exit }' "$root/usr/share/manikind/campaign-example.toml")
in_root manikin campaigns --db /var/lib/manikind/manikind.db >"$work/campaigns.txt" 2>&1 || { cat "$work/campaigns.txt"; fail "manikin campaigns"; }
grep -q "$campaign" "$work/campaigns.txt" || { cat "$work/campaigns.txt"; fail "campaign $campaign is not in the database"; }
db_sum=$(sha256sum "$root/var/lib/manikind/manikind.db" | cut -d' ' -f1)

step "upgrade to $version2"
# A lab's edit: the control socket moved (the upgraded daemon must answer there).
sed -i 's|^socket = "/run/manikind/manikind.sock" |socket = "/run/manikind/edited.sock" |' "$root/etc/manikind/manikind.toml"
grep -q '^socket = "/run/manikind/edited.sock"' "$root/etc/manikind/manikind.toml" || fail "could not edit the configuration"
DEBIAN_FRONTEND=noninteractive in_root apt-get install -y -qq --no-install-recommends "/tmp/$(basename "$deb2")" \
  >>"$work/apt.log" 2>&1 || { tail -n 40 "$work/apt.log"; fail "apt-get install of $(basename "$deb2") as an upgrade"; }
[ "$(in_root dpkg-query -W -f='${Status} ${Version}' manikind)" = "install ok installed $version2" ] || fail "manikind $version2 is not installed"
grep -q '^socket = "/run/manikind/edited.sock"' "$root/etc/manikind/manikind.toml" || fail "the upgrade lost the edit in /etc/manikind/manikind.toml"
[ "$(in_root stat -c '%U:%G %a' /etc/manikind/manikind.toml)" = "root:manikind 640" ] || fail "manikind.toml after the upgrade: $(in_root stat -c '%U:%G %a' /etc/manikind/manikind.toml)"
[ "$(sha256sum "$root/var/lib/manikind/manikind.db" | cut -d' ' -f1)" = "$db_sum" ] || fail "the upgrade changed the database"
start_daemon /run/manikind/edited.sock  # fails unless the upgraded daemon reads the edited configuration
stop_daemon
in_root manikin campaigns --db /var/lib/manikind/manikind.db | grep -q "$campaign" || fail "campaign $campaign is gone after the upgrade"

step "purge"
DEBIAN_FRONTEND=noninteractive in_root apt-get purge -y -qq manikind >>"$work/apt.log" 2>&1 || { tail -n 40 "$work/apt.log"; fail "apt-get purge"; }
state=$(in_root dpkg-query -W -f='${db:Status-Status}' manikind 2>/dev/null || true)
[ -z "$state" ] || [ "$state" = not-installed ] || fail "manikind is $state after purge"
for f in /usr/bin/manikin /usr/bin/manikind /usr/lib/manikind /etc/manikind /usr/lib/systemd/system/manikind.service \
         /usr/share/manikind /etc/systemd/system/multi-user.target.wants/manikind.service /run/manikind; do
  [ ! -e "$root$f" ] && [ ! -L "$root$f" ] || fail "$f is still there after purge"
done
! in_root dpkg-statoverride --list | grep -q manikind || fail "a dpkg-statoverride is left after purge"
[ -f "$root/var/lib/manikind/manikind.db" ] || fail "purge deleted the recordings (docs/daemon.md: they are kept)"
in_root getent passwd manikind >/dev/null || fail "purge removed the user who owns the kept recordings"
step "PASS"
