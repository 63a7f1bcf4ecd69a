#!/bin/sh
# SPDX-License-Identifier: BSD-3-Clause
# The restart policy of imucald.service under a real systemd: systemd (/lib/systemd/systemd) boots
# as PID 1 of its own PID, mount, cgroup, network, UTS and IPC namespaces, on a throwaway root (an
# overlay of / whose writes go to a tmpfs), with the unit, sysusers.d and tmpfiles.d entries and
# example configuration that `cmake --install BUILD_DIR --component service` installs: the unit
# in its installed folder, the example as /etc/imucal/rig.yaml (its --config), the user made by
# systemd-sysusers. A drop-in in /run/systemd/system/imucald.service.d points ExecStart= at
# BUILD_DIR/daemon/imucald with the installed unit's arguments. Checked:
#  - the example configuration, whose devices are not on this machine: imucald exits 69 (device
#    absent), which RestartPreventExitStatus= lists, so the unit starts once and stays failed
#    (NRestarts=0, failed/failed, Result=exit-code) while it is watched for 10 x RestartSec=;
#  - the same with --devices-may-appear-later added to ExecStart= (the drop-in the unit's comments
#    give for devices that come later): imucald exits 1 and is restarted until the start limit
#    trips ("Start request repeated too quickly" in the journal) within StartLimitIntervalSec=:
#    NRestarts ends at StartLimitBurst= or below, the unit ends failed/failed and nothing starts
#    it again for 3 x RestartSec=. Result= is start-limit-hit or, as systemd 252 reports it when
#    the refused restart follows a failed run, that run's exit-code.
# The figures (restarts counted, starts in the journal, final state, seconds waited) are printed.
# systemd boots its basic.target (imucal-test.target wants it: imucald.service's default
# dependencies pull it in anyway) with the timers masked; the root is set up as systemd-nspawn
# does (/sys and /proc/sys read-only, a /dev of its own, no CAP_SYS_MODULE, CAP_SYS_TIME,
# CAP_SYS_RAWIO or CAP_SYSLOG), so nothing of the boot reaches the host's kernel settings, devices
# or network. systemctl and journalctl reach it with nsenter. On exit the namespace's PID 1 is
# killed (every process in it goes with it, its mounts with the last one), its cgroup and the
# scratch folder are removed. About 40 s.
# For a sanitized imucald the drop-in also sets ASAN_OPTIONS=detect_leaks=0: LeakSanitizer needs
# ptrace at exit, which the unit's SystemCallFilter= refuses, and it then exits 1 instead of
# imucald's own status.
# Exit 0 when the checks pass, 1 when one fails, 77 (skip) when systemd cannot be booted here: not
# root, a tool missing (unshare, nsenter, pivot_root and setpriv from util-linux; systemd; cmake),
# namespaces refused, no cgroup2 hierarchy on the host, the build tree hidden from or unreadable
# by the service's user, or the example's devices present on this machine.
#
#   check_systemd_restarts.sh BUILD_DIR
set -u

