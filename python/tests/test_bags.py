"""`mapc localize DB BAG`: ROS 2 bags (rosbag2 MCAP) written at test time by
the independent `mcap` / `mcap-ros2-support` libraries (make_bags.py), read
by mapc's own MCAP + CDR reader. Also the `--mcap` recording mapc writes,
read back with the Python `mcap` reader and `mcap-ros2-support` decoder."""
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
import make_bags  # noqa: E402

ROOT = Path(os.environ.get("REFLOC_ROOT", Path(__file__).resolve().parents[2]))
MAPC = os.environ.get("REFLOC_MAPC", str(ROOT / "target" / "debug" / "mapc"))
MAP = ROOT / "maps" / "office-demo" / "office-demo.yaml"
N = 12


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    d = tmp_path_factory.mktemp("bags")
    subprocess.run([MAPC, "build", "-q", str(MAP), "-o", str(d / "office.refdb")],
                   check=True, capture_output=True)
    subprocess.run(
        [MAPC, "eval", str(d / "office.refdb"), "--poses", str(N), "--experiments", "static",
         "--no-figures", "--out", str(d / "eval"), "--dump", str(d)],
        check=True, capture_output=True)
    scans = [json.loads(l) for l in (d / "static-scans.jsonl").read_text().splitlines()]
    truth = [list(map(float, l.split()[3:6])) for l in (d / "static-truth.txt").read_text().splitlines()
             if l.strip() and not l.startswith("#")]
    assert len(scans) == len(truth) == N
    make_bags.make_all(scans, d)
    return d, truth


def localize(d, *args):
    return subprocess.run([MAPC, "localize", str(d / "office.refdb"), *map(str, args)],
                          capture_output=True, text=True)


def results(p):
    return [json.loads(l) for l in p.stdout.splitlines()]


def wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def test_several_scan_topics_need_topic(work):
    d, _ = work
    p = localize(d, d / "multi.mcap")
    assert p.returncode == 2, p.stderr
    assert "several sensor_msgs/msg/LaserScan topics" in p.stderr
    assert "/scan [" in p.stderr and "/scan_rear [" in p.stderr and "--topic" in p.stderr
    assert p.stdout == ""


def test_topic_is_localized_with_its_stamps(work):
    d, truth = work
    p = localize(d, d / "multi.mcap", "--topic", "/scan", "--no-candidates")
    assert p.returncode == 0, p.stderr
    rs = results(p)
    assert [r["id"] for r in rs] == [f"msg {k}" for k in range(N)]
    for k, r in enumerate(rs):
        ns, _ = make_bags.stamp(k)
        assert r["stamp_ns"] == ns and r["log_time_ns"] == ns
        assert r["frame_id"] == "scan_link"
    right = sum(1 for r, t in zip(rs, truth)
                if r["accepted"] and math.hypot(r["x"] - t[0], r["y"] - t[1]) < 0.3
                and abs(wrap(r["theta"] - t[2])) < math.radians(5))
    wrong = sum(1 for r, t in zip(rs, truth)
                if r["accepted"] and math.hypot(r["x"] - t[0], r["y"] - t[1]) >= 0.3)
    assert right >= N - 2 and wrong == 0, (right, wrong)
    # The same scans as JSON Lines give the same poses: the bag path loses nothing.
    q = localize(d, d / "static-scans.jsonl", "--no-candidates")
    for a, b in zip(rs, results(q)):
        assert (a["accepted"], a["x"], a["y"], a["theta"]) == (b["accepted"], b["x"], b["y"], b["theta"])


def test_lz4_chunks_read_as_zstd_ones(work):
    d, _ = work
    zstd = results(localize(d, d / "multi.mcap", "--topic", "/scan", "--no-candidates"))
    p = localize(d, d / "lz4.mcap", "--topic", "/scan", "--no-candidates")
    assert p.returncode == 0, p.stderr
    rs = results(p)
    assert len(rs) == N
    for a, b in zip(rs, zstd):
        assert (a["id"], a["stamp_ns"], a["accepted"], a["x"], a["y"], a["theta"]) == \
            (b["id"], b["stamp_ns"], b["accepted"], b["x"], b["y"], b["theta"])


def test_unknown_chunk_compression_is_a_clear_error(work):
    d, _ = work
    p = localize(d, d / "brotli.mcap", "--topic", "/scan")
    assert p.returncode != 0
    said = p.stderr + p.stdout
    assert "brz" in said and "not supported" in said and "zstd, lz4" in said, said


def test_sqlite3_bag_is_refused_with_how_to_convert(work, tmp_path):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    d, _ = work
    ts = get_typestore(Stores.ROS2_HUMBLE)
    with Writer(tmp_path / "bag", version=8, storage_plugin=StoragePlugin.SQLITE3) as w:
        w.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=ts)
    p = localize(d, tmp_path / "bag" / "bag.db3")
    assert p.returncode == 2 and p.stdout == ""
    assert "SQLite file" in p.stderr and "--dst-storage mcap" in p.stderr, p.stderr


