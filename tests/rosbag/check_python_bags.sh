#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Bags written by ROS's own rosbag library (Debian's python3-rosbag: a writer that shares no code
# with imucal's) import with their content, and the bags `imucal export bag` writes read back
# through that library (the one Kalibr reads bags with) with the same content.
#   usage: check_python_bags.sh IMUCAL
# For each chunk compression (none, bz2, lz4) and for one chunk or many:
#   write_bag.py -> imucal import bag -> imucal export bag -> read_bag.py on both bags: every
#   Imu message (stamp and the six values, to the last bit) and every mono8 Image the same; the
#   PNG CompressedImages come back as mono8 Images of the same pixels.
# A bag cut in half: exit 3 naming where, and --allow-damaged imports its whole chunks.
# ROS 2 bags (a sqlite3 folder; mcap with plain, lz4 and zstd chunks) from write_rosbag2.py, a
# writer of Python's own modules: imported, exported as a ROS 1 bag, the same messages as the
# ROS 1 bag's; the .db3 is not modified by the reading; an mcap cut in half as a cut bag.
# Skips (exit 77) where python3-rosbag, python3-sensor-msgs, python3-roslz4, python3-lz4 or
# python3-zstandard is missing.
set -euo pipefail

imucal=$1
here=$(cd "$(dirname "$0")" && pwd)
py=/usr/bin/python3  # Debian's: the ROS packages are installed for it
if ! [ -x "$py" ] || ! "$py" -c 'import rosbag, roslz4, sensor_msgs.msg, lz4.frame, zstandard' 2>/dev/null; then
  echo "SKIP: ROS's rosbag library for Python or Python's lz4 and zstandard are not installed (apt-get" \
    "install python3-rosbag python3-sensor-msgs python3-roslz4 python3-lz4 python3-zstandard, or" \
    "scripts/install-deps.sh --test)"
  exit 77
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
fail() {
  echo "FAIL: $*"
  exit 1
}

# One line per message without the receive time (an export stamps both with the log's time).
messages() { "$py" "$here/read_bag.py" "$@" 2>/dev/null | sed -E 's/ recv_ns=[0-9]+//' | sort; }

for comp in none bz2 lz4; do
  for chunk in 786432 4096; do
    name=$comp-$chunk
    "$py" "$here/write_bag.py" "$work/$name.bag" "$comp" "$chunk" >/dev/null
    "$imucal" import bag "$work/$name.bag" -o "$work/$name.imulog" >"$work/import.txt" 2>&1 ||
      fail "$name: import: $(cat "$work/import.txt")"
    grep -q "imported 200 IMU samples (200 Hz, 0.995 s) and 13 frames from 2 cameras" "$work/import.txt" ||
      fail "$name: import said: $(cat "$work/import.txt")"
    "$imucal" export bag "$work/$name.imulog" "$work/$name-out.bag" >"$work/export.txt" 2>&1 ||
      fail "$name: export: $(cat "$work/export.txt")"
    messages "$work/$name.bag" /imu0 /cam0/image_raw >"$work/a.txt"
    messages "$work/$name-out.bag" /imu0 /cam0/image_raw >"$work/b.txt"
    [ "$(wc -l <"$work/a.txt")" -eq 210 ] || fail "$name: read $(wc -l <"$work/a.txt") messages from the bag"
    diff "$work/a.txt" "$work/b.txt" >"$work/diff.txt" || fail "$name: the exported bag differs: $(head -4 "$work/diff.txt")"
    # cam1's PNGs hold (row * 8 + col + k) % 256, k = 0, 1, 2: as mono8, 1128 + 48 k summed.
    expected=$(printf '%s\n' 0 1 2 | while read -r k; do
      echo "/cam1/image_raw sensor_msgs/Image stamp_ns=$((1000000000000 + k * 100000000)) w=8 h=6 enc=mono8 step=8 len=48 sum=$((1128 + 48 * k))"
    done | sort)
    [ "$(messages "$work/$name-out.bag" /cam1/image_raw)" = "$expected" ] ||
      fail "$name: cam1 came back as $(messages "$work/$name-out.bag" /cam1/image_raw)"
  done
done