# --- inside the namespaces: PID 1 prepares the root and becomes systemd --------------------------
# check_systemd_restarts.sh --inner TMP BUILD_DIR (run by unshare below; not for direct use)
# As systemd-nspawn does for a container: /sys and /proc/sys read-only, a /dev of its own with the
# basic nodes, no CAP_SYS_MODULE, CAP_SYS_TIME, CAP_SYS_RAWIO or CAP_SYSLOG. The units of
# sysinit.target that would change the host's kernel (modules, sysctl, binfmt, clock, debugfs)
# then skip on their conditions; the others write to the overlay, the namespace's tmpfs mounts or
# its network namespace.
if [ "${1:-}" = --inner ]; then
  tmp=$2 build=$3
  set -e
  r=$tmp/root
  mount --make-rprivate /
  mount -t tmpfs -o mode=0755 imucal-rw "$tmp/rw"
  mkdir "$tmp/rw/upper" "$tmp/rw/work"
  mount -t overlay -o "lowerdir=/,upperdir=$tmp/rw/upper,workdir=$tmp/rw/work" imucal-root "$r"
  mount -t proc proc "$r/proc"
  for p in sys sysrq-trigger; do
    [ -e "$r/proc/$p" ] || continue
    mount --bind "$r/proc/$p" "$r/proc/$p"
    mount -o remount,bind,ro "$r/proc/$p"
  done
  mount --bind /sys "$r/sys"
  mount -o remount,bind,ro "$r/sys"
  mount -t cgroup2 cgroup2 "$r/sys/fs/cgroup"
  mount -t tmpfs -o mode=0755,nosuid imucal-dev "$r/dev"
  for n in null zero full random urandom tty console; do
    touch "$r/dev/$n"
  done
  for n in null zero full random urandom tty; do
    mount --bind "/dev/$n" "$r/dev/$n"
  done
  mount --bind "$tmp/console" "$r/dev/console"
  mkdir "$r/dev/pts" "$r/dev/shm"
  mount -t devpts -o newinstance,ptmxmode=0666,mode=0620 devpts "$r/dev/pts"
  ln -s pts/ptmx "$r/dev/ptmx"
  mount -t tmpfs -o mode=1777,nosuid,nodev tmpfs "$r/dev/shm"
  ln -s /proc/self/fd "$r/dev/fd"
  ln -s /proc/self/fd/0 "$r/dev/stdin"
  ln -s /proc/self/fd/1 "$r/dev/stdout"
  ln -s /proc/self/fd/2 "$r/dev/stderr"
  mount -t tmpfs -o mode=0755 tmpfs "$r/run"
  mount -t tmpfs -o mode=1777 tmpfs "$r/tmp"
  # The build tree as it is (it may be on another file system than /), read-only.
  mkdir -p "$r$build"
  mount --rbind "$build" "$r$build"
  mount -o remount,bind,ro "$r$build"
  # What the package's maintainer scripts would do: the user and the state folder.
  systemd-sysusers --root="$r" "$tmp/sysusers.conf" >/dev/null
  systemd-tmpfiles --root="$r" --create "$tmp/tmpfiles.conf" >/dev/null
  mkdir -p "$r/etc/imucal" "$r$(dirname "$(cat "$tmp/unit-path")")" "$r/run/systemd/system/imucald.service.d" \
    "$r/run/systemd/journald.conf.d"
  cp "$tmp/rig.yaml" "$r/etc/imucal/rig.yaml"
  cp "$tmp/imucald.service" "$r$(cat "$tmp/unit-path")"
  cp "$tmp/imucal-test.target" "$r/run/systemd/system/"
  cp "$tmp/10-build.conf" "$r/run/systemd/system/imucald.service.d/"
  # One journal in /run (no flush to /var/log/journal), and no timers (apt, man-db, fstrim).
  printf '[Journal]\nStorage=volatile\n' >"$r/run/systemd/journald.conf.d/imucal-test.conf"
  ln -s /dev/null "$r/run/systemd/system/timers.target"
  cd "$r"
  mkdir -p .oldroot
  pivot_root . .oldroot
  umount -l /.oldroot
  rmdir /.oldroot
  cd /
  export container=imucal-test
  exec setpriv --bounding-set=-sys_module,-sys_time,-sys_rawio,-syslog,-wake_alarm,-audit_control,-audit_read \
    /lib/systemd/systemd --unit=imucal-test.target --log-target=journal --show-status=no
fi

