"""Publish a recorded bag's inputs of the node set into live nodes (``rosbag2`` is not on PyPI).

``python -m stockpile_ros.nodes.player BAG [--rate R] [--wait-subscribers S]`` (or
``stockpile-play``): the bag topics that carry an input of the node set (a table entry nobody
publishes: camera, camera info, odometry, /tf, /tf_static, trigger) go out under the table's
names, with the table's QoS, at the recorded pace. The walking of the bag is
:mod:`stockpile_ros.playback`; this module only creates and feeds the publishers.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

import rclpy
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.utilities import remove_ros_args, try_shutdown

from ..bagio.reader import BagReader
from ..errors import StockpileError
from ..playback import INPUTS, PlayStats, input_topics, parse_mapping, play, to_message, wait_until
from ..ros import topics
from .common import qos_profile
from .interfaces import get_message

__all__ = ['BagPlayer', 'main']


class BagPlayer(Node):
    """Node ``stockpile_player``: one publisher per bag topic that feeds an input of the node set.

    Args:
        bag: The open bag.
        mapping: Table topic name by bag topic, for bags recorded under other names
            (see :func:`stockpile_ros.playback.input_topics`).
        **kwargs: Passed to :class:`rclpy.node.Node`.

    Raises:
        ValueError: The bag has no input topic of the node set, or ``mapping`` is wrong.

    """

    def __init__(
        self, bag: BagReader, mapping: dict[str, str] | None = None, **kwargs: Any
    ) -> None:
        super().__init__('stockpile_player', **kwargs)
        self.bag = bag
        bag_topics = {c.topic: c.msgtype for c in bag.reader.connections}
        self.entries = input_topics(bag_topics, mapping)
        if not self.entries:
            inputs = ', '.join(topics.absolute(t.name) for t in INPUTS)
            raise ValueError(f'{bag.path} holds no input of the node set ({inputs})')
        self.classes = {bag_topic: get_message(e.msgtype) for bag_topic, e in self.entries.items()}
        self.pubs = {
            bag_topic: self.create_publisher(self.classes[bag_topic], e.name, qos_profile(e.qos))
            for bag_topic, e in self.entries.items()
        }
        Node.get_logger(self).info(
            'publishing ' + ', '.join(f'{b} as {self.pubs[b].topic_name}' for b in self.entries)
        )

    def unheard(self) -> list[str]:
        """Return the published topics that no subscriber listens to yet."""
        return [p.topic_name for p in self.pubs.values() if p.get_subscription_count() == 0]

    def publish(self, bag_topic: str, msgtype: str, msg: Any) -> None:
        """Publish one bag message (a rosbags message) on its topic."""
        self.pubs[bag_topic].publish(to_message(self.classes[bag_topic], msg, get_message))

    def play(self, rate: float = 1.0) -> PlayStats:
        """Publish the bag at ``rate`` times its recorded pace (``<= 0``: as fast as possible)."""
        return play(self.bag, list(self.entries), self.publish, rate)

    def run(self, rate: float, wait_subscribers: float, linger: float, settle: float) -> PlayStats:
        """Wait for subscribers, play the bag, then wait for delivery; see :func:`main`."""
        log = Node.get_logger(self)
        # DDS discovery takes a moment: without the wait the first messages reach nobody.
        if not wait_until(lambda: not self.unheard(), wait_subscribers):
            log.warning('no subscriber yet on ' + ', '.join(self.unheard()))
        # Matching is not symmetric: this side sees the subscriber before the subscriber has
        # matched this side, and a best-effort sample sent in between is lost (the first frame
        # was, now and then: every keyframe after it then shifted).
        time.sleep(settle)
        stats = self.play(rate)
        if not self.flush(linger):
            log.warning(f'not every reliable message was acknowledged within {linger} s')
        # Best effort has no acknowledgement: give the last samples a moment on the wire.
        time.sleep(min(linger, 0.2))
        skipped = stats.read.total_skipped
        log.info(
            f'published {stats.total} messages in {stats.seconds:.2f} s'
            + (f' ({skipped} undecodable skipped)' if skipped else '')
        )
        return stats

    def flush(self, timeout: float) -> bool:
        """Wait up to ``timeout`` seconds until every reliable subscriber acknowledged all."""
        deadline = Duration(nanoseconds=int(timeout * 1e9))
        # Best-effort publishers return at once; reliable ones once each sample is acknowledged.
        return all([p.wait_for_all_acked(deadline) for p in self.pubs.values()])


def main(args: list[str] | None = None) -> int:
    """Play a bag into the node set.

    Args:
        args: Command-line arguments without the program name (``sys.argv[1:]`` when None);
            ROS arguments (``--ros-args -r ...``) go to rclpy.

    Returns:
        The exit status: 0 played, 2 the bag or the options are unusable, 130 interrupted.

    """
    parser = argparse.ArgumentParser(
        prog='stockpile-play',
        description='Publish the inputs of the stockpile node set recorded in a bag.',
    )
    parser.add_argument('bag', help='bag folder, .mcap or .db3 file')
    parser.add_argument(
        '--rate', type=float, default=1.0, help='speed-up over the recording; 0: at once'
    )
    parser.add_argument(
        '--wait-subscribers',
        type=float,
        default=5.0,
        metavar='SECONDS',
        help='wait up to this long for a subscriber on every topic before playing',
    )
    parser.add_argument(
        '--settle',
        type=float,
        default=1.0,
        metavar='SECONDS',
        help='once every topic has a subscriber, wait this long for it to match the player too',
    )
    parser.add_argument(
        '--map',
        type=parse_mapping,
        action='append',
        default=[],
        metavar='BAG_TOPIC=TABLE_TOPIC',
        help='publish a bag topic as this input of the node set (repeatable)',
    )
    parser.add_argument(
        '--linger',
        type=float,
        default=2.0,
        metavar='SECONDS',
        help='after the last message, wait up to this long for reliable delivery',
    )
    argv = ['stockpile_player', *(sys.argv[1:] if args is None else args)]
    # rclpy takes the ROS arguments (remapping, namespace), argparse the rest.
    options = parser.parse_args(remove_ros_args(argv)[1:])
    rclpy.init(args=argv)
    try:
        with BagReader(options.bag) as bag:
            node = BagPlayer(bag, dict(options.map))
            try:
                node.run(options.rate, options.wait_subscribers, options.linger, options.settle)
            finally:
                Node.destroy_node(node)
    except (StockpileError, ValueError) as exc:
        print(f'stockpile-play: {exc}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    finally:
        try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
