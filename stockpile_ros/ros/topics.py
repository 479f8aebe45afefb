"""The one table of what the node set subscribes to and publishes: name, type, QoS, owner (REP 144).

The nodes create their subscriptions and publishers from it, the replay writes the same topics
(absolute) into its output bag with the same offered QoS, and the tests check both against it.
Names are relative, so that a launch namespace or remapping moves them all.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

__all__ = [
    'CAMERA_INFO',
    'CLOUD',
    'COMPRESSED_SUFFIX',
    'DENSE_CLOUD',
    'DIAGNOSTICS',
    'GRADATION',
    'IMAGE',
    'KEYFRAMES',
    'KEYFRAME_STATUS',
    'MESH',
    'ODOMETRY',
    'QOS_DEPTH',
    'RECONSTRUCT_SERVICE',
    'ROCKS',
    'ROCK_MARKERS',
    'SEGMENTED_CLOUD',
    'STATUS',
    'SURFACE',
    'TABLE',
    'TF',
    'TF_STATIC',
    'TRIGGER',
    'Qos',
    'Topic',
    'absolute',
    'published_by',
    'subscribed_by',
    'topic',
]

Qos = Literal['sensor', 'pose', 'reliable', 'stream', 'latched', 'status', 'tf', 'tf_static']
"""QoS classes (the nodes map each onto an rclpy profile, the replay onto the offered QoS):

- ``sensor``: best effort, keep last 50 (camera, camera info: a lost sample is not sent again, so
  it matches any publisher; the depth lets a busy node catch up on a burst instead of losing
  frames, which would change the keyframes);
- ``pose``: best effort, keep last 1000 (odometry: small samples at 30-100 Hz; a node busy with its
  first keyframes lost the first seconds of a 30 Hz stream with 50, and those keyframes went out
  without a pose);
- ``reliable``: reliable, volatile, keep last 10 (triggers);
- ``stream``: reliable, transient local, keep all (keyframes: every one must arrive, also at a
  reconstruction that matched the keyframe node after the first ones were sent, or restarted;
  the publisher holds at most ``selector.max_keyframes`` of them);
- ``latched``: reliable, transient local, keep last 1 (results: a dashboard that joins late gets
  the last one);
- ``status``: reliable, transient local, keep last 10 (pipeline statuses: with a writer's history
  of one, a status replaced before a reader had it was never delivered, and "mesh ready;
  segmenting" followed by the result within milliseconds lost the first; a late joiner gets the
  last ten, the newest last);
- ``tf`` and ``tf_static``: reliable, keep last 1000 (tf2's own use 100; a moving mast's transforms
  must not be dropped while the node is busy), the static one transient local.