# --- on the host ----------------------------------------------------------------------------------
[ $# -ge 1 ] || { echo "usage: check_systemd_restarts.sh BUILD_DIR" >&2; exit 2; }
build=$(cd "$1" 2>/dev/null && pwd) || { echo "FAIL: no build directory $1"; exit 1; }
self=$(cd "$(dirname "$0")" && pwd)/$(basename "$0")
imucald=$build/daemon/imucald
start_s=$(date +%s)

skip() { echo "SKIP: $*"; exit 77; }
[ -x "$imucald" ] || { echo "FAIL: $imucald is not built"; exit 1; }
[ "$(id -u)" = 0 ] || skip "systemd can only be booted as PID 1 of a namespace by root (run as root)"
[ -x /lib/systemd/systemd ] || skip "no /lib/systemd/systemd (apt-get install systemd)"
for tool in unshare nsenter pivot_root setpriv systemctl journalctl systemd-sysusers systemd-tmpfiles cmake; do
  command -v "$tool" >/dev/null 2>&1 ||
    skip "$tool is not installed (apt-get install util-linux systemd cmake)"
done
case $build in
  /home/* | /root/* | /run/user/*) skip "the unit's ProtectHome=yes hides $build from imucald (use a build tree elsewhere)" ;;
esac
setpriv --reuid=65534 --regid=65534 --clear-groups "$imucald" --version >/dev/null 2>&1 ||
  skip "$imucald cannot be run by another user than its owner; the unit runs it as user imucal (make the build tree readable by others)"
unshare --pid --fork --mount --cgroup --net --uts --ipc true 2>/dev/null ||
  skip "unshare --pid --mount --cgroup --net is refused here (needs CAP_SYS_ADMIN: a privileged container, or a VM)"
cgroup2=$(awk '$3 == "cgroup2" { print $2; exit }' /proc/self/mounts)
[ -n "$cgroup2" ] || skip "no cgroup2 hierarchy is mounted on this host (systemd 252 needs one; mount -t cgroup2 none /sys/fs/cgroup/unified)"
own_cgroup=$(sed -n 's/^0::\(.*\)$/\1/p' /proc/self/cgroup)

tmp=$(mktemp -d /tmp/imucal-restarts.XXXXXX)
cg=$cgroup2${own_cgroup%/}/imucal-restarts-$$
launcher='' pid1=''
cleanup() {
  if [ -n "$pid1" ] && kill -0 "$pid1" 2>/dev/null; then
    # systemd as PID 1 of a namespace: SIGKILL from outside ends it and every process in it; the
    # namespace's mounts go with its last process.
    kill -KILL "$pid1" 2>/dev/null
  fi
  [ -n "$launcher" ] && wait "$launcher" 2>/dev/null
  if [ -d "$cg" ]; then
    for _ in 1 2 3 4 5 6 7 8 9 10; do
      [ -z "$(find "$cg" -name cgroup.procs -exec cat {} + 2>/dev/null)" ] && break
      sleep 0.2
    done
    find "$cg" -depth -type d -exec rmdir {} + 2>/dev/null
    [ -d "$cg" ] && echo "warning: could not remove cgroup $cg"
  fi
  rm -rf "$tmp"
}
trap cleanup EXIT
trap 'exit 1' INT TERM HUP
fail=0
check() { # check DESCRIPTION COMMAND...: runs COMMAND; a failure is reported and remembered.
  what=$1
  shift
  if "$@"; then echo "ok: $what"; else echo "FAIL: $what"; fail=1; fi
}

# --- the installed unit and example configuration --------------------------------------------------
if ! DESTDIR="$tmp/dest" cmake --install "$build" --component service >"$tmp/install.log" 2>&1; then
  echo "FAIL: cmake --install $build --component service:"
  cat "$tmp/install.log"
  exit 1
fi
unit=$(find "$tmp/dest" -path '*/lib/systemd/system/imucald.service' | head -n 1)
{ [ -n "$unit" ] && [ -f "$tmp/dest/etc/imucal/rig.yaml" ]; } || { echo "FAIL: the unit or /etc/imucal/rig.yaml is not installed"; exit 1; }
unit_path=${unit#"$tmp/dest"}
# systemd reads units from /usr/local/lib/systemd/system, /usr/lib/... and /lib/...; a unit
# installed under another prefix is put where an administrator would put it.
case $unit_path in
  /usr/local/lib/systemd/system/* | /usr/lib/systemd/system/* | /lib/systemd/system/*) ;;
  *) unit_path=/etc/systemd/system/imucald.service ;;
esac
echo "unit: $unit_path (installed copy), imucald: $imucald"
printf '%s\n' "$unit_path" >"$tmp/unit-path"
cp "$unit" "$tmp/imucald.service"
cp "$tmp/dest/etc/imucal/rig.yaml" "$tmp/rig.yaml"
cp "$(find "$tmp/dest" -path '*/lib/sysusers.d/imucal.conf')" "$tmp/sysusers.conf"
cp "$(find "$tmp/dest" -path '*/lib/tmpfiles.d/imucal.conf')" "$tmp/tmpfiles.conf"
key() { sed -n "s/^$1=//p" "$unit" | tail -n 1; }
exec_start=$(key ExecStart)
exec_args=${exec_start#* }
case " $(key RestartPreventExitStatus) " in
  *" 69 "*) ;;
  *) echo "FAIL: RestartPreventExitStatus=$(key RestartPreventExitStatus) does not hold 69 (device absent)"; exit 1 ;;
esac

# The example's devices must be absent here, else this is not the case under test.
"$imucald" --config "$tmp/rig.yaml" --state-dir "$tmp/state" --check >"$tmp/check.log" 2>&1
rc=$?
[ "$rc" = 69 ] || { echo "SKIP: imucald --check on the example configuration exits $rc, not 69 (its devices are on this machine?):"; cat "$tmp/check.log"; exit 77; }

cat >"$tmp/imucal-test.target" <<'EOF'
[Unit]
Description=imucal restart test: the basic system, as imucald.service's default dependencies need
Wants=basic.target
After=basic.target
EOF
# The build's imucald, with the installed unit's arguments. A sanitized build's LeakSanitizer
# needs ptrace at exit, which SystemCallFilter= refuses: it then ends the program with status 1
# instead of imucald's own, so leak detection is off in the unit (ASan itself stays on).
printf '[Service]\nExecStart=\nExecStart=%s %s\n' "$imucald" "$exec_args" >"$tmp/10-build.conf"
if ldd "$imucald" 2>/dev/null | grep -q libasan; then
  printf 'Environment=ASAN_OPTIONS=detect_leaks=0\n' >>"$tmp/10-build.conf"
  echo "note: sanitized imucald: ASAN_OPTIONS=detect_leaks=0 in the unit (LeakSanitizer needs ptrace)"
fi
: >"$tmp/console"
mkdir "$tmp/rw" "$tmp/root"

# --- boot ---------------------------------------------------------------------------------------------
if ! mkdir "$cg" 2>"$tmp/cg.err"; then
  skip "cannot make a cgroup for systemd under $cgroup2${own_cgroup%/}: $(cat "$tmp/cg.err")"
fi
# The launcher joins the new cgroup before unshare, so the cgroup namespace's root is that cgroup
# and systemd manages it as its whole tree.
sh -c 'echo $$ >"$1/cgroup.procs" && exec unshare --pid --fork --mount --cgroup --net --uts --ipc --propagation private sh "$2" --inner "$3" "$4"' \
  sh "$cg" "$self" "$tmp" "$build" >"$tmp/inner.log" 2>&1 &
launcher=$!
for _ in $(seq 50); do
  pid1=$(awk '{ print $1 }' "/proc/$launcher/task/$launcher/children" 2>/dev/null)
  [ -n "$pid1" ] && break
  sleep 0.1
done
ns() { nsenter --target "$pid1" --mount --pid --root --wd -- "$@"; }
state=
for _ in $(seq 60); do
  kill -0 "$launcher" 2>/dev/null || break
  state=$(ns systemctl is-system-running 2>/dev/null)
  case $state in running | degraded) break ;; esac
  sleep 0.5
