#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""Dump every message of a ROS 1 bag, one line each, in bag (receive-time) order, with ROS's own
rosbag library: the reader Kalibr uses (tests/rosbag/check_python_bags.sh).

usage: read_bag.py BAG [TOPIC ...]

Line formats (fields separated by a single space; floats printed with %.17g so
they round-trip exactly):
  <topic> <type> stamp_ns=<header.stamp ns> recv_ns=<bag time ns> <payload>
payload:
  sensor_msgs/Imu             acc=<ax> <ay> <az> gyr=<wx> <wy> <wz>
  sensor_msgs/Image           w=<width> h=<height> enc=<encoding> step=<step> len=<len(data)> sum=<sum of data bytes>
  sensor_msgs/CompressedImage fmt=<format> len=<len(data)> sum=<sum of data bytes>
  other types                 (nothing)
stamp_ns is "-" for messages without a std_msgs/Header named 'header'.
Message classes are rebuilt from the bag's own connection definitions (rosbag does
that), so the installed message packages are not needed to read.
"""
import sys

import rosbag


def stamp_ns(msg):
    h = getattr(msg, "header", None)
    if h is None or not hasattr(h, "stamp"):
        return "-"
    return str(h.stamp.secs * 10**9 + h.stamp.nsecs)


def g(x):
    return "%.17g" % x


def data_bytes(d):
    # uint8[] comes back as bytes in Python 3 rosbag/genpy
    return d if isinstance(d, (bytes, bytearray)) else bytes(d)


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    topics = sys.argv[2:] or None
    n = 0
    with rosbag.Bag(sys.argv[1], "r") as bag:
        for topic, msg, t in bag.read_messages(topics=topics):
            typ = msg._type
            recv = t.secs * 10**9 + t.nsecs
            if typ == "sensor_msgs/Imu":
                a, w = msg.linear_acceleration, msg.angular_velocity
                payload = "acc=%s %s %s gyr=%s %s %s" % (g(a.x), g(a.y), g(a.z),
                                                         g(w.x), g(w.y), g(w.z))
            elif typ == "sensor_msgs/Image":
                d = data_bytes(msg.data)
                payload = "w=%d h=%d enc=%s step=%d len=%d sum=%d" % (
                    msg.width, msg.height, msg.encoding, msg.step, len(d), sum(d))
            elif typ == "sensor_msgs/CompressedImage":
                d = data_bytes(msg.data)
                payload = "fmt=%s len=%d sum=%d" % (msg.format, len(d), sum(d))
            else:
                payload = ""
            print(("%s %s stamp_ns=%s recv_ns=%d %s" % (
                topic, typ, stamp_ns(msg), recv, payload)).rstrip())
            n += 1
    print("# %d messages" % n, file=sys.stderr)


if __name__ == "__main__":
    main()
