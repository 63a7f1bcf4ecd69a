#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Regenerates the fixture logs in fixtures/ and their ground truth with the built imucal:
#   scripts/make-fixtures.sh [IMUCAL]      (default build/release/daemon/imucal)
#   SKIP_CAMIMU=1 scripts/make-fixtures.sh  leaves camimu.imulog alone (it takes longest)
# Every sample goes through the MPU-6000 register emulator, the driver and the acquisition loop
# (docs/simulator.md). The samples, events and truth files are deterministic (fixed seeds); only
# the log's created_utc metadata differs between runs. fixtures/README.md lists what each one is for.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
IMUCAL=${1:-$root/build/release/daemon/imucal}
out=$root/fixtures
[ -x "$IMUCAL" ] || { echo "make-fixtures: $IMUCAL not found or not executable; build it first (make build)" >&2; exit 1; }
mkdir -p "$out"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

sim() { echo "+ imucal sim $*"; "$IMUCAL" sim "$@" --force; }

# Multi-position static protocol (Tedaldi et al.): 50 s still + 36 poses held 1-4 s, 100 Hz,
# at the MPU-6000 power-on ranges (+-2 g, +-250 deg/s).
sim static --seed 101 --poses 36 --still 50 --imu-rate 100 --accel-range 2 --gyro-range 250 \
  -o "$out/static.imulog"

# Six faces up, 30 s each, for the gyroscope g-sensitivity (Krebs 5.2.3).
sim gsens --seed 102 --hold 30 --imu-rate 100 --accel-range 2 --gyro-range 250 -o "$out/gsens.imulog"

# Ten minutes on a table, 100 Hz, for the Allan variance.
sim still --seed 103 --duration 600 --imu-rate 100 --accel-range 2 --gyro-range 250 -o "$out/still.imulog"

# Camera-IMU session (checkerboard motion with rendered frames), when this build has it.
if [ -n "${SKIP_CAMIMU:-}" ]; then
  echo "make-fixtures: SKIP_CAMIMU set; camimu.imulog not regenerated"
elif "$IMUCAL" sim camimu --help >/dev/null 2>&1; then
  sim camimu --seed 104 -o "$out/camimu.imulog"
else
  echo "make-fixtures: this imucal has no 'sim camimu'; camimu.imulog not regenerated" >&2
fi

# Broken logs.
# Truncated: a complete short static session cut at a byte offset inside its sample pages.
sim static --seed 105 --poses 12 --still 20 --accel-range 2 --gyro-range 250 -o "$tmp/whole.imulog"
size=$(stat -c %s "$tmp/whole.imulog")
cut=$((size * 6 / 10 + 123))
head -c "$cut" "$tmp/whole.imulog" > "$out/broken-truncated.imulog"
cp "$tmp/whole.truth.yaml" "$out/broken-truncated.truth.yaml"
echo "+ cut $size bytes to $cut -> broken-truncated.imulog"

# Gap: the host stops reading the chip for 2.5 s during the poses and for 1 s in the still
# period. The FIFO holds 0.73 s at 100 Hz; the driver finds it overflowed, resets it, and the
# first sample after each gap carries the gap flag. Enough poses remain for a calibration with
# a warning.
sim static --seed 106 --poses 40 --still 50 --accel-range 2 --gyro-range 250 \
  --drop 100:2.5 --drop 20:1 -o "$out/broken-gap.imulog"

# Saturated: fast moves beyond +-2 g and +-250 deg/s.
sim static --seed 107 --poses 40 --still 50 --accel-range 2 --gyro-range 250 --excitation 4 \
  -o "$out/broken-saturated.imulog"

# A whole guided session of the service on the virtual rig (docs/service-session.md), with the
# scripted operator's keys in its events: `imucal replay` must reach the result it logged. The
# motion step is left out: its frames would make the fixture tens of MB (the tests run it live).
IMUCALD=$(dirname "$IMUCAL")/imucald
echo "+ imucald --sim --sim-operator full --seed 108 (guided session)"
sed -e "s|path: /var/lib/imucal/calibration.bin|path: $tmp/eeprom.bin|" -e "s|^target: .*|target: $root/config/checkerboard-7x6.yaml|" \
  "$root/config/rig.yaml" >"$tmp/rig.yaml"
"$IMUCALD" --config "$tmp/rig.yaml" --socket "$tmp/imucald.sock" --state-dir "$tmp/state" --sim --sim-operator full \
  --seed 108 --time-scale 0 --start preflight,warmup,still,poses,solve,review,write --exit-after-session -q
cp "$tmp"/state/sessions/*/session.imulog "$out/service-session.imulog"

leftovers=$(find "$out" -name '*-wal' -o -name '*-shm' -o -name '*-journal' -o -name '*.tmp')
if [ -n "$leftovers" ]; then
  echo "make-fixtures: leftover files beside the fixtures:" >&2
  echo "$leftovers" >&2
  exit 1
fi
du -ch "$out"/*.imulog | tail -1
