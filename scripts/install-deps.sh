#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Installs the Debian 12 packages imucal needs, only those missing; fast when all are present.
#   scripts/install-deps.sh          build + run (make demo)
#   scripts/install-deps.sh --test   also the test tools (GoogleTest, QEMU for device tests, ...)
set -euo pipefail

build_pkgs=(
  build-essential cmake ninja-build pkg-config ccache time
  libeigen3-dev libceres-dev
  libopencv-core-dev libopencv-imgproc-dev libopencv-imgcodecs-dev libopencv-calib3d-dev
  libboost-dev libgpiod-dev libpng-dev libwebp-dev libbz2-dev liblz4-dev libzstd-dev libsqlite3-dev sqlite3 zlib1g-dev libyaml-cpp-dev nlohmann-json3-dev
  libspdlog-dev libfmt-dev libcli11-dev libsystemd-dev
  libaravis-dev libusb-1.0-0-dev libcamera-dev libapriltag-dev
  gnuplot-nox
  dpkg-dev help2man
  libgtest-dev libgmock-dev libbenchmark-dev
)
test_pkgs=(
  clang-format
  qemu-system-x86 busybox-static cpio kmod
  libcamera-ipa  # libcamera's vimc IPA module for qemu.libcamera
  chromium
  tmux systemd
  lintian
  python3  # tests/check_layering.py (layering.rules)
  python3-rosbag python3-sensor-msgs python3-roslz4  # ROS's own bag writer and reader, for rosbag.python_bags
  python3-lz4 python3-zstandard  # a second writer of rosbag2 mcap chunks, for rosbag.python_bags
)

want=("${build_pkgs[@]}")
if [ "${1:-}" = "--test" ]; then
  want+=("${test_pkgs[@]}")
fi

missing=()
for p in "${want[@]}"; do
  status=$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null || true)
  [ "$status" = "install ok installed" ] || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0

echo "install-deps: installing ${missing[*]}"
SUDO=""
if [ "$(id -u)" != 0 ]; then
  command -v sudo >/dev/null || { echo "install-deps: need root or sudo to install: ${missing[*]}" >&2; exit 1; }
  SUDO=sudo
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