"""

QOS_DEPTH: dict[Qos, int] = {
    'sensor': 50,
    'pose': 1000,
    'reliable': 10,
    'stream': 0,
    'latched': 1,
    'status': 10,
    'tf': 1000,
    'tf_static': 1000,
}
"""History depth of each class (0: keep all)."""

Component = Literal['keyframes', 'reconstruction', 'segmentation']


@dataclass(frozen=True)
class Topic:
    """One topic of the node set.

    Attributes:
        name: Relative name (``/``-prefixed where a standard tool listens at the root).
        msgtype: ``pkg/msg/Name``.
        qos: QoS class, see :data:`Qos`.
        publishers: Components that publish it (empty: an input of the node set).
        subscribers: Components that subscribe to it.

    """

    name: str
    msgtype: str
    qos: Qos
    publishers: tuple[Component, ...] = ()
    subscribers: tuple[Component, ...] = ()


# Inputs.
IMAGE = 'camera/image_raw'
COMPRESSED_SUFFIX = '/compressed'
CAMERA_INFO = 'camera/camera_info'
CLOUD = 'points'
ODOMETRY = 'odom'
TF = '/tf'
TF_STATIC = '/tf_static'
TRIGGER = 'stockpile/trigger'
RECONSTRUCT_SERVICE = 'stockpile/reconstruct'  # std_srvs/Trigger
# Between the components (and so between the cart and a base station).
KEYFRAMES = 'stockpile/keyframes'
KEYFRAME_STATUS = 'stockpile/keyframes/status'
SURFACE = 'stockpile/surface'
# Outputs.
DIAGNOSTICS = '/diagnostics'
DENSE_CLOUD = 'stockpile/dense_cloud'
MESH = 'stockpile/mesh'
SEGMENTED_CLOUD = 'stockpile/segmented_cloud'
ROCK_MARKERS = 'stockpile/rock_markers'
ROCKS = 'stockpile/rocks'
GRADATION = 'stockpile/gradation'
STATUS = 'stockpile/status'

_KF: Component = 'keyframes'
_RC: Component = 'reconstruction'
_SG: Component = 'segmentation'

TABLE: tuple[Topic, ...] = (
    Topic(IMAGE, 'sensor_msgs/msg/Image', 'sensor', (), (_KF,)),
    Topic(IMAGE + COMPRESSED_SUFFIX, 'sensor_msgs/msg/CompressedImage', 'sensor', (), (_KF,)),
    Topic(CAMERA_INFO, 'sensor_msgs/msg/CameraInfo', 'sensor', (), (_KF,)),
    # A depth camera's or a LiDAR's points (cloud.source): the reconstruction accumulates them
    # in the odometry frame, so it takes the odometry and the transforms too.
    Topic(CLOUD, 'sensor_msgs/msg/PointCloud2', 'sensor', (), (_RC,)),
    Topic(ODOMETRY, 'nav_msgs/msg/Odometry', 'pose', (), (_KF, _RC)),
    # Where the camera sits on the cart (its offset from the odometry's base frame); the
    # reconstruction also places the stockpile frame in the odometry frame on /tf_static.
    Topic(TF, 'tf2_msgs/msg/TFMessage', 'tf', (), (_KF, _RC)),
    Topic(TF_STATIC, 'tf2_msgs/msg/TFMessage', 'tf_static', (_RC,), (_KF, _RC)),
    # std_msgs/Empty: reconstruct now (recorded triggers replay).
    Topic(TRIGGER, 'std_msgs/msg/Empty', 'reliable', (), (_RC,)),
    # Each keyframe with its image, camera and pose: nothing but DDS between cart and base.
    Topic(KEYFRAMES, 'stockpile_msgs/msg/Keyframe', 'stream', (_KF,), (_RC,)),
    Topic(KEYFRAME_STATUS, 'stockpile_msgs/msg/PipelineStatus', 'status', (_KF,), (_RC,)),
    # The metric z-up surface the segmentation cuts into rocks.
    Topic(SURFACE, 'stockpile_msgs/msg/SurfaceMesh', 'latched', (_RC,), (_SG,)),
    # Absolute: the diagnostic aggregator listens there.
    Topic(DIAGNOSTICS, 'diagnostic_msgs/msg/DiagnosticArray', 'latched', (_KF, _RC, _SG)),
    Topic(DENSE_CLOUD, 'sensor_msgs/msg/PointCloud2', 'latched', (_RC,)),  # x, y, z, rgb
    Topic(MESH, 'visualization_msgs/msg/MarkerArray', 'latched', (_RC,)),  # triangle list
    Topic(SEGMENTED_CLOUD, 'sensor_msgs/msg/PointCloud2', 'latched', (_SG,)),  # + label
    Topic(ROCK_MARKERS, 'visualization_msgs/msg/MarkerArray', 'latched', (_SG,)),
    Topic(ROCKS, 'stockpile_msgs/msg/RockArray', 'latched', (_SG,)),
    Topic(GRADATION, 'stockpile_msgs/msg/Gradation', 'latched', (_SG,)),
    Topic(STATUS, 'stockpile_msgs/msg/PipelineStatus', 'status', (_RC, _SG)),
)


def topic(name: str) -> Topic:
    """Return the table's entry of ``name`` (relative or absolute).

    Raises:
        KeyError: Not a topic of the node set.

    """
    for entry in TABLE:
        if absolute(entry.name) == absolute(name):
            return entry
    raise KeyError(f'{name} is not a topic of the node set')


def absolute(name: str) -> str:
    """Return ``name`` with a leading ``/`` (how the replay writes it into its bag)."""
    return name if name.startswith('/') else '/' + name


def published_by(component: str) -> tuple[Topic, ...]:
    """Topics ``component`` publishes."""
    return tuple(t for t in TABLE if component in t.publishers)


def subscribed_by(component: str) -> tuple[Topic, ...]:
    """Topics ``component`` subscribes to."""
    return tuple(t for t in TABLE if component in t.subscribers)
