#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Runs one command on the Debian 6.1 kernel under QEMU (TCG), with kernel modules loaded, so
# that device tests meet real kernel drivers (i2c-stub + i2c-dev, vivid, at24) on a machine
# that has none of them. The guest's root is the host's root, shared read-only over 9p; the
# command runs with `chroot` into it, so host binaries (build outputs included) run unchanged.
#
#   run-in-qemu.sh [--module "NAME [PARAM=VALUE ...]"]... [--timeout SECONDS] [--cwd DIR] -- CMD [ARG...]
#
# A --module the kernel does not have but tests/qemu/build-kmod.sh has a recipe for (gpio-sim,
# vimc, and this project's test module imucal-irq-i2c) is built once per kernel version out of
# tree (from Debian's linux-source, or from tests/qemu/kmod/) against the kernel's
# linux-headers, cached beside the kernel and installed into its module tree; configfs is
# mounted at /sys/kernel/config in the guest whenever it is loaded.
#
# Exit status: the command's own exit status when it ran in the guest;
#   77  the harness cannot run here (no QEMU, busybox-static, cpio or kmod; the kernel package,
#       or the packages an out-of-tree module is built from, cannot be fetched) -- reported as
#       a skip by ctest (SKIP_RETURN_CODE 77);
#   124 the guest did not finish within the timeout;
#   125 the guest booted but the command's exit marker never appeared (a module failed to
#       load, the 9p root could not be mounted, the kernel panicked: see the console log).
#
# Environment:
#   IMUCAL_QEMU_CACHE    cache for the kernel package and the modules built for it
#                        (default ~/.cache/imucal/qemu)
#   IMUCAL_QEMU_KERNEL   kernel package name to use instead of the newest linux-image-6.1.0-*-amd64
#   IMUCAL_QEMU_VERBOSE  1: show the whole console output, not only the command's output
set -euo pipefail

SKIP=77
skip() { echo "SKIP: $*" >&2; exit $SKIP; }
die() { echo "run-in-qemu: $*" >&2; exit 125; }

modules=()
timeout_s=300
cwd=$(pwd)
while [ $# -gt 0 ]; do
  case "$1" in
    --module) modules+=("$2"); shift 2 ;;
    --timeout) timeout_s=$2; shift 2 ;;
    --cwd) cwd=$2; shift 2 ;;
    --) shift; break ;;
    -h|--help) sed -n '3,/^set -euo/{/^set -euo/!p}' "$0"; exit 0 ;;
    *) die "unknown option '$1' (see --help)" ;;
  esac
