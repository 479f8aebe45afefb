"""The three nodes in one process, on one multi-threaded executor (launch ``composed:=true``)."""

from __future__ import annotations

import rclpy
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node

from .keyframe_node import KeyframeNode
from .reconstruction_node import ReconstructionNode
from .segmentation_node import SegmentationNode

__all__ = ['main']


def main(args: list[str] | None = None) -> None:
    """Run keyframe, reconstruction and segmentation nodes together."""
    rclpy.init(args=args)
    nodes: list[Node] = []
    executor = MultiThreadedExecutor()
    try:
        nodes = [KeyframeNode(), ReconstructionNode(), SegmentationNode()]
        for node in nodes:
            executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
