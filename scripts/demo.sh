#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# The main job on the built-in simulated rig: the service imucald runs a whole guided session on
# the virtual rig (the MPU-6000 emulator behind the real driver and acquisition), with a scripted
# operator who turns the rig as the prompts ask (1.5 s per pose change), moves it in front of the
# virtual camera's target and presses the keys, on accelerated time. The calibration is written to
# a file-backed EEPROM image and read back with `imucal store read`; the session is replayed from
# its log, with no devices, to the same result; the last thing shown is the table of every
# estimated quantity beside the virtual rig's truth (sim-truth.txt in the session folder).
# The programs' full output goes to files in OUTPUT_DIR; the terminal gets one line per step.
# Usage: scripts/demo.sh [BUILD_DIR] [OUTPUT_DIR]
set -euo pipefail
BUILD=${1:-build/release}
OUT=$(realpath -m "${2:-build/demo}")
IMUCAL="$BUILD/daemon/imucal"
IMUCALD="$BUILD/daemon/imucald"
rm -rf "$OUT"
mkdir -p "$OUT/state"
START=$SECONDS
step() { printf '\n==> %s\n' "$*"; }
elapsed() {
  local s=$((SECONDS - START))
  printf '%d min %02d s' $((s / 60)) $((s % 60))
}
# On a failure: the end of the file that holds the output of the step that failed.
LOG=""
trap 'rc=$?; if [ $rc -ne 0 ] && [ -n "$LOG" ]; then echo "imucal demo: failed; the end of $LOG:" >&2; tail -n 20 "$LOG" >&2; fi' EXIT

# The shipped virtual rig with a stereo pair (config/rig-stereo.yaml), its calibration storage in a
# file-backed EEPROM image here.
sed -e "s|path: /var/lib/imucal/calibration.bin|path: $OUT/eeprom.bin|" config/rig-stereo.yaml >"$OUT/rig.yaml"
cp config/checkerboard-7x6.yaml "$OUT/"

echo "imucal demo: a guided calibration session of the service imucald on the virtual rig."
echo "Outputs go to $OUT/."

step "imucald: guided session on accelerated time (service log: $OUT/imucald.log)"
# The first prompt of each step, warnings and the end of the session.
LOG="$OUT/imucald.log"
"$IMUCALD" --config "$OUT/rig.yaml" --socket "$OUT/imucald.sock" --state-dir "$OUT/state" \
  --sim --sim-operator full --time-scale 0 --start default --exit-after-session 2>&1 |
  tee "$LOG" |
  awk '/^info: \[[a-z]+\]/ { s = $2; if (s != last) { last = s; sub(/^info: /, ""); print "    " $0; fflush() } next }
       /^(warning|error|critical): / || /^info: session [a-z]+: / { print "    " $0; fflush() }'
SESSION=$(ls -d "$OUT"/state/sessions/*/ | head -1)
SESSION=${SESSION%/}
echo "    session done after $(elapsed)"

step "The record on the rig's storage, read back (imucal store read: $OUT/stored-record.yaml)"
LOG="$OUT/stored-record.yaml"
"$IMUCAL" store read --config "$OUT/rig.yaml" >"$LOG" 2>&1
grep '^#' "$LOG" | sed -e 's/^# */    /'

step "Replay: the same session from its log, with no devices (imucal replay: $OUT/replay.txt)"
LOG="$OUT/replay.txt"
"$IMUCAL" replay "$SESSION/session.imulog" -o "$OUT/replay" >"$LOG" 2>&1
grep -v '^  wrote ' "$LOG" | sed -e 's/^/    /'
LOG=""

step "Every estimated quantity beside the virtual rig's truth ($SESSION/sim-truth.txt)"
cat "$SESSION/sim-truth.txt"

step "Done in $(elapsed)"
echo "Session folder: $SESSION/ (session.imulog, motion.imulog, imu-static.yaml, camimu/)"
echo "Reports:        $SESSION/report.html (the IMU), $SESSION/report-camimu.html (the cameras and the camera-IMU calibration)"
echo "Storage image:  $OUT/eeprom.bin"
echo "Watch a session in a web browser (the live view; Ctrl-C ends it):"
echo "  $IMUCALD --config $OUT/rig.yaml --socket /tmp/imucald.sock --state-dir /tmp/imucal-state \\"
echo "    --sim --sim-operator full --time-scale 1 --start default --live-view 8421"
echo "  then open http://127.0.0.1:8421/"
