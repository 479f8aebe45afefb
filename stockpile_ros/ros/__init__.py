"""ROS messages without a node: topics, types, builders and readers, publications.

The topic table, our types in the rosbags typestore, message builders and readers written once for
rclpy and rosbags, and what the node set publishes. Imports neither rclpy nor a message package:
the nodes pass their classes in (a message factory).
"""
