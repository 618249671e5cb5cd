"""The refloc ROS 2 node: thin wiring of rclpy to refloc_ros.logic.

Parameters: refdb (a compiled .refdb) or map_yaml (a map_server YAML, compiled
at start to refdb_cache, default /tmp/refloc_ros.refdb); frame_id (default
map); localize_on_start (default true); max_beams (default 4096).
Subscribes scan (sensor_msgs/msg/LaserScan, remap to your topic); publishes
initialpose (geometry_msgs/msg/PoseWithCovarianceStamped); services
reinitialize_global_localization (std_srvs/srv/Empty) and ~/localize
(std_srvs/srv/Trigger, the confidence in its message).
"""
import types as _types

import rclpy
from builtin_interfaces.msg import Time
from geometry_msgs.msg import (Point, Pose, PoseWithCovariance,
                               PoseWithCovarianceStamped, Quaternion)
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Header
from std_srvs.srv import Empty, Trigger

import refloc

from .logic import Decider

TYPES = _types.SimpleNamespace(Header=Header, Time=Time, Pose=Pose, Point=Point, Quaternion=Quaternion,
                               PoseWithCovariance=PoseWithCovariance,
                               PoseWithCovarianceStamped=PoseWithCovarianceStamped)


class ReflocNode(Node):
    def __init__(self):
        super().__init__("refloc")
        refdb = self.declare_parameter("refdb", "").value
        map_yaml = self.declare_parameter("map_yaml", "").value
        cache = self.declare_parameter("refdb_cache", "/tmp/refloc_ros.refdb").value
        frame_id = self.declare_parameter("frame_id", "map").value
        on_start = self.declare_parameter("localize_on_start", True).value
        max_beams = self.declare_parameter("max_beams", 4096).value
        if not refdb:
            if not map_yaml:
                raise RuntimeError("set the parameter refdb or map_yaml")
            self.get_logger().info(f"compiling {map_yaml} to {cache}")
            refloc.build(map_yaml, cache)
            refdb = cache
        self.db = refloc.RefDb(refdb)
        self.decider = Decider(refloc.Localizer(self.db, max_beams=max_beams), TYPES, frame_id, on_start)
        self.pub = self.create_publisher(PoseWithCovarianceStamped, "initialpose", 1)
        self.create_subscription(LaserScan, "scan", self.on_scan, qos_profile_sensor_data)
        self.create_service(Empty, "reinitialize_global_localization", self.on_reinit)
        self.create_service(Trigger, "~/localize", self.on_localize)
        self.get_logger().info(f"refloc: {refdb}, {self.db.site_count} sites")

    def publish(self, out):
        if out is not None and out.publish is not None:
            self.pub.publish(out.publish)
            self.get_logger().info(f"published /initialpose: {out.message}")

    def on_scan(self, msg):
        self.publish(self.decider.on_scan(msg))

    def on_reinit(self, _req, resp):
        self.decider.reinitialize()
        return resp

    def on_localize(self, _req, resp):
        out = self.decider.localize_now()
        self.publish(out)
        resp.success, resp.message = out.success, out.message
        return resp


def main(args=None):
    rclpy.init(args=args)
    node = ReflocNode()
    try:
        rclpy.spin(node)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
