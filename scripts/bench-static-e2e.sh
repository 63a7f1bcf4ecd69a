#!/usr/bin/env bash
# End-to-end time of a static calibration from text files, as a user runs it: `imucal import
# ascii` of the Xsens MTi example pair (512 s, 100 Hz, raw counts; ../shared/data/xsens_mti) plus
# `imucal calibrate static` of the log, median wall time and peak RSS of RUNS runs of each.
# With IMUTK set to an imu_tk driver (docs/static-calibration.md, "Against imu_tk"), the same
# is measured for it.
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

: > "$tmp/import" ; : > "$tmp/calib"; : > "$tmp/total"
# Wall time from bash's microsecond clock (/usr/bin/time rounds it to 10 ms); peak RSS from
# /usr/bin/time.
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
done
echo "imucal: $IMUCAL, $RUNS runs, Xsens MTi pair (51175 samples)"
printf '  import ascii       median %.3f s  peak RSS %.1f MB\n' "$(cut -d' ' -f1 "$tmp/import" | median)" \
  "$(cut -d' ' -f2 "$tmp/import" | median | awk '{ print $1 / 1024 }')"
printf '  calibrate static   median %.3f s  peak RSS %.1f MB\n' "$(cut -d' ' -f1 "$tmp/calib" | median)" \
  "$(cut -d' ' -f2 "$tmp/calib" | median | awk '{ print $1 / 1024 }')"
printf '  both               median %.3f s\n' "$(median < "$tmp/total")"
if [ -n "${IMUTK:-}" ]; then
  : > "$tmp/peer"
  (cd "$tmp" && for _ in $(seq "$RUNS"); do
    t0=$(now)
    /usr/bin/time -f "%M" -o "$tmp/mp" "$IMUTK" > /dev/null 2>&1
    t1=$(now)
    echo "$(awk -v a="$t0" -v b="$t1" 'BEGIN { print b - a }') $(cat "$tmp/mp")" >> "$tmp/peer"
  done)
  printf '  imu_tk (%s)  median %.3f s  peak RSS %.1f MB\n' "$IMUTK" "$(cut -d' ' -f1 "$tmp/peer" | median)" \
    "$(cut -d' ' -f2 "$tmp/peer" | median | awk '{ print $1 / 1024 }')"
fi
