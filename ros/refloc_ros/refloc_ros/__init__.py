"""ROS 2 wrapper of refloc: global localization from one laser scan."""
