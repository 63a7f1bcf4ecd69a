#!/bin/sh
# SPDX-License-Identifier: BSD-3-Clause
# The Debian package of a built tree: cpack (DEB) packages BUILD_DIR into a scratch folder, the
# package is installed into a fresh root and checked:
#  - the files are imucal_VERSION_ARCH.deb, with the programs, the modules (the virtual rig's too),
#    and imucal-aravis_VERSION_ARCH.deb and imucal-libcamera_VERSION_ARCH.deb with the camera
#    backends' modules (not the main package's dependencies; each depends on imucal of its version);
#    all three are installed into the root;
#    the unit, sysusers.d and tmpfiles.d entries, man pages and bash completion, the examples with
#    the virtual rig's target file, and every doc the programs' messages cite (docs/NAME.md);
#  - the unit's ExecStart names a program that is in the root; its --config is the package's
#    conffile and lies in ConfigurationDirectory=; its --state-dir is StateDirectory= and the
#    tmpfiles.d folder; RestartPreventExitStatus= holds imucald's configuration status, 78, and its
#    device-absent status, 69;
#  - the maintainer scripts ran: user imucal exists in the root's /etc/passwd, the state folder
#    exists and belongs to it, and nothing enabled the service;
#  - the installed imucald --check reads the installed configuration (modules found beside the
#    installed program, as on a rig) and exits 0 with --devices-may-appear-later (the example's
#    devices are not on this machine: 69 without it); on a broken copy it exits 78;
#  - lintian reports no errors (its warnings are printed).
# As root the package is installed with `dpkg --root` (an empty dpkg database; --force-depends,
# since the root holds no other package; --force-script-chrootless, so the maintainer scripts run
# with DPKG_ROOT set and change the files of that root). Otherwise it is extracted with
# `dpkg-deb -x` and the postinst is run with DPKG_ROOT by hand.
# Exit 77 (skip) when dpkg-deb, dpkg-shlibdeps or lintian is missing; the other checks run first.
#
#   check_package.sh BUILD_DIR
set -u
build=$1
src=$(cd "$(dirname "$0")/.." && pwd)

for tool in dpkg-deb dpkg-shlibdeps cpack; do
  if ! command -v "$tool" >/dev/null 2>&1; then
    echo "SKIP: $tool is not installed (apt-get install dpkg-dev cmake)"
    exit 77
  fi
done
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail=0
check() { # check DESCRIPTION COMMAND...: runs COMMAND; a failure is reported and remembered.
  what=$1
  shift
  if "$@"; then echo "ok: $what"; else echo "FAIL: $what"; fail=1; fi
}

if ! cpack --config "$build/CPackConfig.cmake" -B "$tmp/pkg" >"$tmp/cpack.log" 2>&1; then
  echo "FAIL: cpack:"
  cat "$tmp/cpack.log"
  exit 1
fi
grep -i "warning" "$tmp/cpack.log" && echo "(cpack's warnings above)"
version=$(sed -n 's/^set(CPACK_PACKAGE_VERSION "\(.*\)")/\1/p' "$build/CPackConfig.cmake")
arch=$(dpkg --print-architecture)
deb="$tmp/pkg/imucal_${version}_${arch}.deb"
backends=""
for b in aravis libcamera; do
  backends="$backends $tmp/pkg/imucal-${b}_${version}_${arch}.deb"
done
for d in "$deb" $backends; do
  [ -f "$d" ] || { echo "FAIL: no $(basename "$d"):"; ls "$tmp/pkg"; exit 1; }
  echo "package: $(basename "$d"), $(du -k "$d" | cut -f1) KiB"
  dpkg-deb --field "$d" Depends Recommends Suggests | sed 's/^/  /'
done
# The camera backends' libraries are not the main package's dependencies, and each backend's
# package depends on the main one of the same version.
check "imucal does not depend on Aravis or libcamera" sh -c \
  "! dpkg-deb --field '$deb' Depends | grep -Eq 'libaravis|libcamera'"
check "imucal suggests its camera backends" sh -c \
  "dpkg-deb --field '$deb' Suggests | grep -q imucal-aravis && dpkg-deb --field '$deb' Suggests | grep -q imucal-libcamera"
