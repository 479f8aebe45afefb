"""The ROS 2 node set: the only modules that import rclpy and ROS message packages.

Thin layers over the ROS-free components: messages in, a call into
:mod:`stockpile_ros.recon.collector`, :mod:`stockpile_ros.runner` and :mod:`stockpile_ros.publish`,
messages out.
"""
