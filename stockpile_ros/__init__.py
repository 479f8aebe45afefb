"""stockpile_ros: measure the rocks of a stockpile from a moving camera.

The package is a ROS-free core (numpy, OpenCV, open3d, pycolmap, rosbags) plus thin rclpy
adapters in :mod:`stockpile_ros.nodes`. Nothing outside ``nodes`` imports rclpy or ROS messages.
"""

__all__ = ['__version__']

__version__ = '0.1.0'
