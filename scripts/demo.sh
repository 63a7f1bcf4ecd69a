#!/usr/bin/env bash
# The main job on the built-in simulated rig, offline: record a static multi-position session on
# the virtual rig, summarise the log, calibrate the IMU, and characterise its noise from a still
# recording. The guided on-rig session (imucald) will replace the recording step.
# Usage: scripts/demo.sh [IMUCAL_BINARY] [OUTPUT_DIR]
set -euo pipefail
IMUCAL=${1:-build/release/daemon/imucal}
OUT=${2:-build/demo}
mkdir -p "$OUT"
step() { printf '\n==> %s\n' "$*"; }

echo "imucal demo on the simulated rig (offline flow: sim -> info -> calibrate static -> allan)."
echo "Outputs go to $OUT/."

step "Recording a static multi-position session on the virtual rig (50 s still, 40 poses, 100 Hz)"
"$IMUCAL" sim static --seed 7 --force -o "$OUT/static.imulog"

step "What the log holds"
"$IMUCAL" info "$OUT/static.imulog"

step "Calibrating accelerometer and gyroscope (Tedaldi multi-position method)"
"$IMUCAL" calibrate static "$OUT/static.imulog" --force -o "$OUT/static-result.yaml" --json "$OUT/static-result.json"

step "Recording 10 minutes of a still rig for the noise model"
"$IMUCAL" sim still --seed 7 --duration 600 --force -o "$OUT/still.imulog"

step "Allan deviation: noise densities and random walks (Kalibr imu.yaml)"
"$IMUCAL" allan "$OUT/still.imulog" --force -o "$OUT/imu.yaml"

step "Done"
echo "Calibration: $OUT/static-result.yaml (ground truth of the simulated IMU: $OUT/static.truth.yaml)"
echo "Noise model: $OUT/imu.yaml"