done
case $state in
  running | degraded)
    echo "systemd: $(ns systemctl --version | head -n 1), PID 1 of a namespace, $state after $(($(date +%s) - start_s)) s"
    [ "$state" = running ] || echo "  failed units: $(ns systemctl list-units --failed --plain --no-legend | awk '{ printf "%s ", $1 }')" ;;
  *)
    echo "SKIP: systemd could not be booted in a namespace (state '$state'); what the namespace's PID 1 said:"
    sed 's/^/  /' "$tmp/inner.log"
    tail -n 20 "$tmp/console" | sed 's/^/  /'
    exit 77 ;;
esac

show() {
  ns systemctl show imucald.service -p NRestarts -p ActiveState -p SubState -p Result -p ExecMainStatus >"$tmp/show" 2>&1
}
prop() { sed -n "s/^$1=//p" "$tmp/show"; }
now_ms() { date +%s%3N; }
secs() { # milliseconds as seconds, with one decimal when not whole
  if [ $(($1 % 1000)) = 0 ]; then echo $(($1 / 1000)); else echo "$(($1 / 1000)).$(($1 % 1000 / 100))"; fi
}
figures() { echo "  after $1 s: NRestarts=$(prop NRestarts) $(prop ActiveState)/$(prop SubState) Result=$(prop Result) ExecMainStatus=$(prop ExecMainStatus)"; }
# The unit's journal (systemd's lines about it and imucald's output) after the mark: mark counts
# its lines so far (one journal, in /run, so lines only add at its end).
unit_journal() { ns journalctl -u imucald.service -o short-monotonic --no-pager 2>/dev/null | grep -v '^-- '; }
mark() { marked=$(unit_journal | wc -l); }
journal() { unit_journal | tail -n +$((marked + 1)); }
echo "unit: StartLimitBurst=$(key StartLimitBurst) StartLimitIntervalSec=$(key StartLimitIntervalSec)" \
  "Restart=$(key Restart) RestartSec=$(key RestartSec) RestartPreventExitStatus=$(key RestartPreventExitStatus)"
