#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Builds a kernel module that the Debian kernel does not ship (its option is unset) as an
# out-of-tree module: the driver's source from Debian's linux-source-<major.minor> package,
# compiled against the linux-headers (kbuild) of the exact kernel that run-in-qemu.sh boots.
# run-in-qemu.sh calls it for a --module the kernel lacks and caches the result per kernel
# version and version of this script; by hand:
#
#   build-kmod.sh --knows NAME              exit 0 when NAME has a recipe here
#   build-kmod.sh NAME KVER WORKDIR OUT.ko  build NAME for kernel KVER (e.g. 6.1.0-56-amd64)
#
# The packages are fetched with `apt-get download` into WORKDIR (no install, no root once the
# apt lists know them) and WORKDIR is left for the caller to remove.
#
# Exit status: 0 built; 77 the packages or the host tools cannot be had (the reason on stderr,
# run-in-qemu.sh turns it into a skip); 1 the build itself failed (its log on stderr).
#
# Recipes:
#   gpio-sim  drivers/gpio/gpio-sim.c (CONFIG_GPIO_SIM) with drivers/gpio/gpiolib.h, the
#             gpiolib-internal header it includes, and kernel/irq/irq_sim.c (CONFIG_IRQ_SIM,
#             a bool only selected by GPIO_SIM/GPIO_MOCKUP, so also unset on Debian) linked into
#             the same module with its exports dropped. irq_sim.c calls
#             handle_simple_irq(irq_to_desc(irq)); irq_to_desc is not exported to modules
#             (since Linux 5.11), so that call becomes generic_handle_irq(irq), which runs the
#             same handler (irq_sim maps every interrupt with handle_simple_irq). Needs configfs
#             (a module on Debian, found by modprobe through the module's depends).
#   vimc      drivers/media/test-drivers/vimc/ (CONFIG_VIDEO_VIMC), the virtual media-controller
#             camera (sensors -> debayers -> scaler -> capture: /dev/media0, /dev/video0..2,
#             /dev/v4l-subdev0..7), built with its own Makefile's object list. All it needs is
#             in Debian's kernel: CONFIG_MEDIA_CONTROLLER and CONFIG_VIDEO_V4L2_SUBDEV_API are
#             on (built into the mc and videodev modules), videobuf2-vmalloc and v4l2-tpg are
#             modules (vivid uses them too), find_font() of CONFIG_FONT_SUPPORT is built in;
#             their symbols are in the headers' Module.symvers, so modprobe loads them through
#             vimc's depends.
set -euo pipefail

SKIP=77
skip() { echo "build-kmod: $*" >&2; exit $SKIP; }
fail() { echo "build-kmod: $*" >&2; exit 1; }

recipes="gpio-sim vimc imucal-irq-i2c"
if [ "${1:-}" = "--knows" ]; then
  for r in $recipes; do [ "$r" = "${2:-}" ] && exit 0; done
  exit 1
fi
[ $# -eq 4 ] || fail "usage: build-kmod.sh NAME KVER WORKDIR OUT.ko (or --knows NAME)"
name=$1 kver=$2 work=$3 out=$4
case " $recipes " in *" $name "*) ;; *) fail "no recipe for '$name' (known: $recipes)" ;; esac
here=$(cd "$(dirname "$0")" && pwd)
# Recipes of this project's own modules need only the headers, not the kernel's source.
needs_source=1
[ "$name" = imucal-irq-i2c ] && needs_source=0

export PATH="$PATH:/usr/sbin:/sbin"
for tool in apt-get apt-cache dpkg tar xz make; do
  command -v "$tool" >/dev/null 2>&1 ||
    skip "'$tool' not found; building $name needs apt, dpkg, xz-utils and make (build-essential)"
done

# --- packages ---------------------------------------------------------------------------------
# The headers of exactly this kernel (their version is the kernel package's), the common
# headers and kbuild tools they depend on, and the kernel source of the same Debian version
# when the archive still has it.
series=$(echo "$kver" | cut -d. -f1,2)  # 6.1
headers=linux-headers-$kver
version_of() { { apt-cache show "$1" 2>/dev/null || true; } | sed -n 's/^Version: //p' | sort -V | tail -n 1; }
hver=$(version_of "$headers")
if [ -z "$hver" ]; then
  echo "build-kmod: $headers is not in the apt lists; running apt-get update" >&2
  apt-get update -qq >&2 2>&1 || true
  hver=$(version_of "$headers")
fi
[ -n "$hver" ] ||
  skip "$headers is not available from apt (no network, no Debian bookworm sources, or the archive no longer has kernel $kver: delete it from the QEMU cache to use the newest)"
common=$(apt-cache show "$headers=$hver" | sed -n 's/^Depends: //p' | tr ',' '\n' |
  sed -n 's/^ *\(linux-headers-[^ ]*-common\) .*/\1/p' | head -n 1)
kbuild=linux-kbuild-$series
source=linux-source-$series
[ -n "$common" ] || fail "cannot find the common headers package in the dependencies of $headers"
source_spec="$source=$hver" sver=$hver
if [ "$needs_source" = 0 ]; then
  source_spec="" sver="(not needed)"
