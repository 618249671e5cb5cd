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
