#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""Write a small ROS 2 bag with Python's sqlite3, struct, zlib, lz4 and zstandard: a second
writer that shares no code with imucal's reader (tests/rosbag/check_python_bags.sh). The
messages are those of write_bag.py, CDR-serialized as ROS 2 does.

usage: write_rosbag2.py OUT sqlite3              a rosbag2 folder OUT/ (metadata.yaml, OUT_0.db3)
       write_rosbag2.py OUT.mcap mcap none|lz4|zstd [CHUNK_BYTES]
"""
import os
import sqlite3
import struct
import sys
import zlib

W, H = 8, 6
BASE_NS = 1000 * 10**9


class Cdr:
    """Little-endian CDR: each primitive aligned to its size, counted after the 4-byte header."""

    def __init__(self):
        self.body = bytearray()

    def pad(self, n):
        while len(self.body) % n:
            self.body.append(0)

    def put(self, fmt, *values):
        self.pad(struct.calcsize("<" + fmt[0]))
        self.body += struct.pack("<" + fmt, *values)

    def string(self, s):
        raw = s.encode() + b"\0"
        self.put("I", len(raw))
        self.body += raw

    def octets(self, b):
        self.put("I", len(b))
        self.body += b

    def header(self, ns, frame):
        self.put("iI", ns // 10**9, ns % 10**9)
        self.string(frame)

    def message(self):
        return b"\x00\x01\x00\x00" + bytes(self.body)


def imu(i):
    ns = BASE_NS + i * 5 * 10**6
    c = Cdr()
    c.header(ns, "imu0")
    c.put("dddd", 0.0, 0.0, 0.0, 1.0)
    c.put("d" * 9, -1.0, *([0.0] * 8))
    c.put("ddd", 0.001 * i, 0.5 - 0.002 * i, 0.01 + 0.0005 * i)
    c.put("d" * 9, *([0.0] * 9))
    c.put("ddd", 0.1 * i, 9.81, -0.5)
    c.put("d" * 9, *([0.0] * 9))
    return ns, "/imu0", c.message()


def image(k):
    ns = BASE_NS + k * 50 * 10**6
    c = Cdr()
    c.header(ns, "cam0")
    c.put("II", H, W)
    c.string("mono8")
    c.put("B", 0)
    c.put("I", W)
    c.octets(bytes((r * W + col + k) % 256 for r in range(H) for col in range(W)))
    return ns + 2 * 10**6, "/cam0/image_raw", c.message()


def png(k):
    def chunk(typ, data):
        return struct.pack(">I", len(data)) + typ + data + struct.pack(">I", zlib.crc32(typ + data) & 0xFFFFFFFF)
    raw = b"".join(b"\x00" + bytes((r * W + col + k) % 256 for col in range(W)) for r in range(H))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", W, H, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def compressed(k):
    ns = BASE_NS + k * 100 * 10**6
    c = Cdr()
    c.header(ns, "cam1")
    c.string("png")
    c.octets(png(k))
    return ns + 2 * 10**6, "/cam1/image_raw/compressed", c.message()


TOPICS = [("/imu0", "sensor_msgs/msg/Imu"), ("/cam0/image_raw", "sensor_msgs/msg/Image"),
          ("/cam1/image_raw/compressed", "sensor_msgs/msg/CompressedImage")]


def messages():
    out = [imu(i) for i in range(200)] + [image(k) for k in range(10)] + [compressed(k) for k in range(3)]
    return sorted(out, key=lambda m: m[0])


def write_sqlite(folder):
    os.makedirs(folder)
    name = os.path.basename(folder.rstrip("/")) + "_0.db3"
    db = sqlite3.connect(os.path.join(folder, name))
    db.execute("CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL)")
    db.execute("INSERT INTO schema VALUES (3, 'humble')")
    db.execute("CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, "
               "serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL)")
    db.execute("CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, "
               "timestamp INTEGER NOT NULL, data BLOB NOT NULL)")
    ids = {}
    for n, (topic, typ) in enumerate(TOPICS, start=1):
        db.execute("INSERT INTO topics VALUES (?, ?, ?, 'cdr', '')", (n, topic, typ))
        ids[topic] = n
    counts = {}
    for t, topic, data in messages():
        db.execute("INSERT INTO messages(topic_id, timestamp, data) VALUES (?, ?, ?)", (ids[topic], t, data))
        counts[topic] = counts.get(topic, 0) + 1
    db.commit()
    db.close()
    with open(os.path.join(folder, "metadata.yaml"), "w") as f:
        f.write("rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: sqlite3\n"
                "  relative_file_paths:\n    - %s\n  topics_with_message_count:\n" % name)
        for topic, typ in TOPICS:
            f.write("    - topic_metadata:\n        name: %s\n        type: %s\n        serialization_format: cdr\n"
                    "      message_count: %d\n" % (topic, typ, counts[topic]))


def record(op, content):
    return struct.pack("<BQ", op, len(content)) + content


def mstr(s):
    b = s.encode()
    return struct.pack("<I", len(b)) + b


def write_mcap(path, compression, chunk_bytes):
    out = bytearray(b"\x89MCAP0\r\n")
    out += record(0x01, mstr("ros2") + mstr("imucal-test"))
    pending = bytearray()
    for n, (topic, typ) in enumerate(TOPICS, start=1):
        pending += record(0x03, struct.pack("<H", n) + mstr(typ) + mstr("ros2msg") + mstr(""))
        pending += record(0x04, struct.pack("<HH", n, n) + mstr(topic) + mstr("cdr") + struct.pack("<I", 0))
    ids = {topic: n for n, (topic, _) in enumerate(TOPICS, start=1)}
    times = []

    def flush():
        nonlocal pending, times
        if not pending:
            return
        raw = bytes(pending)
        if compression == "zstd":
            import zstandard
            data = zstandard.ZstdCompressor().compress(raw)
        elif compression == "lz4":
            import lz4.frame
            data = lz4.frame.compress(raw)
        else:
            data = raw
        start, end = (min(times), max(times)) if times else (0, 0)
        name = "" if compression == "none" else compression
        content = struct.pack("<QQQI", start, end, len(raw), zlib.crc32(raw) & 0xFFFFFFFF) + mstr(name)
        content += struct.pack("<Q", len(data)) + data
        out.extend(record(0x06, content))
        pending = bytearray()
        times = []

    for seq, (t, topic, data) in enumerate(messages()):
        pending += record(0x05, struct.pack("<HIQQ", ids[topic], seq, t, t) + data)
        times.append(t)
        if len(pending) >= chunk_bytes:
            flush()
    flush()
    out += record(0x0F, struct.pack("<I", 0))          # data end
    out += record(0x02, struct.pack("<QQI", 0, 0, 0))  # footer: no summary
    out += b"\x89MCAP0\r\n"
    with open(path, "wb") as f:
        f.write(out)


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    if sys.argv[2] == "sqlite3":
        write_sqlite(sys.argv[1])
    elif sys.argv[2] == "mcap":
        write_mcap(sys.argv[1], sys.argv[3] if len(sys.argv) > 3 else "none",
                   int(sys.argv[4]) if len(sys.argv) > 4 else 768 * 1024)
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main()
