#!/usr/bin/env bash
# The main job on the built-in simulated rig: the service imucald runs a whole guided session on
# the virtual rig (the MPU-6000 emulator behind the real driver and acquisition), with a scripted
# operator who turns the rig as the prompts ask (1.5 s per pose change), moves it in front of the
# virtual camera's target and presses the keys, on accelerated time. The calibration is written to a file-backed EEPROM image, read back with
# `imucal store read`, and shown beside the simulator's truth. Then the session is replayed from
# its log, with no devices, to the same result.
# Usage: scripts/demo.sh [BUILD_DIR] [OUTPUT_DIR]
set -euo pipefail
BUILD=${1:-build/release}
OUT=$(realpath -m "${2:-build/demo}")
IMUCAL="$BUILD/daemon/imucal"
IMUCALD="$BUILD/daemon/imucald"
rm -rf "$OUT"
mkdir -p "$OUT/state"
step() { printf '\n==> %s\n' "$*"; }

# The shipped virtual rig, with its calibration storage in a file-backed EEPROM image here.
sed -e "s|path: /var/lib/imucal/calibration.bin|path: $OUT/eeprom.bin|" config/rig.yaml >"$OUT/rig.yaml"
cp config/checkerboard-7x6.yaml "$OUT/"

echo "imucal demo: a guided calibration session of the service on the virtual rig."
echo "Outputs go to $OUT/."

step "imucald: guided session (preflight, warm-up, still start, poses, motion, solve, review, write) on accelerated time"
"$IMUCALD" --config "$OUT/rig.yaml" --socket "$OUT/imucald.sock" --state-dir "$OUT/state" \
  --sim --sim-operator full --time-scale 0 --start default --exit-after-session
SESSION=$(ls -d "$OUT"/state/sessions/*/ | head -1)

step "The record on the rig's storage, read back"
"$IMUCAL" store read --config "$OUT/rig.yaml"

step "The result beside the virtual rig's truth"
cat "$SESSION/sim-truth.txt"

step "Replay: the same session from its log, with no devices"
"$IMUCAL" replay "$SESSION/session.imulog" -o "$OUT/replay"

step "Done"
echo "Session folder: $SESSION (session.imulog, motion.imulog, imu-static.yaml, camimu/, report.html)"
echo "Storage image:  $OUT/eeprom.bin"
