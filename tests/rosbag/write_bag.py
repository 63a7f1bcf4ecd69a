#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""Write a small ROS 1 bag (format 2.0) with ROS's own rosbag library (Debian's python3-rosbag),
a writer that shares no code with imucal's (tests/rosbag/check_python_bags.sh).

usage: write_bag.py OUTPUT.bag [none|bz2|lz4] [CHUNK_THRESHOLD_BYTES]

CHUNK_THRESHOLD_BYTES defaults to rosbag's 768*1024 (this bag then has 1 chunk);
e.g. 4096 gives many chunks.

Contents:
  /imu0                         200 sensor_msgs/Imu at 200 Hz,
                                header.stamp = 1000 s + i*5 ms, receive time = stamp
  /cam0/image_raw               10 sensor_msgs/Image 8x6 mono8,
                                pixel (row*8+col+frame) % 256,
                                header.stamp = 1000 s + k*50 ms, receive time = stamp + 2 ms
  /cam1/image_raw/compressed    3 sensor_msgs/CompressedImage format "png",
                                header.stamp = 1000 s + k*100 ms, receive time = stamp + 2 ms
"""
import struct
import sys
import zlib

import rosbag
import rospy
from sensor_msgs.msg import CompressedImage, Image, Imu

W, H = 8, 6
BASE_NS = 1000 * 10**9


def t(ns):
    return rospy.Time(ns // 10**9, ns % 10**9)


def make_png(width, height, pixel):
    """8-bit grayscale PNG built with zlib/struct; pixel(row, col) -> 0..255."""
    def chunk(typ, data):
        c = struct.pack(">I", len(data)) + typ + data
        return c + struct.pack(">I", zlib.crc32(typ + data) & 0xFFFFFFFF)
    raw = b"".join(b"\x00" + bytes(pixel(r, c) for c in range(width))
                   for r in range(height))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)  # gray, 8 bit
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr)
            + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    out = sys.argv[1]
    comp = sys.argv[2] if len(sys.argv) > 2 else "none"
    if comp not in ("none", "bz2", "lz4"):
        sys.exit("compression must be none, bz2 or lz4")
    chunk_threshold = int(sys.argv[3]) if len(sys.argv) > 3 else 768 * 1024

    msgs = []  # (receive_ns, topic, msg)

    for i in range(200):
        ns = BASE_NS + i * 5 * 10**6
        m = Imu()
        m.header.seq = i
        m.header.stamp = t(ns)
        m.header.frame_id = "imu0"
        m.orientation.w = 1.0
        m.orientation_covariance[0] = -1.0  # orientation unknown
        m.linear_acceleration.x = 0.1 * i
        m.linear_acceleration.y = 9.81
        m.linear_acceleration.z = -0.5
        m.angular_velocity.x = 0.001 * i
        m.angular_velocity.y = 0.5 - 0.002 * i
        m.angular_velocity.z = 0.01 + 0.0005 * i
        msgs.append((ns, "/imu0", m))

    for k in range(10):
        ns = BASE_NS + k * 50 * 10**6
        m = Image()
        m.header.seq = k
        m.header.stamp = t(ns)
        m.header.frame_id = "cam0"
        m.height = H
        m.width = W
        m.encoding = "mono8"
        m.is_bigendian = 0
        m.step = W
        m.data = bytes((r * W + c + k) % 256 for r in range(H) for c in range(W))
        msgs.append((ns + 2 * 10**6, "/cam0/image_raw", m))

    for k in range(3):
        ns = BASE_NS + k * 100 * 10**6
        m = CompressedImage()
        m.header.seq = k
        m.header.stamp = t(ns)
        m.header.frame_id = "cam1"
        m.format = "png"
        m.data = make_png(W, H, lambda r, c, k=k: (r * W + c + k) % 256)
        msgs.append((ns + 2 * 10**6, "/cam1/image_raw/compressed", m))

    msgs.sort(key=lambda x: x[0])  # write in receive-time order, like rosbag record
    with rosbag.Bag(out, "w", compression=comp,
                    chunk_threshold=chunk_threshold) as bag:
        for ns, topic, m in msgs:
            bag.write(topic, m, t(ns))
    print("wrote %s (%d messages, compression=%s)" % (out, len(msgs), comp))


if __name__ == "__main__":
    main()
