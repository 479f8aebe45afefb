"""The node set's components, free of ROS: one per node, each owning its state and its messages.

Each takes messages as plain data (rosbags or rclpy objects: the same field names) and returns,
or emits, the ``(topic, message)`` pairs to publish. The nodes in :mod:`stockpile_ros.nodes` wire
them to rclpy; :mod:`stockpile_ros.replay` drives them from a bag. Topics: :mod:`.topics`.
"""

from .keyframes import WAIT_NS, KeyframeComponent, KeyframeCounts
from .reconstruction import Emit, ReconstructionComponent
from .segmentation import SegmentationComponent, result_lines, verdict

__all__ = [
    'WAIT_NS',
    'Emit',
    'KeyframeComponent',
    'KeyframeCounts',
    'ReconstructionComponent',
    'SegmentationComponent',
    'result_lines',
    'verdict',
]
