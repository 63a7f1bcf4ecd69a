#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Records the virtual rig in real time, IMU at 1 kHz and one 752x480 camera at 30 fps, and prints
# the samples and frames lost and the peak RSS (docs/benchmarks.md, "Recording IMU and a camera").
#   scripts/bench-record-camera.sh [IMUCAL] [SECONDS]
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
imucal=${1:-$here/build/release/daemon/imucal}
seconds=${2:-60}
[ -x "$imucal" ] || { echo "bench-record-camera: no imucal at $imucal (build it, or pass its path)" >&2; exit 1; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cat > "$work/rig.yaml" <<YAML
name: bench
imu:
  bus: sim
  accel_range_g: 4
  gyro_range_dps: 500
  rate_hz: 1000
  dlpf_hz: 188
cameras:
  - name: cam0
    backend: sim
    width: 752
    height: 480
    rate_hz: 30
    pixel_format: GREY
target: $here/config/checkerboard-7x6.yaml
storage:
  backend: file
  path: $work/calibration.bin
YAML
/usr/bin/time -v "$imucal" record --config "$work/rig.yaml" --sim --realtime --sim-camera pattern \
  -o "$work/r.imulog" --duration "$seconds" --json > "$work/summary.json" 2> "$work/time.txt"
python3 - "$work/summary.json" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
print(f"IMU: {j['samples']} samples at {j['rate_hz']:.1f} Hz, {j['samples_lost']} lost, {j['gaps']} gaps, "
      f"{j['log_dropped']} dropped by the log ring")
for c in j.get("cameras", []):
    print(f"camera {c['name']}: {c['frames_written']} frames written, {c['device_dropped']} dropped by the device, "
          f"{c['queue_dropped']} dropped for want of a pool slot, pool high water {c['queue_high_water']}")
PY
grep -E "Maximum resident|Elapsed|User time|System time" "$work/time.txt"
