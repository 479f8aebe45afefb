"""The ROS 2 node set: the only modules that import rclpy and ROS message packages.

Thin layers over the ROS-free components (:mod:`stockpile_ros.components`): messages in, a call
into a component, the publications it returns out.
"""
