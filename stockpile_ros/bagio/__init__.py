"""ROS 2 bag input and output with rosbags (no ROS installation needed)."""
