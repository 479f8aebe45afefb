"""Launch the stockpile_ros node set on a cart, a base station, or against `ros2 bag play --clock`.

Arguments:
  role:              all: every node here; cart: the keyframe node alone (beside the camera);
                     base: reconstruction and segmentation (a base station that shares nothing
                     with the cart but DDS: keyframes and results travel as messages).
  composed:          true: the role's nodes in one process (one executor); false: one process each.
  params_file:       parameters (default: the package's config/stockpile.yaml).
  image_topic:       camera image topic to remap camera/image_raw to.
  camera_info_topic: camera info topic to remap camera/camera_info to.
  odom_topic:        nav_msgs/Odometry topic to remap odom to.
  use_sim_time:      true when replaying a bag with --clock.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node

from launch import LaunchDescription

# executable, node name, the roles that run it (as stockpile_ros.nodes.rig.ROLES).
NODES = (
    ('keyframe_node', 'stockpile_keyframes', ('all', 'cart')),
    ('reconstruction_node', 'stockpile_reconstruction', ('all', 'base')),
    ('segmentation_node', 'stockpile_segmentation', ('all', 'base')),
)


def _when(composed, roles):
    """True when the launch's ``composed`` is ``composed`` and its role one of ``roles``."""
    return IfCondition(PythonExpression([
        "'", LaunchConfiguration('composed'), f"' == '{composed}' and '",
        LaunchConfiguration('role'), f"' in {list(roles)!r}",
    ]))  # fmt: skip


def generate_launch_description():
    share = get_package_share_directory('stockpile_ros')
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
        DeclareLaunchArgument('role', default_value='all', choices=['all', 'cart', 'base']),
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
            # No name=: in one process it would rename all the nodes alike.
            arguments=['--role', LaunchConfiguration('role')],
            parameters=params,
            remappings=remappings,
            output='screen',
            condition=_when('true', ('all', 'cart', 'base')),
        ),
    ]
    for executable, name, roles in NODES:
        actions.append(
            Node(
                package='stockpile_ros',
                executable=executable,
                name=name,
                parameters=params,
                remappings=remappings,
                output='screen',
                condition=_when('false', roles),
            )
        )
    return LaunchDescription(actions)
