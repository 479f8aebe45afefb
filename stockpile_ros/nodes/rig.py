"""The node set in one process, on one multi-threaded executor, whole or by role.

``rig`` runs all three nodes; ``rig --role cart`` the keyframe node alone (on the cart, next to
the camera) and ``rig --role base`` the reconstruction and segmentation (on a base station),
which then share nothing with the cart but DDS. Remaining arguments go to ROS (``--ros-args``).
"""

from __future__ import annotations

import argparse
import sys

from .common import spin
from .keyframe_node import KeyframeNode
from .reconstruction_node import ReconstructionNode
from .segmentation_node import SegmentationNode

__all__ = ['ROLES', 'main']

ROLES = {
    'all': (KeyframeNode, ReconstructionNode, SegmentationNode),
    'cart': (KeyframeNode,),
    'base': (ReconstructionNode, SegmentationNode),
}
"""The nodes of each role."""


def main(args: list[str] | None = None) -> None:
    """Run the nodes of one role (``--role all|cart|base``, all by default)."""
    parser = argparse.ArgumentParser(prog='rig', description=__doc__)
    parser.add_argument('--role', choices=sorted(ROLES), default='all')
    known, ros_args = parser.parse_known_args(sys.argv[1:] if args is None else args)
    spin(*ROLES[known.role], args=[sys.argv[0], *ros_args])


if __name__ == '__main__':
    main()