elif [ -z "$(apt-cache show "$source_spec" 2>/dev/null)" ]; then
  sver=$(version_of "$source")
  [ -n "$sver" ] || skip "$source is not available from apt"
  source_spec="$source=$sver"
  echo "build-kmod: $source $hver is no longer in the archive; using $sver" >&2
fi

mkdir -p "$work/deb" "$work/root" "$work/src" "$work/build"
echo "build-kmod: fetching $headers, $common, $kbuild ${source_spec:+and $source_spec }to build $name for $kver (once)" >&2
# shellcheck disable=SC2086 # an empty source_spec is no argument
(cd "$work/deb" && apt-get download "$headers=$hver" "$common=$hver" "$kbuild" ${source_spec} >&2 2>&1) ||
  skip "apt-get download of $headers, $common, $kbuild, $source_spec failed (no network or no Debian bookworm apt sources?)"
for deb in "$work"/deb/*.deb; do
  dpkg -x "$deb" "$work/root" || fail "dpkg -x $deb failed"
done
rm -rf "$work/deb"

kdir=$work/root/usr/src/$headers
[ -f "$kdir/Makefile" ] || fail "$headers has no $kdir/Makefile"
# The arch headers' Makefile includes the common one by its installed path; point it here.
sed -i "s|^include /usr/src/|include $work/root/usr/src/|" "$kdir/Makefile"
cc=$(sed -n 's/^CC = .*)\(gcc-[0-9]*\)$/\1/p' "$kdir/.kernelvariables" 2>/dev/null || true)
cc=${cc:-gcc}
command -v "$cc" >/dev/null 2>&1 ||
  skip "$cc not found: the kernel was built with it and modules must be too (install the Debian package '$cc')"
tarball=$(ls "$work"/root/usr/src/linux-source-*.tar.xz 2>/dev/null | head -n 1 || true)
[ -n "$tarball" ] || [ "$needs_source" = 0 ] || fail "no kernel source tarball in $source"
top=$(basename "${tarball:-none}" .tar.xz)

# --- recipe -----------------------------------------------------------------------------------
b=$work/build
case "$name" in
  gpio-sim)
    tar -xJf "$tarball" -C "$work/src" "$top/drivers/gpio/gpio-sim.c" "$top/drivers/gpio/gpiolib.h" \
      "$top/kernel/irq/irq_sim.c" || fail "gpio-sim sources not found in $tarball"
    s=$work/src/$top
    cp "$s/drivers/gpio/gpio-sim.c" "$b/gpio-sim-main.c"
    cp "$s/drivers/gpio/gpiolib.h" "$b/gpiolib.h"
    sed -e '/^EXPORT_SYMBOL/d' \
      -e 's/handle_simple_irq(irq_to_desc(irqnum));/generic_handle_irq(irqnum);/' \
      "$s/kernel/irq/irq_sim.c" >"$b/irq_sim.c"
    grep -q 'generic_handle_irq(irqnum);' "$b/irq_sim.c" ||
      fail "kernel/irq/irq_sim.c of $top no longer has the irq_to_desc() call this recipe replaces"
    printf 'obj-m := gpio-sim.o\ngpio-sim-y := gpio-sim-main.o irq_sim.o\n' >"$b/Kbuild"
    ;;
  vimc)
    d=drivers/media/test-drivers/vimc
    tar -xJf "$tarball" -C "$work/src" "$top/$d" || fail "vimc sources ($d) not found in $tarball"
    cp "$work/src/$top/$d"/*.[ch] "$b/"
    # The driver's Makefile lists its objects under obj-$(CONFIG_VIDEO_VIMC); build it as a module.
    # shellcheck disable=SC2016  # a literal $(...) of make, not a shell expansion
    sed 's/\$(CONFIG_VIDEO_VIMC)/m/' "$work/src/$top/$d/Makefile" >"$b/Kbuild"
    grep -q '^obj-m += vimc.o' "$b/Kbuild" ||
      fail "the vimc Makefile of $top no longer has obj-\$(CONFIG_VIDEO_VIMC) += vimc.o"
    ;;
  imucal-irq-i2c)
    cp "$here/kmod/imucal_irq_i2c.c" "$b/" || fail "tests/qemu/kmod/imucal_irq_i2c.c not found"
    printf 'obj-m := imucal-irq-i2c.o\nimucal-irq-i2c-y := imucal_irq_i2c.o\n' >"$b/Kbuild"
    ;;
esac

if ! make -C "$kdir" M="$b" modules >"$work/build.log" 2>&1; then
  tail -n 30 "$work/build.log" >&2
  fail "building $name against $headers failed (log above)"
fi
[ -f "$b/$name.ko" ] || fail "the build made no $name.ko"
cp "$b/$name.ko" "$out.tmp" && mv "$out.tmp" "$out"
echo "build-kmod: built $name for $kver ($headers $hver)${source_spec:+ from $source $sver}" >&2
