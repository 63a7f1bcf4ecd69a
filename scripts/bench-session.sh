#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Operator time of the guided session on the virtual rig (docs/benchmarks.md, "Guided session"):
# imucald runs whole sessions with the scripted operator (0.8 s reaction, 1.5 s per pose change)
# for several seeds, and `imucal replay` reads each log back: rig time per step, first prompt to
# review, and the wall time of the final solve.
#   scripts/bench-session.sh [BUILD_DIR] [SEEDS]
set -euo pipefail
BUILD=${1:-build/release}
SEEDS=${2:-5}
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for seed in $(seq 1 "$SEEDS"); do
  dir="$tmp/$seed"
  mkdir -p "$dir"
  sed -e "s|path: /var/lib/imucal/calibration.bin|path: $dir/eeprom.bin|" \
    -e "s|^target: .*|target: $root/config/checkerboard-7x6.yaml|" "$root/config/rig.yaml" >"$dir/rig.yaml"
  "$BUILD/daemon/imucald" --config "$dir/rig.yaml" --socket "$dir/s.sock" --state-dir "$dir/state" --sim \
    --sim-operator full --seed "$seed" --time-scale 0 --start default --exit-after-session -q
  printf 'seed %s: ' "$seed"
  "$BUILD/daemon/imucal" replay "$dir"/state/sessions/*/session.imulog -o "$dir/replay" | grep "rig time per step"
done