# The unit's figures as systemd has them (drop-ins included), in milliseconds.
span_ms() {
  us=$(systemd-analyze timespan "$1" 2>/dev/null | sed -n 's/.*s: \([0-9][0-9]*\)$/\1/p')
  echo $((${us:-0} / 1000))
}
burst=$(ns systemctl show imucald.service -p StartLimitBurst --value)
interval_ms=$(span_ms "$(ns systemctl show imucald.service -p StartLimitIntervalUSec --value)")
restart_ms=$(span_ms "$(ns systemctl show imucald.service -p RestartUSec --value)")
{ [ -n "$burst" ] && [ "$interval_ms" -gt 0 ] && [ "$restart_ms" -gt 0 ]; } ||
  { echo "FAIL: cannot read StartLimitBurst=, StartLimitIntervalSec= or RestartSec= from systemd"; exit 1; }
interval_s=$(secs "$interval_ms") restart_s=$(secs "$restart_ms")

# --- 1: the example configuration, devices absent: exit 69, no restart -----------------------------------
echo "== 1: the installed example configuration, its devices absent: exit 69, not restarted"
mark
watch_ms=$((10 * restart_ms))
t0=$(now_ms)
ns systemctl start --no-block imucald.service
while :; do
  sleep 1
  show
  [ "$(prop NRestarts)" != 0 ] && break
  [ $(($(now_ms) - t0)) -ge "$watch_ms" ] && break
done
waited=$(secs $(($(now_ms) - t0)))
figures "$waited"
journal >"$tmp/journal1"
starts=$(grep -c ': Starting imucald.service' "$tmp/journal1")
echo "  restarts counted: $(prop NRestarts); starts in the journal: $starts; watched $waited s (10 x RestartSec=$restart_s)"
check "imucald exits 69 (device absent)" test "$(prop ExecMainStatus)" = 69
check "NRestarts=0 (69 is in RestartPreventExitStatus=)" test "$(prop NRestarts)" = 0
check "the unit stays failed (failed/failed, Result=exit-code)" \
  test "$(prop ActiveState)/$(prop SubState)/$(prop Result)" = failed/failed/exit-code
check "one start in the journal" test "$starts" = 1
check "imucald's message in the journal names the missing device" grep -q 'imucald\[[0-9]*\]: .*not on this machine: imu.device' "$tmp/journal1"
[ "$fail" = 0 ] || sed 's/^/  | /' "$tmp/journal1"

