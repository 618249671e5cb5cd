"""Everything the node decides and converts, without rclpy.

The node (node.py) only wires ROS to these functions; they take and build
messages through the constructors they are given (`types`), so the same code
runs with rclpy's generated classes and, in the tests, with the ROS 2 message
types of `rosbags.typesys`. A `types` object has the attributes Header, Time,
Pose, Point, Quaternion, PoseWithCovariance, PoseWithCovarianceStamped.
"""
import math
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

# Rows/columns of x, y and yaw in a PoseWithCovariance's 6x6 covariance
# (x, y, z, rotation about X, Y, Z).
_XY_YAW = (0, 1, 5)


def scan_args(msg) -> tuple:
    """A sensor_msgs/msg/LaserScan as the arguments of Localizer.localize:
    (ranges as a float32 array, angle_min, angle_increment, range_min,
    range_max). NaN and out-of-range readings are left for refloc, which
    treats them as no return."""
    ranges = np.asarray(msg.ranges, dtype=np.float32)
    if ranges.size == 0:
        raise ValueError("LaserScan has no ranges")
    if not (math.isfinite(msg.angle_increment) and msg.angle_increment != 0.0):
        raise ValueError(f"LaserScan angle_increment {msg.angle_increment} is not usable")
    range_max = float(msg.range_max) if math.isfinite(msg.range_max) and msg.range_max > 0 else 30.0
    range_min = float(msg.range_min) if math.isfinite(msg.range_min) and msg.range_min >= 0 else 0.0
    return ranges, float(msg.angle_min), float(msg.angle_increment), range_min, range_max


def covariance_6x6(cov3) -> np.ndarray:
    """The 3x3 (x, y, yaw) covariance in the 6x6 of a PoseWithCovariance
    (float64, 36 values, row-major); all zero when there is none."""
    out = np.zeros(36, dtype=np.float64)
    if cov3 is not None:
        c = np.asarray(cov3, dtype=np.float64).reshape(3, 3)
        for i, a in enumerate(_XY_YAW):
            for j, b in enumerate(_XY_YAW):
                out[a * 6 + b] = c[i, j]
    return out


def yaw_quaternion(types, theta: float):
    """A rotation of theta about z."""
    return types.Quaternion(x=0.0, y=0.0, z=math.sin(theta / 2), w=math.cos(theta / 2))


def pose_msg(types, result, stamp, frame_id: str = "map"):
    """A geometry_msgs/msg/PoseWithCovarianceStamped of an accepted result
    (refloc.Localization), stamped with the scan's stamp."""
    x, y, theta = result.pose
    pose = types.Pose(position=types.Point(x=float(x), y=float(y), z=0.0),
                      orientation=yaw_quaternion(types, float(theta)))
    return types.PoseWithCovarianceStamped(
        header=types.Header(stamp=stamp, frame_id=frame_id),
        pose=types.PoseWithCovariance(pose=pose, covariance=covariance_6x6(result.covariance)))


def describe(result) -> str:
    """The ~/localize reply: the confidence first, then the pose."""
    x, y, theta = result.pose
    return (f"confidence {result.confidence:.3f} {'accepted' if result.accepted else 'not accepted'}"
            f" pose x {x:.3f} m y {y:.3f} m theta {theta:.4f} rad"
            f" hypotheses {len(result.hypotheses)}")


@dataclass
class Outcome:
    """What the node does with one localization."""
    publish: Any  # a PoseWithCovarianceStamped to publish on /initialpose, or None
    success: bool  # for ~/localize
    message: str


class Decider:
    """When to localize and what to publish.

    Pending from the start and after reinitialize(): each incoming scan is
    localized until one is accepted; that pose is published on /initialpose
    and pending ends (so a running AMCL is not reset on every scan).
    localize_now() (~/localize) localizes the latest scan whatever the state
    and publishes when accepted.
    """

    def __init__(self, localizer, types, frame_id: str = "map", localize_on_start: bool = True):
        self.localizer = localizer
        self.types = types
        self.frame_id = frame_id
        self.pending = localize_on_start
        self.latest = None

    def reinitialize(self) -> None:
        """reinitialize_global_localization: look again from the next scan."""
        self.pending = True

    def _run(self, msg) -> Outcome:
        try:
            r = self.localizer.localize(*scan_args(msg))
        except Exception as e:  # refloc.LocalizeError or a bad message: a reply, not a crash
            return Outcome(None, False, f"not localized: {e}")
        pub = pose_msg(self.types, r, msg.header.stamp, self.frame_id) if r.accepted else None
        return Outcome(pub, bool(r.accepted), describe(r))

    def on_scan(self, msg) -> Optional[Outcome]:
        """A scan arrived: remembered; localized when pending."""
        self.latest = msg
        if not self.pending:
            return None
        out = self._run(msg)
        if out.success:
            self.pending = False
        return out

    def localize_now(self) -> Outcome:
        """~/localize: the latest scan, now."""
        if self.latest is None:
            return Outcome(None, False, "no scan received yet")
        out = self._run(self.latest)
        if out.success:
            self.pending = False
        return out