# gnuplot-nox is suggested, not recommended: its recommends would add 123 packages (docs/service.md).
check "imucal suggests gnuplot-nox and recommends nothing" sh -c \
  "dpkg-deb --field '$deb' Suggests | grep -q gnuplot-nox && [ -z \"\$(dpkg-deb --field '$deb' Recommends)\" ]"
for b in aravis libcamera; do
  check "imucal-$b depends on imucal (= $version)" sh -c \
    "dpkg-deb --field '$tmp/pkg/imucal-${b}_${version}_${arch}.deb' Depends | grep -qF 'imucal (= $version)'"
done

root="$tmp/root"
mkdir -p "$root/var/lib/dpkg/info" "$root/var/lib/dpkg/updates"
: >"$root/var/lib/dpkg/status"
if [ "$(id -u)" = 0 ] && command -v dpkg >/dev/null 2>&1; then
  echo "install: dpkg --root (maintainer scripts with DPKG_ROOT)"
  # shellcheck disable=SC2086 # the backends' paths hold no spaces (mktemp)
  if ! dpkg --root="$root" --log=/dev/null --force-depends --force-script-chrootless -i "$deb" $backends >"$tmp/dpkg.log" 2>&1; then
    echo "FAIL: dpkg --root:"
    cat "$tmp/dpkg.log"
    exit 1
  fi
  grep -q '^Status: install ok installed' "$root/var/lib/dpkg/status" || { echo "FAIL: dpkg does not list imucal as installed"; fail=1; }
else
  echo "install: dpkg-deb -x, then the postinst with DPKG_ROOT (not root: dpkg --root cannot set owners)"
  for d in "$deb" $backends; do dpkg-deb -x "$d" "$root"; done
  dpkg-deb -e "$deb" "$tmp/control"
  DPKG_ROOT="$root" "$tmp/control/postinst" configure >"$tmp/postinst.log" 2>&1 || { echo "FAIL: postinst:"; cat "$tmp/postinst.log"; exit 1; }
fi

# What the package holds.
for f in usr/bin/imucal usr/bin/imucald usr/bin/imucalctl; do
  check "$f is an executable" test -x "$root/$f"
done
for m in solve render camera aravis libcamera virtual_rig; do
  check "module libimucal_$m.so" test -f "$root/usr/lib/imucal/libimucal_$m.so"
done
for f in usr/share/man/man1/imucal.1.gz usr/share/man/man8/imucald.8.gz usr/share/man/man1/imucalctl.1.gz \
  usr/share/bash-completion/completions/imucal usr/share/bash-completion/completions/imucald \
  usr/share/bash-completion/completions/imucalctl usr/share/doc/imucal/copyright \
  usr/share/doc/imucal/changelog.gz usr/lib/sysusers.d/imucal.conf usr/lib/tmpfiles.d/imucal.conf \
  usr/share/imucal/examples/rig.yaml usr/share/imucal/examples/checkerboard-7x6.yaml; do
  check "$f" test -f "$root/$f"
done
# Every doc the programs' messages cite ("docs/NAME.md") is installed as the manual's NAME.md.
for doc in $(grep -rhoE 'docs/[a-z-]+\.md' "$src"/app "$src"/core "$src"/daemon "$src"/drivers "$src"/calib "$src"/sim \
  --include='*.cpp' --include='*.hpp' | sort -u); do
  check "$doc installed" test -f "$root/usr/share/doc/imucal/${doc#docs/}"
done

# The unit's paths against the package's files.
unit=$(find "$root" -path '*/systemd/system/imucald.service' | head -n 1)
[ -n "$unit" ] || { echo "FAIL: no imucald.service in the package"; exit 1; }
echo "unit: ${unit#"$root"}"
key() { sed -n "s/^$1=//p" "$unit"; }
exec_start=$(key ExecStart)
program=${exec_start%% *}
config=$(printf '%s\n' "$exec_start" | sed -n 's/.* --config \([^ ]*\).*/\1/p')
state=$(printf '%s\n' "$exec_start" | sed -n 's/.* --state-dir \([^ ]*\).*/\1/p')
check "ExecStart's program $program is in the package" test -x "$root$program"
check "--config $config is the conffile" sh -c "dpkg-deb --info '$deb' conffiles | grep -qx '$config'"
check "--config $config is installed" test -f "$root$config"
check "--config $config is in ConfigurationDirectory=$(key ConfigurationDirectory)" \
  test "$(dirname "$config")" = "/etc/$(key ConfigurationDirectory)"
