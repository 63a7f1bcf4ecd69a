#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# ROS bags in and out (docs/benchmarks.md, "ROS bags"): the camera-IMU fixture (60 s: 11,820 IMU
# samples, 1200 frames of 376 x 240) exported as a ROS 1 bag with each chunk compression, then
# imported again; wall time, CPU time and peak memory of each, and the bag's size.
# Usage: scripts/bench-bags.sh [BUILD_DIR] [LOG]   (default build/release, fixtures/camimu.imulog)
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
BUILD=${1:-$root/build/release}
LOG=${2:-$root/fixtures/camimu.imulog}
IMUCAL=$BUILD/daemon/imucal
[ -x "$IMUCAL" ] || { echo "bench-bags: $IMUCAL not found; build it first (make build)" >&2; exit 1; }
command -v /usr/bin/time >/dev/null || { echo "bench-bags: needs /usr/bin/time (apt-get install time)" >&2; exit 1; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# Runs a command under /usr/bin/time; prints "wall s, CPU s, peak RSS MB".
measure() {
  /usr/bin/time -f "%e %U %S %M" -o "$tmp/time" "$@" > /dev/null 2> "$tmp/err" || {
    cat "$tmp/err" >&2
    exit 1
  }
  read -r wall user sys rss < <(tail -n 1 "$tmp/time")
  awk -v w="$wall" -v u="$user" -v s="$sys" -v r="$rss" 'BEGIN { printf "%5.2f s wall, %5.2f s CPU, %4d MB", w, u + s, r / 1024 }'
}

echo "binaries: $BUILD; log: $LOG ($(($(stat -c %s "$LOG") / 1048576)) MB)"
printf "%-12s %-44s %-44s %s\n" compression "export bag" "import bag" "bag size"
for c in none lz4 bz2; do
  bag=$tmp/$c.bag
  out=$(measure "$IMUCAL" export bag "$LOG" "$bag" --compression "$c")
  in=$(measure "$IMUCAL" import bag "$bag" -o "$tmp/$c.imulog")
  printf "%-12s %-44s %-44s %d MB\n" "$c" "$out" "$in" $(($(stat -c %s "$bag") / 1048576))
  rm -f "$bag" "$tmp/$c.imulog"
done