# ROS 2 bags from write_rosbag2.py (Python's sqlite3, struct, lz4 and zstandard: no code of
# imucal's): a sqlite3 folder and mcap files with each chunk compression hold the same messages,
# which come out of imucal (import rosbag2, export bag) as ROS's rosbag reads the ROS 1 bag above.
"$py" "$here/write_rosbag2.py" "$work/ros2" sqlite3
"$py" "$here/write_rosbag2.py" "$work/ros2-none.mcap" mcap none
"$py" "$here/write_rosbag2.py" "$work/ros2-lz4.mcap" mcap lz4
"$py" "$here/write_rosbag2.py" "$work/ros2-zstd.mcap" mcap zstd 4096
db_before=$(md5sum "$work/ros2/ros2_0.db3")
messages "$work/none-786432.bag" >"$work/ros1.txt"
for ros2 in ros2 ros2-none.mcap ros2-lz4.mcap ros2-zstd.mcap; do
  "$imucal" import rosbag2 "$work/$ros2" -o "$work/$ros2.imulog" >"$work/import.txt" 2>&1 ||
    fail "$ros2: import: $(cat "$work/import.txt")"
  grep -q "imported 200 IMU samples (200 Hz, 0.995 s) and 13 frames from 2 cameras" "$work/import.txt" ||
    fail "$ros2: import said: $(cat "$work/import.txt")"
  "$imucal" export bag "$work/$ros2.imulog" "$work/$ros2-out.bag" >"$work/export.txt" 2>&1 ||
    fail "$ros2: export: $(cat "$work/export.txt")"
  messages "$work/$ros2-out.bag" >"$work/b.txt"
  messages "$work/none-786432-out.bag" >"$work/a.txt"
  diff "$work/a.txt" "$work/b.txt" >"$work/diff.txt" ||
    fail "$ros2: differs from the ROS 1 bag's import: $(head -4 "$work/diff.txt")"
done
[ "$(md5sum "$work/ros2/ros2_0.db3")" = "$db_before" ] || fail "the .db3 was modified by reading it"
[ -z "$(ls "$work/ros2" | grep -v -e '^ros2_0.db3$' -e '^metadata.yaml$')" ] ||
  fail "reading the rosbag2 left files beside it: $(ls "$work/ros2")"

# Cut short: refused (exit 3) naming the byte, or its whole chunks with --allow-damaged.
bag=$work/lz4-4096.bag
size=$(stat -c %s "$bag")
head -c $((size / 2)) "$bag" >"$work/cut.bag"
set +e
"$imucal" import bag "$work/cut.bag" -o "$work/cut.imulog" >"$work/cut.txt" 2>&1
rc=$?
set -e
[ $rc -eq 3 ] || fail "a cut bag: exit $rc, not 3: $(cat "$work/cut.txt")"
grep -q "is damaged: .*byte [0-9]* of $((size / 2)).*--allow-damaged" "$work/cut.txt" ||
  fail "a cut bag said: $(cat "$work/cut.txt")"
[ ! -e "$work/cut.imulog" ] || fail "a refused import left $work/cut.imulog"
"$imucal" import bag "$work/cut.bag" --allow-damaged -o "$work/cut.imulog" >"$work/cut.txt" 2>&1 ||
  fail "--allow-damaged: $(cat "$work/cut.txt")"
grep -q "note: .*is damaged: .*imported what comes before it" "$work/cut.txt" ||
  fail "--allow-damaged said: $(cat "$work/cut.txt")"
# An mcap cut in half: the same.
size=$(stat -c %s "$work/ros2-zstd.mcap")
head -c $((size / 2)) "$work/ros2-zstd.mcap" >"$work/cut.mcap"
set +e
"$imucal" import rosbag2 "$work/cut.mcap" -o "$work/cut-mcap.imulog" >"$work/cut.txt" 2>&1
rc=$?
set -e
[ $rc -eq 3 ] || fail "a cut mcap: exit $rc, not 3: $(cat "$work/cut.txt")"
grep -q "is damaged: .*byte [0-9]* of $((size / 2))" "$work/cut.txt" || fail "a cut mcap said: $(cat "$work/cut.txt")"
"$imucal" import rosbag2 "$work/cut.mcap" --allow-damaged -o "$work/cut-mcap.imulog" >"$work/cut.txt" 2>&1 ||
  fail "a cut mcap, --allow-damaged: $(cat "$work/cut.txt")"
echo "OK: 6 bags of ROS's rosbag and 4 ROS 2 bags of a second writer imported and exported with the same" \
  "messages; a cut bag and a cut mcap refused and partly imported"