check "--state-dir $state is StateDirectory=$(key StateDirectory)" test "$state" = "/var/lib/$(key StateDirectory)"
check "--state-dir $state is the tmpfiles.d folder" grep -q "^d $state " "$root/usr/lib/tmpfiles.d/imucal.conf"
check "RestartPreventExitStatus=78 69" test "$(key RestartPreventExitStatus)" = "78 69"
check "the unit is not enabled" sh -c "! find '$root/etc/systemd' -name imucald.service 2>/dev/null | grep -q ."

# What the maintainer scripts did.
check "postinst: user imucal (sysusers.d)" grep -q '^imucal:x:[0-9]*:[0-9]*:' "$root/etc/passwd"
check "postinst: imucal in group video" grep -q '^video:x:[0-9]*:.*imucal' "$root/etc/group"
if [ "$(id -u)" = 0 ]; then
  uid=$(sed -n 's/^imucal:x:\([0-9]*\):.*/\1/p' "$root/etc/passwd")
  check "postinst: $state made and owned by imucal (tmpfiles.d)" test "$(stat -c %u:%a "$root$state" 2>/dev/null)" = "$uid:750"
fi

# The installed service reads the installed configuration.
unset IMUCAL_MODULE_DIR
if "$root$program" --config "$root$config" --state-dir "$tmp/state" --check --devices-may-appear-later \
  >"$tmp/check.log" 2>&1; then
  echo "ok: $program --config $config --check --devices-may-appear-later"
  sed 's/^/  /' "$tmp/check.log"
else
  echo "FAIL: $program --config $config --check exited $?:"
  cat "$tmp/check.log"
  fail=1
fi
check "--check --sim loads the package's virtual rig" sh -c \
  "'$root$program' --config '$root$config' --state-dir '$tmp/state' --sim --check | grep -q 'imucal_virtual_rig: loaded'"
sed 's/^imu:/imu:\n  not_a_key: 1/' "$root$config" >"$tmp/broken.yaml"
"$root$program" --config "$tmp/broken.yaml" --check >"$tmp/broken.log" 2>&1
rc=$?
check "--check on a broken configuration exits 78 and names the file" \
  sh -c "[ $rc = 78 ] && grep -q 'Edit $tmp/broken.yaml' '$tmp/broken.log'"

# Every subcommand of the programs is in their man page.
for p in imucal imucalctl; do
  page=$(find "$root/usr/share/man" -name "$p.*.gz")
  for c in $("$root/usr/bin/$p" --help 2>/dev/null | awk '/^Subcommands:/ { on = 1; next } on && /^  [a-z]/ { print $1 } /^$/ { on = 0 }'); do
    zcat "$page" | grep -q "^\.SS \"$p $c\"" || { echo "FAIL: $p $c is not in $page"; fail=1; }
  done
done

if ! command -v lintian >/dev/null 2>&1; then
  echo "SKIP: lintian is not installed (apt-get install lintian); the other checks ran"
  [ "$fail" = 0 ] && exit 77
  exit 1
fi
# As root lintian says so on stderr; the tags go to stdout.
# shellcheck disable=SC2086
lintian --no-tag-display-limit "$deb" $backends >"$tmp/lintian.log" 2>"$tmp/lintian.err"
errors=$(grep -c '^E:' "$tmp/lintian.log")
warnings=$(grep -c '^W:' "$tmp/lintian.log")
echo "lintian: $errors errors, $warnings warnings"
grep '^[EW]:' "$tmp/lintian.log" | sed 's/^/  /'
[ "$errors" = 0 ] || fail=1
exit $fail