done
[ $# -gt 0 ] || die "no command given (usage: run-in-qemu.sh [--module M]... -- CMD [ARG...])"

# --- host tools -------------------------------------------------------------------------------
need_pkg() {  # need_pkg PROGRAM PACKAGE
  command -v "$1" >/dev/null 2>&1 || [ -x "$1" ] ||
    skip "$1 not found; install the Debian package '$2' (scripts/install-deps.sh --test)"
}
export PATH="$PATH:/usr/sbin:/sbin"
need_pkg qemu-system-x86_64 qemu-system-x86
need_pkg cpio cpio
need_pkg depmod kmod
need_pkg modprobe kmod
need_pkg timeout coreutils
need_pkg flock util-linux
need_pkg gzip gzip
busybox=""
for b in /bin/busybox /usr/bin/busybox; do
  if [ -x "$b" ] && ! ldd "$b" >/dev/null 2>&1; then busybox=$b; break; fi
done
[ -n "$busybox" ] || skip "no statically linked busybox; install the Debian package 'busybox-static'"

# --- kernel package: fetched once into the cache ----------------------------------------------
cache=${IMUCAL_QEMU_CACHE:-${HOME:-/tmp}/.cache/imucal/qemu}
mkdir -p "$cache" || skip "cannot create the cache directory $cache (set IMUCAL_QEMU_CACHE)"

newest_kernel_pkg() {
  apt-cache search --names-only '^linux-image-6\.1\.0-[0-9]+-amd64$' 2>/dev/null |
    awk '{print $1}' | sort -V | tail -n 1
}

fetch_kernel() {  # prints the unpacked tree's path; runs under the cache lock
  local pkg=${IMUCAL_QEMU_KERNEL:-}
  if [ -z "$pkg" ]; then
    # Reuse an unpacked kernel when there is one: no network needed after the first run.
    local have
    have=$(find "$cache" -maxdepth 1 -type d -name 'linux-image-6.1.0-*-amd64' -printf '%f\n' 2>/dev/null |
      sort -V | tail -n 1)
    if [ -n "$have" ] && [ -f "$cache/$have/.ready" ]; then echo "$cache/$have"; return 0; fi
    pkg=$(newest_kernel_pkg)
    if [ -z "$pkg" ]; then
      echo "run-in-qemu: no linux-image-6.1.0-*-amd64 in the apt lists; running apt-get update" >&2
      apt-get update -qq >&2 2>&1 || true
      pkg=$(newest_kernel_pkg)
    fi
    [ -n "$pkg" ] || return 1
  fi
  local tree=$cache/$pkg
  if [ ! -f "$tree/.ready" ]; then
    echo "run-in-qemu: fetching $pkg into $cache (once)" >&2
    rm -rf "$tree" "$cache"/dl && mkdir -p "$cache/dl"
    if ! (cd "$cache/dl" && apt-get download "$pkg" >&2 2>&1) ||
       ! dpkg -x "$cache"/dl/"${pkg}"_*.deb "$tree"; then
      rm -rf "$tree" "$cache/dl"
      return 1
    fi
    rm -rf "$cache/dl"
    local kver
    kver=$(ls "$tree/lib/modules" | head -n 1)
    depmod -b "$tree" "$kver" || return 1
    touch "$tree/.ready"
  fi
  echo "$tree"
}

exec 9>"$cache/.lock"
flock 9
tree=$(fetch_kernel) || skip "the kernel package ${IMUCAL_QEMU_KERNEL:-linux-image-6.1.0-*-amd64} cannot be fetched (apt-get download failed: no network or no Debian bookworm apt sources?)"
flock -u 9
kver=$(ls "$tree/lib/modules" | head -n 1)
vmlinuz="$tree/boot/vmlinuz-$kver"
[ -f "$vmlinuz" ] || die "no kernel image at $vmlinuz (delete $tree and retry)"

# --- modules the kernel lacks: built out of tree, once per kernel version ---------------------
# Cached as $cache/kmod/<kernel version>/NAME.ko with the build script's checksum beside it (a
# changed recipe builds again), and installed into the kernel's tree under extra/ so that
# modprobe finds it and its dependencies like any other module.
here=$(cd "$(dirname "$0")" && pwd)
ensure_module() {  # ensure_module NAME; runs under the cache lock
  local name=$1
  "$here/build-kmod.sh" --knows "$name" || return 0  # the kernel's own: add_module finds it
  local extra=$tree/lib/modules/$kver/extra/$name.ko
  # A kernel that ships the module needs no build.
  if [ ! -f "$extra" ] && modprobe -d "$tree" -S "$kver" --show-depends "$name" >/dev/null 2>&1; then
    return 0
  fi
  local dir=$cache/kmod/$kver ko recipe
  ko=$dir/$name.ko
  # The recipe's key: the build script, and the project's own module source when there is one.
  recipe=$(cat "$here/build-kmod.sh" "$here"/kmod/"${name//-/_}".c 2>/dev/null | sha256sum | cut -d' ' -f1)
  if [ ! -f "$ko" ] || [ "$(cat "$ko.recipe" 2>/dev/null)" != "$recipe" ]; then
    mkdir -p "$dir"
    local bwork status=0
    bwork=$(mktemp -d "$cache/kmod-build.XXXXXX")
    "$here/build-kmod.sh" "$name" "$kver" "$bwork" "$ko" || status=$?
    rm -rf "$bwork"
    [ "$status" = 0 ] || return "$status"
    echo "$recipe" >"$ko.recipe"
  fi
  if ! cmp -s "$ko" "$extra"; then
    mkdir -p "$(dirname "$extra")" && cp "$ko" "$extra" && depmod -b "$tree" "$kver" || return 1
  fi
}
for spec in "${modules[@]}"; do
  name=${spec%% *}
  flock 9
  status=0
  ensure_module "$name" || status=$?
  flock -u 9
  case "$status" in
    0) ;;
    "$SKIP") skip "module $name cannot be built for kernel $kver (reason above)" ;;
    *) die "building module $name for kernel $kver failed (log above)" ;;
  esac
done

# --- initramfs --------------------------------------------------------------------------------
work=$(mktemp -d "${TMPDIR:-/tmp}/imucal-qemu.XXXXXX")
trap 'rm -rf "$work"' EXIT
root=$work/root
mkdir -p "$root"/{bin,dev,proc,sys,mnt,lib/modules}
cp "$busybox" "$root/bin/busybox"
for applet in sh mount umount mkdir chroot poweroff insmod echo cat sleep; do
  ln -s busybox "$root/bin/$applet"
done

# The 9p share of the host root first, then the requested modules; each with its dependencies
# in load order as depmod computed them (modprobe --show-depends prints "insmod PATH [PARAMS]").
load_lines=()
add_module() {  # add_module NAME [PARAMS...]
  local name=$1; shift
  local deps
  deps=$(modprobe -d "$tree" -S "$kver" --show-depends "$name" 2>&1) ||
    die "kernel $kver has no module '$name' ($deps)"
  local line path base
  while read -r line; do
    case "$line" in
      builtin*) continue ;;
      insmod*) ;;
      *) continue ;;
    esac
    path=$(echo "$line" | awk '{print $2}')
    base=$(basename "$path")
    # Only the module asked for gets the parameters; its dependencies load plain.
    local params=""
    if [ "$(basename "$base" .ko)" = "$(echo "$name" | tr - _)" ] ||
       [ "$(basename "$base" .ko)" = "$name" ]; then params="$*"; fi
    if [ ! -f "$root/lib/modules/$base" ]; then
      cp "$path" "$root/lib/modules/$base"
      load_lines+=("insmod /lib/modules/$base $params || fail 'insmod $base'")
    fi
  done <<<"$deps"
}
for m in netfs fscache 9pnet 9p virtio_ring virtio 9pnet_virtio virtio_pci_modern_dev \
         virtio_pci_legacy_dev virtio_pci; do
  add_module "$m"