def test_other_topic_types_are_refused(work):
    d, _ = work
    p = localize(d, d / "multi.mcap", "--topic", "/chatter")
    assert p.returncode == 2
    assert "/chatter is std_msgs/msg/String" in p.stderr
    p = localize(d, d / "multi.mcap", "--topic", "/nope")
    assert p.returncode == 2 and "no topic /nope" in p.stderr and "/odom [" in p.stderr


def test_bag_without_scans_lists_its_topics(work):
    d, _ = work
    p = localize(d, d / "noscan.mcap")
    assert p.returncode == 2
    assert "no sensor_msgs/msg/LaserScan topic" in p.stderr
    assert "/chatter [std_msgs/msg/String, 12 messages]" in p.stderr
    assert "/odom [geometry_msgs/msg/Pose2D, 12 messages]" in p.stderr


def test_truncated_bag_localizes_what_is_there_then_fails(work):
    d, _ = work
    full = results(localize(d, d / "multi.mcap", "--topic", "/scan", "--no-candidates"))
    p = localize(d, d / "truncated.mcap", "--topic", "/scan", "--no-candidates")
    assert p.returncode == 1, p.stderr
    rs = results(p)
    assert "ends early" in rs[-1]["error"] and "cut-off" in rs[-1]["error"]
    good = rs[:-1]
    assert 0 < len(good) < N
    for a, b in zip(good, full):
        assert (a["id"], a["x"], a["y"], a["stamp_ns"]) == (b["id"], b["x"], b["y"], b["stamp_ns"])


def yaw(q):
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def decoded(path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    with open(path, "rb") as f:
        r = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = r.get_summary()
        msgs = {}
        for schema, ch, m, d in r.iter_decoded_messages():
            msgs.setdefault(ch.topic, []).append((m.log_time, d))
    return summary, msgs


def test_mcap_recording_reads_back_in_the_python_reader(work):
    d, _ = work
    out = d / "out.mcap"
    p = localize(d, d / "multi.mcap", "--topic", "/scan", "--no-candidates", "--mcap", out)
    assert p.returncode == 0, p.stderr
    rs = results(p)
    summary, msgs = decoded(out)
    types = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert types == {
        "/map": "nav_msgs/msg/OccupancyGrid",
        "/scan": "sensor_msgs/msg/LaserScan",
        "/tf": "tf2_msgs/msg/TFMessage",
        "/refloc/pose": "geometry_msgs/msg/PoseWithCovarianceStamped",
        "/refloc/hypotheses": "geometry_msgs/msg/PoseArray",
    }
    assert all(s.encoding == "ros2msg" for s in summary.schemas.values())
    assert all(c.message_encoding == "cdr" for c in summary.channels.values())
    stamps = [make_bags.stamp(k)[0] for k in range(N)]

    [(t, grid)] = msgs["/map"]
    assert t == stamps[0] and grid.header.frame_id == "map"
    assert abs(grid.info.resolution - 0.05) < 1e-7  # office-demo.yaml
    assert len(grid.data) == grid.info.width * grid.info.height > 0
    occ = sum(1 for v in grid.data if v == 100)
    assert 0 < occ < len(grid.data) and all(v in (0, 100) for v in grid.data)

    _, bag_in = decoded(d / "multi.mcap")
    assert [t for t, _ in msgs["/scan"]] == stamps
    for (_, a), (_, b) in zip(msgs["/scan"], bag_in["/scan"]):
        assert a.header.frame_id == "scan_link"
        assert (a.header.stamp.sec, a.header.stamp.nanosec) == (b.header.stamp.sec, b.header.stamp.nanosec)
        assert list(a.ranges) == list(b.ranges)
        assert (a.angle_min, a.angle_increment) == (b.angle_min, b.angle_increment)

    acc = [(s, r) for s, r in zip(stamps, rs) if r["accepted"]]
    poses = msgs["/refloc/pose"]
    assert [t for t, _ in poses] == [s for s, _ in acc]
    for (_, m), (_, r) in zip(poses, acc):
        assert m.header.frame_id == "map"
        pp = m.pose.pose
        assert abs(pp.position.x - r["x"]) < 1e-5 and abs(pp.position.y - r["y"]) < 1e-5
        assert abs(wrap(yaw(pp.orientation) - r["theta"])) < 1e-5
        c3, c6 = r["covariance"], list(m.pose.covariance)
        for i, a in enumerate((0, 1, 5)):
            for j, b in enumerate((0, 1, 5)):
                assert abs(c6[a * 6 + b] - c3[i * 3 + j]) < 1e-9
        assert sum(1 for v in c6 if v != 0) <= 9
    tfs = msgs["/tf"]
    assert len(tfs) == len(acc)
    for (_, m), (_, r) in zip(tfs, acc):
        [tr] = m.transforms
        assert (tr.header.frame_id, tr.child_frame_id) == ("map", "scan_link")
    hyps = msgs["/refloc/hypotheses"]
    assert len(hyps) == N
    for (_, m), r in zip(hyps, rs):
        assert len(m.poses) == len(r["hypotheses"]) >= 1
        assert abs(m.poses[0].position.x - r["hypotheses"][0]["x"]) < 1e-5
