"""refloc next to Nav2: the same `namespace`, `use_sim_time` and `map`
arguments as nav2_bringup, so it can be included beside bringup_launch.py;
it publishes `initialpose` (relative, so a namespaced AMCL gets it)."""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    args = [
        DeclareLaunchArgument("namespace", default_value=""),
        DeclareLaunchArgument("use_sim_time", default_value="false"),
        DeclareLaunchArgument("map", default_value="", description="map_server YAML (compiled at start)"),
        DeclareLaunchArgument("refdb", default_value="", description="a compiled .refdb (instead of map)"),
        DeclareLaunchArgument("scan_topic", default_value="scan"),
    ]
    node = Node(
        package="refloc_ros",
        executable="refloc_node",
        name="refloc",
        namespace=LaunchConfiguration("namespace"),
        output="screen",
        parameters=[{
            "use_sim_time": LaunchConfiguration("use_sim_time"),
            "map_yaml": LaunchConfiguration("map"),
            "refdb": LaunchConfiguration("refdb"),
        }],
        remappings=[("scan", LaunchConfiguration("scan_topic"))],
    )
    return LaunchDescription(args + [node])
