"""refloc_ros.logic with the ROS 2 message types of rosbags.typesys (ROS 2
Humble definitions) and the real refloc package: LaserScan in,
PoseWithCovarianceStamped out, serialized to CDR by rosbags to prove the
messages are well-typed; the Decider's publish/pending rules."""
import math
import os
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from refloc_ros import logic  # noqa: E402

refloc = pytest.importorskip("refloc")
ROOT = Path(os.environ.get("REFLOC_ROOT", Path(__file__).resolve().parents[3]))
TS = get_typestore(Stores.ROS2_HUMBLE)
T = TS.types
TYPES = types.SimpleNamespace(
    Header=T["std_msgs/msg/Header"], Time=T["builtin_interfaces/msg/Time"],
    Pose=T["geometry_msgs/msg/Pose"], Point=T["geometry_msgs/msg/Point"],
    Quaternion=T["geometry_msgs/msg/Quaternion"],
    PoseWithCovariance=T["geometry_msgs/msg/PoseWithCovariance"],
    PoseWithCovarianceStamped=T["geometry_msgs/msg/PoseWithCovarianceStamped"])


def laser_scan(ranges, angle_min, inc, sec=100, nanosec=5, range_max=30.0):
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    n = len(ranges)
    return T["sensor_msgs/msg/LaserScan"](
        header=Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id="laser"),
        angle_min=angle_min, angle_max=angle_min + (n - 1) * inc, angle_increment=inc,
        time_increment=0.0, scan_time=0.1, range_min=0.05, range_max=range_max,
        ranges=np.asarray(ranges, dtype=np.float32), intensities=np.zeros(0, dtype=np.float32))


@pytest.fixture(scope="module")
def db(tmp_path_factory):
    out = tmp_path_factory.mktemp("ros") / "office.refdb"
    refloc.build(ROOT / "maps" / "office-demo" / "office-demo.yaml", out)
    return refloc.RefDb(out)


def wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def test_scan_becomes_an_initialpose_with_covariance(db):
    x, y, th = db.site_position(3) + (0.7,)
    ranges, amin, inc = db.simulate_scan(x, y, th, beams=360)
    msg = laser_scan(ranges, amin, inc)
    d = logic.Decider(refloc.Localizer(db), TYPES)
    out = d.on_scan(msg)
    assert out.success and out.publish is not None
    assert out.message.startswith("confidence ")
    p = out.publish
    assert p.header.frame_id == "map" and (p.header.stamp.sec, p.header.stamp.nanosec) == (100, 5)
    q = p.pose.pose.orientation
    yaw = math.atan2(2 * q.w * q.z, 1 - 2 * q.z * q.z)
    assert math.hypot(p.pose.pose.position.x - x, p.pose.pose.position.y - y) < 0.3
    assert abs(wrap(yaw - th)) < math.radians(5)
    cov = p.pose.covariance
    assert cov.shape == (36,) and cov[0] > 0 and cov[7] > 0 and cov[35] > 0
    assert cov[14] == cov[21] == cov[28] == 0
    # rosbags serializes it as the ROS 2 type: the fields and types are right.
    raw = TS.serialize_cdr(p, "geometry_msgs/msg/PoseWithCovarianceStamped")
    back = TS.deserialize_cdr(raw, "geometry_msgs/msg/PoseWithCovarianceStamped")
    assert np.array_equal(back.pose.covariance, cov)
    # Pending ends after an accepted pose: the next scan publishes nothing.
    assert d.on_scan(msg) is None
    d.reinitialize()
    assert d.on_scan(msg).publish is not None


def test_covariance_mapping():
    c = logic.covariance_6x6(np.arange(1, 10, dtype=np.float32).reshape(3, 3))
    assert (c[0], c[1], c[5], c[6], c[30], c[35]) == (1, 2, 3, 4, 7, 9)
    assert np.count_nonzero(c) == 9
    assert not logic.covariance_6x6(None).any()


class Fake:
    """A localizer that answers what it is told."""
    def __init__(self, accepted, confidence=0.5):
        self.accepted, self.confidence, self.calls = accepted, confidence, 0

    def localize(self, ranges, amin, inc, rmin, rmax):
        self.calls += 1
        return types.SimpleNamespace(pose=(1.0, 2.0, 0.5), accepted=self.accepted,
                                     confidence=self.confidence, covariance=None, hypotheses=[1, 2])


def test_not_accepted_publishes_nothing_and_stays_pending():
    f = Fake(False, 0.25)
    d = logic.Decider(f, TYPES)
    msg = laser_scan([1.0] * 10, -1.0, 0.2)
    out = d.on_scan(msg)
    assert out.publish is None and not out.success and "confidence 0.250 not accepted" in out.message
    assert d.pending and d.on_scan(msg) is not None and f.calls == 2


def test_localize_service_without_scan_and_on_demand():
    d = logic.Decider(Fake(True, 0.9), TYPES, localize_on_start=False)
    assert d.localize_now().message == "no scan received yet"
    msg = laser_scan([1.0] * 10, -1.0, 0.2)
    assert d.on_scan(msg) is None  # not pending: no localization on scans
    out = d.localize_now()
    assert out.success and out.publish is not None and "confidence 0.900 accepted" in out.message


def test_bad_scans_are_replies_not_crashes():
    d = logic.Decider(Fake(True), TYPES)
    out = d.on_scan(laser_scan([], -1.0, 0.2))
    assert not out.success and "no ranges" in out.message
    out = d.on_scan(laser_scan([1.0] * 4, -1.0, 0.0))
    assert not out.success and "angle_increment" in out.message
