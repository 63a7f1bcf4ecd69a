#!/bin/sh
# SPDX-License-Identifier: BSD-3-Clause
# The service's systemd files as installed by `cmake --install --component service`:
#  - systemd-analyze verify passes on the unit (ExecStart pointed at a built binary, since the
#    installed path does not exist here);
#  - systemd-analyze security --offline rates its exposure at most MAX_EXPOSURE;
#  - the live view's socket unit (imucald.socket) passes verify beside the unit;
#  - systemd-sysusers and systemd-tmpfiles accept the sysusers.d and tmpfiles.d entries in a
#    scratch root and create the user, its device groups and the state folder.
# Exit 77 (skip) when systemd-analyze is not installed.
#
#   check_systemd_units.sh BUILD_DIR EXECUTABLE [MAX_EXPOSURE]
set -eu
build=$1
executable=$2
max_exposure=${3:-2.0}

if ! command -v systemd-analyze >/dev/null 2>&1; then
  echo "SKIP: systemd-analyze is not installed (apt-get install systemd)"
  exit 77
fi
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
DESTDIR="$tmp/dest" cmake --install "$build" --component service >/dev/null

unit=$(find "$tmp/dest" -name imucald.service -path '*/lib/systemd/system/*')
socket_unit=$(find "$tmp/dest" -name imucald.socket -path '*/lib/systemd/system/*')
[ -n "$socket_unit" ] || { echo "FAIL: the live view's socket unit is not installed"; exit 1; }
sysusers=$(find "$tmp/dest" -path '*/lib/sysusers.d/imucal.conf')
tmpfiles=$(find "$tmp/dest" -path '*/lib/tmpfiles.d/imucal.conf')
[ -n "$unit" ] && [ -n "$sysusers" ] && [ -n "$tmpfiles" ] || { echo "FAIL: unit, sysusers.d or tmpfiles.d entry not installed"; exit 1; }
find "$tmp/dest" -path '*/bin/imucalctl' | grep -q . || { echo "FAIL: imucalctl not installed"; exit 1; }
find "$tmp/dest" -path '*/etc/imucal/rig.yaml' | grep -q . || { echo "FAIL: no example /etc/imucal/rig.yaml"; exit 1; }

grep -q '^ExecStart=/.*/bin/imucald --config /etc/imucal/rig.yaml ' "$unit" || { echo "FAIL: unexpected ExecStart"; grep ExecStart "$unit"; exit 1; }
mkdir "$tmp/verify"
sed "s|^ExecStart=[^ ]*|ExecStart=$executable|" "$unit" > "$tmp/verify/imucald.service"
if ! out=$(systemd-analyze verify "$tmp/verify/imucald.service" 2>&1) || [ -n "$out" ]; then
  echo "FAIL: systemd-analyze verify:"; echo "$out"; exit 1
fi
echo "verify: OK"
cp "$socket_unit" "$tmp/verify/imucald.socket"
if ! out=$(systemd-analyze verify "$tmp/verify/imucald.socket" 2>&1) || [ -n "$out" ]; then
  echo "FAIL: systemd-analyze verify imucald.socket:"; echo "$out"; exit 1
fi
grep -q '^ListenStream=127.0.0.1:8421$' "$tmp/verify/imucald.socket" ||
  { echo "FAIL: the live view's socket is not on this machine's loopback by default"; exit 1; }
echo "verify imucald.socket: OK"

level=$(systemd-analyze security --offline=yes "$tmp/verify/imucald.service" 2>/dev/null |
  sed -n 's/.*Overall exposure level for imucald.service: \([0-9.]*\).*/\1/p')
[ -n "$level" ] || { echo "FAIL: no exposure level from systemd-analyze security"; exit 1; }
echo "security: exposure $level (at most $max_exposure)"
awk -v l="$level" -v m="$max_exposure" 'BEGIN { exit !(l <= m) }' || { echo "FAIL: exposure above $max_exposure"; exit 1; }

if command -v systemd-sysusers >/dev/null 2>&1; then
  mkdir -p "$tmp/root/etc"
  systemd-sysusers --root="$tmp/root" "$sysusers"
  grep -q '^imucal:x:[0-9]*:[0-9]*:imucal calibration service:/var/lib/imucal:' "$tmp/root/etc/passwd" ||
    { echo "FAIL: sysusers did not create user imucal"; cat "$tmp/root/etc/passwd"; exit 1; }
  for g in i2c video; do
    grep -q "^$g:x:[0-9]*:.*imucal" "$tmp/root/etc/group" || { echo "FAIL: imucal not in group $g"; exit 1; }
  done
  echo "sysusers: OK"
  systemd-tmpfiles --root="$tmp/root" --create "$tmpfiles"
  [ "$(stat -c %a "$tmp/root/var/lib/imucal")" = 750 ] || { echo "FAIL: tmpfiles did not create /var/lib/imucal 0750"; exit 1; }
  echo "tmpfiles: OK"
else
  echo "note: systemd-sysusers not installed, sysusers.d and tmpfiles.d entries not checked"
fi
