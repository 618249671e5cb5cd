"""Writes ROS 2 bags (rosbag2's MCAP storage: CDR messages, ros2msg schemas)
for the tests of `mapc localize BAG`, with the independent `mcap` and
`mcap-ros2-support` libraries (not with refloc's code).

    python make_bags.py SCANS.jsonl OUT_DIR

SCANS.jsonl holds LaserScan dicts (`mapc eval --dump` output). Writes
multi.mcap (LaserScans on /scan and /scan_rear, plus /chatter and /odom;
zstd chunks), lz4.mcap (the same with lz4 chunks), brotli.mcap (lz4.mcap
with its chunks' compression renamed to one no reader knows), truncated.mcap
(multi.mcap cut inside its data), noscan.mcap (/chatter and /odom only).
Stamps: scan k at STAMP0 + k * 0.1 s.
"""
import json
import math
import sys
from pathlib import Path

from mcap.writer import CompressionType
from mcap_ros2.writer import Writer

STAMP0 = 1_733_270_400  # s; 2024-12-04 00:00 UTC

TIME = "int32 sec\nuint32 nanosec\n"
HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
SEP = "=" * 80 + "\n"
LASER_SCAN = (
    "std_msgs/Header header\n"
    "float32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n"
    "float32 time_increment\nfloat32 scan_time\n"
    "float32 range_min\nfloat32 range_max\n"
    "float32[] ranges\nfloat32[] intensities\n"
    + SEP + "MSG: std_msgs/Header\n" + HEADER
    + SEP + "MSG: builtin_interfaces/Time\n" + TIME
)
STRING = "string data\n"
# A 2D odometry stand-in of another type than LaserScan.
POSE2D = "float64 x\nfloat64 y\nfloat64 theta\n"


def stamp(k):
    ns = STAMP0 * 10**9 + k * 100_000_000
    return ns, {"sec": ns // 10**9, "nanosec": ns % 10**9}


def laser_msg(s, k, frame):
    _, st = stamp(k)
    ranges = [math.inf if r is None else float(r) for r in s["ranges"]]
    n = len(ranges)
    return {
        "header": {"stamp": st, "frame_id": frame},
        "angle_min": s["angle_min"],
        "angle_max": s["angle_min"] + (n - 1) * s["angle_increment"],
        "angle_increment": s["angle_increment"],
        "time_increment": 0.0,
        "scan_time": 0.1,
        "range_min": s.get("range_min", 0.0),
        "range_max": s["range_max"],
        "ranges": ranges,
        "intensities": [100.0] * n,
    }


def write_bag(path, scans, scan_topics, others=True, chunk_size=8192,
              compression=CompressionType.ZSTD):
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=chunk_size, compression=compression)
        ls = w.register_msgdef("sensor_msgs/msg/LaserScan", LASER_SCAN)
        st = w.register_msgdef("std_msgs/msg/String", STRING)
        p2 = w.register_msgdef("geometry_msgs/msg/Pose2D", POSE2D)
        for k, s in enumerate(scans):
            ns, _ = stamp(k)
            for t in scan_topics:
                w.write_message(t, ls, laser_msg(s, k, t.strip("/") + "_link"),
                                log_time=ns, publish_time=ns, sequence=k)
            if others:
                w.write_message("/chatter", st, {"data": f"scan {k}"}, log_time=ns, publish_time=ns)
                w.write_message("/odom", p2, {"x": 0.1 * k, "y": 0.0, "theta": 0.0},
                                log_time=ns, publish_time=ns)
        w.finish()


def make_all(scans, out):
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_bag(out / "multi.mcap", scans, ["/scan", "/scan_rear"])
    write_bag(out / "noscan.mcap", scans, [])
    write_bag(out / "lz4.mcap", scans, ["/scan", "/scan_rear"], compression=CompressionType.LZ4)
    # The compression name is a length-prefixed string in each chunk (and
    # chunk index) record: "lz4" -> "brz", same length, nothing else moves.
    lz4 = (out / "lz4.mcap").read_bytes()
    name = b"\x03\x00\x00\x00lz4"
    assert lz4.count(name) >= 2
    (out / "brotli.mcap").write_bytes(lz4.replace(name, b"\x03\x00\x00\x00brz"))
    data = (out / "multi.mcap").read_bytes()
    (out / "truncated.mcap").write_bytes(data[: len(data) * 6 // 10])
    return out


if __name__ == "__main__":
    scans = [json.loads(l) for l in Path(sys.argv[1]).read_text().splitlines() if l.strip()]
    make_all(scans, sys.argv[2])
