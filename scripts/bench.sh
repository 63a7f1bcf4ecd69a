#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Runs every benchmark binary of a build tree (Google Benchmark or bench commands) and prints
# their figures. Usage: scripts/bench.sh [BUILD_DIR]   (make bench does this)
set -euo pipefail
dir=${1:-build/bench}
shopt -s nullglob
for b in "$dir"/tests/bench_*; do
  [ -x "$b" ] || continue
  echo "=== $(basename "$b")"
  "$b"
done
echo "=== program start (scripts/bench-startup.sh)"
"$(dirname "$0")/bench-startup.sh" "$dir/daemon/imucal"
echo "=== static calibration end to end (scripts/bench-static-e2e.sh)"
"$(dirname "$0")/bench-static-e2e.sh" "$dir/daemon/imucal"
echo "=== ROS bags out and in (scripts/bench-bags.sh)"
"$(dirname "$0")/bench-bags.sh" "$dir"
