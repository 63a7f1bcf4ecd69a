#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# The static calibration's sigmas against the spread of a real recording: the Xsens MTi example
# pair (512 s, 100 Hz, raw counts, 38 static intervals; ../shared/data/xsens_mti) is calibrated
# whole, then split by poses into two halves that share the still start (the first 18 poses after
# it, and the last 19: their file has a gap after the still start, across which no gyro motion is
# integrated), each half calibrated alone. For every estimated parameter the halves' difference
# is divided by their combined sigma, sqrt(sigma_A^2 + sigma_B^2); if the sigmas hold, about 68,
# 95 and 99.7 % of those ratios are within 1, 2 and 3 (docs/benchmarks.md, "Static sigmas on a
# real recording split by poses").
# Usage: scripts/static-halves.sh [IMUCAL]   (default build/release/daemon/imucal)
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
IMUCAL=${1:-$root/build/release/daemon/imucal}
DATA=${IMUCAL_DATA:-$root/../shared/data}/xsens_mti
[ -x "$IMUCAL" ] || { echo "static-halves: $IMUCAL not found; build it first (make build)" >&2; exit 1; }
if [ ! -f "$DATA/xsens_acc.txt" ]; then
  echo "static-halves: skipped: $DATA/xsens_acc.txt is absent (the real recordings are not part of a clone)"
  exit 0
fi
command -v python3 >/dev/null || { echo "static-halves: needs python3 (apt-get install python3)" >&2; exit 1; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

calibrate() {  # NAME ACC GYRO: import and calibrate, the result in $tmp/NAME.json
  "$IMUCAL" import ascii --accel "$2" --gyro "$3" --units raw --accel-offset 32768 --accel-scale 0.00241 \
    --gyro-offset 32768 --gyro-scale 0.0001598 -o "$tmp/$1.imulog" > /dev/null 2> "$tmp/err" ||
    { echo "static-halves: import of $1 failed:" >&2; cat "$tmp/err" >&2; exit 1; }
  "$IMUCAL" calibrate static "$tmp/$1.imulog" --gravity 9.81744 -o "$tmp/$1.yaml" --json "$tmp/$1.json" \
    > "$tmp/$1.out" 2> "$tmp/err" || { echo "static-halves: calibration of $1 failed:" >&2; cat "$tmp/err" >&2; exit 1; }
  sed -n 2p "$tmp/$1.out"
}

calibrate whole "$DATA/xsens_acc.txt" "$DATA/xsens_gyro.txt"
# The split: halfway between the end of the 18th pose after the still start and the start of the
# next, in seconds from the first sample.
read -r still split < <(python3 -c '
import json, sys
j = json.load(open(sys.argv[1]))
iv = j["static_intervals"]
k = (len(iv) - 1) // 2
print(j["init_still_s"], (iv[k]["t1_s"] + iv[k + 1]["t0_s"]) / 2)' "$tmp/whole.json")
for f in acc gyro; do
  awk -v s="$still" -v m="$split" -v a="$tmp/A_$f.txt" -v b="$tmp/B_$f.txt" '
    /^[[:space:]]*(#|$)/ { next }
    { if (t0 == "") t0 = $1; t = $1 - t0; if (t < m) print > a; if (t < s || t >= m) print > b }' \
    "$DATA/xsens_$f.txt"
done
calibrate A "$tmp/A_acc.txt" "$tmp/A_gyro.txt"
calibrate B "$tmp/B_acc.txt" "$tmp/B_gyro.txt"

python3 - "$tmp/A.json" "$tmp/B.json" <<'EOF'
import json, math, sys
A, B = (json.load(open(p)) for p in sys.argv[1:3])
rows = []
def add(name, a, b, sa, sb):
    s = math.hypot(sa, sb)
    if s > 0 and math.isfinite(s):
        rows.append((name, a - b, s, (a - b) / s))
for sensor in ("accel", "gyro"):
    r, q = A[sensor], B[sensor]
    for i, ax in enumerate("xyz"):
        add(f"{sensor} scale {ax}", r["scale"][i], q["scale"][i], r["sigma"]["scale"][i], q["sigma"]["scale"][i])
        add(f"{sensor} bias {ax}", r["bias"][i], q["bias"][i], r["sigma"]["bias"][i], q["sigma"]["bias"][i])
        for k in range(3):
            sa, sb = r["sigma"]["misalignment"][i][k], q["sigma"]["misalignment"][i][k]
            if sa and sb:
                add(f"{sensor} misalignment {i}{k}", r["misalignment"][i][k], q["misalignment"][i][k], sa, sb)
for i in range(3):
    for k in range(3):
        add(f"g-sensitivity G {i}{k}", A["gsens"]["G"][i][k], B["gsens"]["G"][i][k],
            A["gsens"]["G_sigma"][i][k], B["gsens"]["G_sigma"][i][k])
for name, d, s, z in rows:
    print(f"  {name:26s} difference {d:12.4g}  combined sigma {s:10.3g}  {z:6.2f} sigmas")
n = len(rows)
within = [sum(abs(z) <= k for *_, z in rows) for k in (1, 2, 3)]
chi2 = sum(z * z for *_, z in rows)
print(f"{n} parameters: within 1, 2, 3 combined sigmas: " +
      ", ".join(f"{w} ({100 * w / n:.0f} %)" for w in within) +
      f"; sum of squares {chi2:.1f} for {n} (RMS ratio {math.sqrt(chi2 / n):.2f})")
EOF
