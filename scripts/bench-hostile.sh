#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# The hostile cases too slow for the test suite, with their figures (docs/hostile-inputs.md):
#   1. a session nobody answers, at time-scale 0: how long it records and how large its log grows
#      before session.operator_wait_s (default 30 min of rig time) ends it;
#   2. `imucal info` on a long log (HOURS of 1 kHz samples): its peak memory;
#   3. imucald killed (SIGKILL) at random moments of sessions, at time-scale 0 and 20 in turn (at 0
#      the steps before the motion step take under a second of wall time): how many of the logs
#      left behind open, with how many samples.
# Usage: scripts/bench-hostile.sh [BUILD_DIR] [HOURS] [KILLS]
#        (default build/release, 3 hours, 10 kills)
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
BUILD=${1:-$root/build/release}
HOURS=${2:-3}
KILLS=${3:-10}
IMUCAL=$BUILD/daemon/imucal
IMUCALD=$BUILD/daemon/imucald
for p in "$IMUCAL" "$IMUCALD"; do
  [ -x "$p" ] || { echo "bench-hostile: $p not found; build it first (make build)" >&2; exit 1; }
done
command -v /usr/bin/time >/dev/null || { echo "bench-hostile: needs /usr/bin/time (apt-get install time)" >&2; exit 1; }
tmp=$(mktemp -d)
trap 'kill -9 $(jobs -p) 2>/dev/null || true; rm -rf "$tmp"' EXIT

# A rig configuration with its storage in $1.
rig_config() {
  sed -e "s|path: /var/lib/imucal/calibration.bin|path: $1/eeprom.bin|" \
    -e "s|target: checkerboard-7x6.yaml|target: $root/config/checkerboard-7x6.yaml|" "$root/config/rig.yaml" > "$1/rig.yaml"
}

# The session log under state dir $1.
session_log() { find "$1/sessions" -name session.imulog 2>/dev/null | head -n 1; }

echo "binaries: $BUILD"
echo "== 1. a session nobody answers (time-scale 0, the default operator wait)"
d=$tmp/wait
mkdir -p "$d"
rig_config "$d"
start=$(date +%s.%N)
/usr/bin/time -f "%e %M" -o "$d/time" "$IMUCALD" --config "$d/rig.yaml" --socket "$d/s.sock" --state-dir "$d/state" \
  --sim --time-scale 0 --start default --exit-after-session -q 2> "$d/imucald.log" || true
read -r wall rss < <(tail -n 1 "$d/time")
log=$(session_log "$d/state")
size=$(stat -c %s "$log")
# From info's text: "  duration: 1800.000 s (...)" and "    samples: N, nominal ...".
info=$("$IMUCAL" info "$log")
samples=$(awk '$1 == "samples:" { sub(/,$/, "", $2); print $2; exit }' <<< "$info")
rig_s=$(awk '$1 == "duration:" { printf "%.0f", $2; exit }' <<< "$info")
outcome=$("$IMUCAL" replay "$log" -o "$d/replay" 2>&1 | grep -m1 '^outcome' || true)
echo "ended after $wall s of wall time (peak RSS $((rss / 1024)) MB): $rig_s s of rig time, $samples samples, log $((size / 1048576)) MB; replay: $outcome"

echo "== 2. imucal info on a $HOURS-hour log at 1 kHz"
long=$tmp/long.imulog
"$IMUCAL" sim still --seed 3 --imu-rate 1000 --duration $((HOURS * 3600)) -o "$long" > /dev/null 2>&1
/usr/bin/time -f "%e %M" -o "$tmp/info-time" "$IMUCAL" info "$long" > /dev/null
read -r wall rss < <(tail -n 1 "$tmp/info-time")
echo "log $(($(stat -c %s "$long") / 1048576)) MB: info took $wall s, peak RSS $((rss / 1024)) MB"
rm -f "$long" "${long%.imulog}.truth.yaml"

echo "== 3. imucald killed during $KILLS sessions (time-scale 0 and 20 in turn, scripted operator)"
readable=0 with_samples=0
for k in $(seq "$KILLS"); do
  d=$tmp/kill$k
  mkdir -p "$d"
  rig_config "$d"
  "$IMUCALD" --config "$d/rig.yaml" --socket "$d/s.sock" --state-dir "$d/state" --sim --sim-operator full \
    --seed "$k" --time-scale $((k % 2 ? 0 : 20)) --start default -q 2> "$d/imucald.log" &
  pid=$!
  # A moment from 0.5 to 8 s into the session, different for each kill.
  sleep "$(awk -v k="$k" 'BEGIN { srand(k); printf "%.2f", 0.5 + 7.5 * rand() }')"
  kill -9 "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
  log=$(session_log "$d/state")
  n=0
  if [ -n "$log" ] && "$IMUCAL" info "$log" > "$d/info.txt" 2> "$d/info.err"; then
    readable=$((readable + 1))
    n=$(awk '$1 == "samples:" { sub(/,$/, "", $2); n += $2 } END { print n + 0 }' "$d/info.txt")
    [ "$n" -gt 0 ] && with_samples=$((with_samples + 1))
  fi
  echo "  kill $k (time-scale $((k % 2 ? 0 : 20))): $([ -n "$log" ] && echo "a log" || echo "no log"), $n samples $(head -c 160 "$d/info.err" 2> /dev/null)"
  rm -rf "$d"
done
echo "$readable of $KILLS logs readable, $with_samples with samples"
