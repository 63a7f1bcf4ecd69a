#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Program start: wall time, peak resident memory and shared-library count of `imucal --version`
# and of a whole static calibration of the committed fixture, as a user runs them.
# Usage: scripts/bench-startup.sh [IMUCAL] [RUNS]    (default build/release/daemon/imucal, 20 runs)
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
IMUCAL=${1:-$root/build/release/daemon/imucal}
RUNS=${2:-20}
[ -x "$IMUCAL" ] || { echo "bench-startup: $IMUCAL not found; build it first (make build)" >&2; exit 1; }
command -v /usr/bin/time >/dev/null || { echo "bench-startup: needs /usr/bin/time (apt-get install time)" >&2; exit 1; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# measure LABEL CMD...: median wall time and median peak RSS over RUNS runs.
measure() {
  local label=$1
  shift
  : > "$tmp/t"
  for _ in $(seq "$RUNS"); do
    /usr/bin/time -f "%e %M" -a -o "$tmp/t" "$@" > /dev/null 2>&1
  done
  local mid=$(((RUNS + 1) / 2)) t rss
  t=$(cut -d' ' -f1 "$tmp/t" | sort -n | sed -n "${mid}p")
  rss=$(cut -d' ' -f2 "$tmp/t" | sort -n | sed -n "${mid}p")
  awk -v label="$label" -v t="$t" -v rss="$rss" \
    'BEGIN { printf "%-48s median wall %6.3f s   median peak RSS %6.1f MB\n", label, t, rss / 1024 }'
}

echo "binary: $IMUCAL"
libs=$(ldd "$IMUCAL")
echo "shared libraries loaded (ldd): $(wc -l <<< "$libs")"
heavy=$(grep -ciE 'gdal|poppler|hdf5' <<< "$libs" || true)
echo "  of which GDAL, poppler or HDF5: $heavy"
measure "imucal --version" "$IMUCAL" --version
measure "imucal calibrate static fixtures/static.imulog" \
  "$IMUCAL" calibrate static "$root/fixtures/static.imulog" --force -o "$tmp/r.yaml"
