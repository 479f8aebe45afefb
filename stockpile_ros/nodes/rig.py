"""The three nodes in one process, on one multi-threaded executor (launch ``composed:=true``)."""

from __future__ import annotations

from .common import spin
from .keyframe_node import KeyframeNode
from .reconstruction_node import ReconstructionNode
from .segmentation_node import SegmentationNode

__all__ = ['main']


def main(args: list[str] | None = None) -> None:
    """Run keyframe, reconstruction and segmentation nodes together."""
    spin(KeyframeNode, ReconstructionNode, SegmentationNode, args=args)


if __name__ == '__main__':
    main()
