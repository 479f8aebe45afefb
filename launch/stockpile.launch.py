"""Launch the stockpile_ros node set on the cart, or against `ros2 bag play --clock`.

Arguments:
  composed:          true: the three nodes in one process (one executor); false: three processes.
  params_file:       parameters (default: the package's config/stockpile.yaml).
  image_topic:       camera image topic to remap camera/image_raw to.
  camera_info_topic: camera info topic to remap camera/camera_info to.
  odom_topic:        nav_msgs/Odometry topic to remap odom to.
  use_sim_time:      true when replaying a bag with --clock.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition, UnlessCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription

NODES = (
    ('keyframe_node', 'stockpile_keyframes'),
    ('reconstruction_node', 'stockpile_reconstruction'),
    ('segmentation_node', 'stockpile_segmentation'),
)


def generate_launch_description():
    share = get_package_share_directory('stockpile_ros')
    composed = LaunchConfiguration('composed')
    params = [
        LaunchConfiguration('params_file'),
        {'use_sim_time': LaunchConfiguration('use_sim_time')},
    ]
    remappings = [
        ('camera/image_raw', LaunchConfiguration('image_topic')),
        ('camera/image_raw/compressed', [LaunchConfiguration('image_topic'), '/compressed']),
        ('camera/camera_info', LaunchConfiguration('camera_info_topic')),
        ('odom', LaunchConfiguration('odom_topic')),
    ]
    actions = [
        DeclareLaunchArgument('composed', default_value='false'),
        DeclareLaunchArgument(
            'params_file', default_value=os.path.join(share, 'config', 'stockpile.yaml')
        ),
        DeclareLaunchArgument('image_topic', default_value='/camera/image_raw'),
        DeclareLaunchArgument('camera_info_topic', default_value='/camera/camera_info'),
        DeclareLaunchArgument('odom_topic', default_value='/odom'),
        DeclareLaunchArgument('use_sim_time', default_value='false'),
        Node(
            package='stockpile_ros',
            executable='rig',
            # No name=: in one process it would rename all three nodes alike.
            parameters=params,
            remappings=remappings,
            output='screen',
            condition=IfCondition(composed),
        ),
    ]
    for executable, name in NODES:
        actions.append(
            Node(
                package='stockpile_ros',
                executable=executable,
                name=name,
                parameters=params,
                remappings=remappings,
                output='screen',
                condition=UnlessCondition(composed),
            )
        )
    return LaunchDescription(actions)
