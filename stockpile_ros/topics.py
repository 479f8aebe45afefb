"""Names of what the node set subscribes to and publishes (REP 144), shared by nodes and replay.

Relative names, so that a launch namespace or remapping moves them all. The replay writes the same
names, absolute, into its output bag.
"""

from __future__ import annotations

__all__ = [
    'CAMERA_INFO',
    'COMPRESSED_SUFFIX',
    'DENSE_CLOUD',
    'DIAGNOSTICS',
    'GRADATION',
    'IMAGE',
    'KEYFRAME_STATUS',
    'MESH',
    'MESH_READY',
    'ODOMETRY',
    'RECONSTRUCT_SERVICE',
    'ROCKS',
    'ROCK_MARKERS',
    'SEGMENTED_CLOUD',
    'STATUS',
    'TF_STATIC',
    'TRIGGER',
]

# Inputs.
IMAGE = 'camera/image_raw'
COMPRESSED_SUFFIX = '/compressed'
CAMERA_INFO = 'camera/camera_info'
ODOMETRY = 'odom'
# With /tf_static: where the camera sits on the cart (its offset from the odometry's base frame).
TF = '/tf'  # tf2_msgs/TFMessage
TRIGGER = 'stockpile/trigger'  # std_msgs/Empty: reconstruct now (recorded triggers replay)
RECONSTRUCT_SERVICE = 'stockpile/reconstruct'  # std_srvs/Trigger

# Outputs.
KEYFRAME_STATUS = 'stockpile/keyframes/status'  # stockpile_msgs/PipelineStatus
# Absolute: the diagnostic aggregator listens there.
DIAGNOSTICS = '/diagnostics'  # diagnostic_msgs/DiagnosticArray
DENSE_CLOUD = 'stockpile/dense_cloud'  # sensor_msgs/PointCloud2 (x, y, z, rgb)
MESH = 'stockpile/mesh'  # visualization_msgs/MarkerArray (the Poisson surface as a triangle list)
# Latched: where the stockpile frame lies in the odometry frame.
TF_STATIC = '/tf_static'  # tf2_msgs/TFMessage
MESH_READY = 'stockpile/mesh_ready'  # std_msgs/String: the work folder whose mesh/ is ready
SEGMENTED_CLOUD = 'stockpile/segmented_cloud'  # sensor_msgs/PointCloud2 (x, y, z, rgb, label)
ROCK_MARKERS = 'stockpile/rock_markers'  # visualization_msgs/MarkerArray
ROCKS = 'stockpile/rocks'  # stockpile_msgs/RockArray
GRADATION = 'stockpile/gradation'  # stockpile_msgs/Gradation
STATUS = 'stockpile/status'  # stockpile_msgs/PipelineStatus
