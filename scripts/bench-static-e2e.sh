#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# End-to-end time of a static calibration from text files, as a user runs it: `imucal import
# ascii` of the Xsens MTi example pair (512 s, 100 Hz, raw counts; ../shared/data/xsens_mti) plus
# `imucal calibrate static` of the log, median wall time and peak RSS of RUNS runs of each.
# With IMUTK set to an imu_tk driver (docs/static-calibration.md, "Against imu_tk"), imu_tk runs
# after each imucal run, and the median and range of the per-run ratios imucal / imu_tk are
# printed too.
# Usage: scripts/bench-static-e2e.sh [IMUCAL] [RUNS]   (default build/release/daemon/imucal, 9)
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
IMUCAL=${1:-$root/build/release/daemon/imucal}
RUNS=${2:-9}
DATA=${IMUCAL_DATA:-$root/../shared/data}/xsens_mti
[ -x "$IMUCAL" ] || { echo "bench-static-e2e: $IMUCAL not found; build it first (make build)" >&2; exit 1; }
if [ ! -f "$DATA/xsens_acc.txt" ]; then
  echo "bench-static-e2e: skipped: $DATA/xsens_acc.txt is absent (the real recordings are not part of a clone)"
  exit 0
fi
command -v /usr/bin/time >/dev/null || { echo "bench-static-e2e: needs /usr/bin/time (apt-get install time)" >&2; exit 1; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

median() { sort -n | awk '{ v[NR] = $1 } END { print v[int((NR + 1) / 2)] }'; }

: > "$tmp/import" ; : > "$tmp/calib"; : > "$tmp/total"; : > "$tmp/peer"; : > "$tmp/ratio"
# Wall time from bash's microsecond clock (/usr/bin/time rounds it to 10 ms); peak RSS from
# /usr/bin/time. With IMUTK, each run of imucal's two commands is followed by one of imu_tk, and
# the ratio of the two is taken per run: on a shared host whose speed drifts, runs side by side
# compare the tools under the same conditions.
now() { echo "${EPOCHREALTIME/,/.}"; }
for _ in $(seq "$RUNS"); do
  rm -f "$tmp/x.imulog"
  t0=$(now)
  /usr/bin/time -f "%M" -o "$tmp/mi" "$IMUCAL" import ascii --accel "$DATA/xsens_acc.txt" \
    --gyro "$DATA/xsens_gyro.txt" --units raw --accel-offset 32768 --accel-scale 0.00241 \
    --gyro-offset 32768 --gyro-scale 0.0001598 -o "$tmp/x.imulog" > /dev/null 2> "$tmp/err" ||
    { echo "bench-static-e2e: import failed:" >&2; cat "$tmp/err" >&2; exit 1; }
  t1=$(now)
  /usr/bin/time -f "%M" -o "$tmp/mc" "$IMUCAL" calibrate static "$tmp/x.imulog" --gravity 9.81744 \
    --force -o "$tmp/r.yaml" > /dev/null 2> "$tmp/err" ||
    { echo "bench-static-e2e: calibrate failed:" >&2; cat "$tmp/err" >&2; exit 1; }
  t2=$(now)
  echo "$(awk -v a="$t0" -v b="$t1" 'BEGIN { print b - a }') $(cat "$tmp/mi")" >> "$tmp/import"
  echo "$(awk -v a="$t1" -v b="$t2" 'BEGIN { print b - a }') $(cat "$tmp/mc")" >> "$tmp/calib"
  awk -v a="$t0" -v b="$t2" 'BEGIN { print b - a }' >> "$tmp/total"
  if [ -n "${IMUTK:-}" ]; then
    # imu_tk writes its result files into the working directory: run it in $tmp.
    t3=$(now)
    (cd "$tmp" && /usr/bin/time -f "%M" -o "$tmp/mp" "$IMUTK" > /dev/null 2>&1)
    t4=$(now)
    echo "$(awk -v a="$t3" -v b="$t4" 'BEGIN { print b - a }') $(cat "$tmp/mp")" >> "$tmp/peer"
    awk -v a="$t0" -v b="$t2" -v c="$t3" -v d="$t4" 'BEGIN { print (b - a) / (d - c) }' >> "$tmp/ratio"
  fi
done
echo "imucal: $IMUCAL, $RUNS runs, Xsens MTi pair (51175 samples)"
printf '  import ascii       median %.3f s  peak RSS %.1f MB\n' "$(cut -d' ' -f1 "$tmp/import" | median)" \
  "$(cut -d' ' -f2 "$tmp/import" | median | awk '{ print $1 / 1024 }')"
printf '  calibrate static   median %.3f s  peak RSS %.1f MB\n' "$(cut -d' ' -f1 "$tmp/calib" | median)" \
  "$(cut -d' ' -f2 "$tmp/calib" | median | awk '{ print $1 / 1024 }')"
printf '  both               median %.3f s\n' "$(median < "$tmp/total")"
if [ -n "${IMUTK:-}" ]; then
  printf '  imu_tk (%s)  median %.3f s  peak RSS %.1f MB\n' "$IMUTK" "$(cut -d' ' -f1 "$tmp/peer" | median)" \
    "$(cut -d' ' -f2 "$tmp/peer" | median | awk '{ print $1 / 1024 }')"
  printf '  imucal / imu_tk    median of the per-run ratios %.3f (range %.3f-%.3f)\n' "$(median < "$tmp/ratio")" \
    "$(sort -n "$tmp/ratio" | head -1)" "$(sort -n "$tmp/ratio" | tail -1)"
fi
