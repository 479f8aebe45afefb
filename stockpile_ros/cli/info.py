"""``stockpile info BAG``: what a bag holds and what is wrong with it."""

from __future__ import annotations

import argparse
import json

from ..bagio.summary import format_summary, summarize

__all__ = ['DESCRIPTION', 'add_arguments', 'run']

DESCRIPTION = """\
Summarise a ROS 2 bag (a rosbag2 folder, an .mcap or a .db3 file; MCAP or sqlite3).

Prints the storage format, start, end and duration, and per topic its type and message count. Every
image message (sensor_msgs/Image, sensor_msgs/CompressedImage) is decoded: the summary gives the
image sizes, encodings or formats, frame rate, and whether a CameraInfo matches the frames. It then
says where odometry comes from (nav_msgs/Odometry, or /tf odom->base_link) and lists every bad
message with its topic, index and what is wrong.

examples:
  stockpile info bags/pile.mcap
  stockpile info bags/pile --json > pile.json
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``info`` arguments."""
    parser.add_argument('bag', help='rosbag2 folder, .mcap or .db3 file')
    parser.add_argument('--json', action='store_true', help='print the summary as JSON')
    parser.add_argument(
        '--no-decode',
        action='store_true',
        help='do not decode the images (fast; no sizes, encodings or problems)',
    )


def run(args: argparse.Namespace) -> int:
    """Print the summary; 0 on success (bad messages are reported, not fatal)."""
    summary = summarize(args.bag, decode=not args.no_decode)
    if args.json:
        print(json.dumps(summary.to_dict(), indent=2))
    else:
        print(format_summary(summary))
    return 0