# --- 2: a failure that is restarted, until the start limit ---------------------------------------------------
echo "== 2: --devices-may-appear-later: exit 1, restarted until the start limit"
fail1=$fail
ns systemctl stop imucald.service >/dev/null 2>&1
ns systemctl reset-failed imucald.service >/dev/null 2>&1
printf '[Service]\nExecStart=\nExecStart=%s %s --devices-may-appear-later\n' "$imucald" "$exec_args" |
  ns sh -c 'cat >/run/systemd/system/imucald.service.d/20-devices-later.conf'
ns systemctl daemon-reload
mark
limit_ms=$((interval_ms + 10000))
t0=$(now_ms)
ns systemctl start --no-block imucald.service
# With Restart=on-failure the unit is activating (auto-restart) between starts: failed is the end.
while :; do
  sleep 1
  show
  [ "$(prop ActiveState)" = failed ] && break
  [ $(($(now_ms) - t0)) -ge "$limit_ms" ] && break
done
ended=$(secs $(($(now_ms) - t0)))
figures "$ended"
restarts=$(prop NRestarts)
# Nothing starts it again: the figures stay for 3 x RestartSec=.
sleep "$(secs $((3 * restart_ms)))"
show
waited=$(secs $(($(now_ms) - t0)))
figures "$waited"
journal >"$tmp/journal2"
starts=$(grep -c ': Starting imucald.service' "$tmp/journal2")
refused=$(grep -c 'imucald.service: Start request repeated too quickly' "$tmp/journal2")
# From the first start to the refused one, by the journal's monotonic clock.
span=$(awk -F'[][]' '/: Starting imucald.service/ && !first { first = $2 }
  /Start request repeated too quickly/ { last = $2 } END { if (first != "" && last != "") printf "%.1f", last - first }' "$tmp/journal2")
echo "  restarts counted: $(prop NRestarts) (starts: $starts, refused: $refused); start limit hit $span s after the first start" \
  "(StartLimitBurst=$burst in StartLimitIntervalSec=$interval_s); unit failed after $ended s, watched $waited s"
check "the start limit trips (\"Start request repeated too quickly\" once)" test "$refused" = 1
check "within StartLimitIntervalSec=$interval_s" awk -v s="${span:-999999}" -v l="$interval_ms" 'BEGIN { exit !(s * 1000 < l) }'
check "restarted, and NRestarts=$(prop NRestarts) at most StartLimitBurst=$burst" \
  sh -c "[ '$(prop NRestarts)' -ge 1 ] && [ '$(prop NRestarts)' -le '$burst' ]"
check "starts run: $starts, at most StartLimitBurst=$burst" test "$starts" -le "$burst"
after=$(awk '/Start request repeated too quickly/ { on = 1 } on && /: Starting imucald.service/ { n++ } END { print n + 0 }' "$tmp/journal2")
check "no start after the limit (NRestarts stays $restarts, $after starts in the journal after it)" \
  sh -c "[ '$(prop NRestarts)' = '$restarts' ] && [ '$after' = 0 ]"
check "the unit ends failed (failed/failed)" test "$(prop ActiveState)/$(prop SubState)" = failed/failed
# systemd 252 keeps the last run's result when the limit refuses an automatic restart (Result=
# start-limit-hit only when that run had succeeded; systemd issue #32203): either means the limit.
check "Result=$(prop Result) (start-limit-hit, or exit-code from the last run)" \
  sh -c "[ '$(prop Result)' = start-limit-hit ] || [ '$(prop Result)' = exit-code ]"
check "imucald exits 1 (device absent, --devices-may-appear-later)" test "$(prop ExecMainStatus)" = 1
[ "$fail" = "$fail1" ] || sed 's/^/  | /' "$tmp/journal2"

# --- done: stop systemd --------------------------------------------------------------------------------------
ns systemctl exit 0 >/dev/null 2>&1
for _ in $(seq 50); do
  kill -0 "$launcher" 2>/dev/null || break
  sleep 0.2
done
kill -0 "$launcher" 2>/dev/null && echo "note: systemd did not exit on 'systemctl exit'; killed"
echo "total: $(($(date +%s) - start_s)) s"
exit $fail