done
for spec in "${modules[@]}"; do
  # shellcheck disable=SC2086
  add_module $spec
done

quote() {  # POSIX single-quoting of each argument
  local out="" a
  for a in "$@"; do out+="'${a//\'/\'\\\'\'}' "; done
  printf '%s' "$out"
}
command_line="cd $(quote "$cwd") && exec $(quote "$@")"
marker="IMUCAL_QEMU_EXIT"
# Sanitizer settings of the caller reach the guest command (ctest or a developer may set them).
sanitizer_env=""
for v in ASAN_OPTIONS UBSAN_OPTIONS LSAN_OPTIONS; do
  if [ -n "${!v:-}" ]; then sanitizer_env+="$(quote "$v=${!v}")"; fi
done

{
  echo '#!/bin/sh'
  echo "fail() { echo \"$marker=harness-error: \$*\"; poweroff -f; }"
  echo 'mount -t proc proc /proc; mount -t sysfs sysfs /sys; mount -t devtmpfs devtmpfs /dev'
  printf '%s\n' "${load_lines[@]}"
  echo 'mount -t 9p -o trans=virtio,version=9p2000.L,ro hostroot /mnt || fail "9p mount of the host root"'
  echo 'mount -t proc proc /mnt/proc && mount -t sysfs sysfs /mnt/sys && mount -t devtmpfs devtmpfs /mnt/dev || fail "proc/sys/dev mounts"'
  # configfs (gpio-sim's chips are made there) when a module brought it in.
  echo 'if [ -d /mnt/sys/kernel/config ]; then mount -t configfs configfs /mnt/sys/kernel/config || fail "configfs mount"; fi'
  # The host root is read-only; a guest tmpfs on /run (host /tmp stays visible) is the
  # command's writable scratch space, named by TMPDIR.
  echo 'mount -t tmpfs tmpfs /mnt/run && mkdir -p /mnt/run/tmp || fail "tmpfs on /run"'
  echo "echo IMUCAL_QEMU_BEGIN"
  echo "chroot /mnt /usr/bin/env -i PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin HOME=/run/tmp TMPDIR=/run/tmp IMUCAL_IN_QEMU=1 $sanitizer_env /bin/sh -c $(quote "$command_line")"
  # The marker on a line of its own, even when the command's output did not end with a newline.
  echo "status=\$?; echo; echo \"$marker=\$status\""
  echo 'poweroff -f'
} >"$root/init"
chmod +x "$root/init"
(cd "$root" && find . | cpio -o -H newc --quiet | gzip -1) >"$work/initrd.gz"

# --- boot -------------------------------------------------------------------------------------
log=$work/console.log
start_s=$(date +%s)
set +e
timeout --foreground -k 5 "$timeout_s" qemu-system-x86_64 \
  -accel tcg -cpu max -smp 1 -m 1024 -nographic -no-reboot -nic none \
  -kernel "$vmlinuz" -initrd "$work/initrd.gz" \
  -append "console=ttyS0 panic=-1 quiet loglevel=3" \
  -virtfs local,path=/,mount_tag=hostroot,security_model=none,readonly=on,multidevs=remap \
  </dev/null >"$log" 2>&1
qemu_status=$?
set -e
tr -d '\r' <"$log" >"$log.txt"
elapsed_s=$(($(date +%s) - start_s))

if [ "${IMUCAL_QEMU_VERBOSE:-0}" = 1 ]; then
  cat "$log.txt"
else
  # The command's own output: everything between the begin marker and the exit marker.
  sed -n '/IMUCAL_QEMU_BEGIN$/,/^IMUCAL_QEMU_EXIT=/p' "$log.txt" | sed '1d;$d' | sed '${/^$/d}'
fi

if [ "$qemu_status" = 124 ] || [ "$qemu_status" = 137 ]; then
  echo "run-in-qemu: the guest did not finish within ${timeout_s} s; console log:" >&2
  tail -n 40 "$log.txt" >&2
  exit 124
fi
result=$(grep -a "^$marker=" "$log.txt" | tail -n 1 | cut -d= -f2-)
case "$result" in
  ''|*[!0-9]*)
    echo "run-in-qemu: no exit status from the guest (${result:-no marker}); qemu exited $qemu_status; console log:" >&2
    tail -n 40 "$log.txt" >&2
    exit 125 ;;
esac
echo "run-in-qemu: kernel $kver, ${elapsed_s} s, command exited $result" >&2
exit "$result"
