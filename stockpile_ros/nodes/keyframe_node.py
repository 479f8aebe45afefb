"""Keyframe node: camera (raw or compressed), camera info, odometry and tf in; keyframes out."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from rclpy.node import Node

from ..components import WAIT_NS, KeyframeComponent
from ..ros import topics
from ..ros.publications import Publication
from .common import (
    Inbox,
    Publishers,
    RclpyFactory,
    current_settings,
    declare_settings,
    now_ns,
    spin,
    subscribe,
)

__all__ = ['KeyframeNode', 'main']


class KeyframeNode(Node):
    """Select keyframes and send each, with its image, camera and pose, to the reconstruction.

    The callbacks only queue (see :class:`Inbox`); one thread feeds the component everything in
    arrival order, so it sees one message at a time.
    """

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('stockpile_keyframes', **kwargs)
        declare_settings(self, 'keyframes')
        settings = current_settings(self, 'keyframes')
        self.component = KeyframeComponent(settings, RclpyFactory())
        self.pubs = Publishers(self, 'keyframes')
        self.inbox = Inbox(topics.QOS_DEPTH['sensor'], Node.get_logger(self))
        self._dropped = 0
        c = self.component
        compressed = bool(settings.values['compressed'])
        image = topics.IMAGE + (topics.COMPRESSED_SUFFIX if compressed else '')
        queue_image = self._queue(self._image, droppable=True)

        def on_image(msg: Any) -> None:
            # Stamped on arrival, not when the inbox reaches it: a quiet check between the two
            # sent the first keyframe out before its CameraInfo, queued just behind it, was read.
            self.last_image = time.monotonic()
            queue_image(msg)

        subscribe(self, image, on_image)
        subscribe(self, topics.CAMERA_INFO, self._queue(c.on_camera_info))
        subscribe(self, topics.ODOMETRY, self._queue(c.on_odometry))
        subscribe(self, topics.TF_STATIC, self._queue(lambda m, t: c.on_tf(m, True, t)))
        subscribe(self, topics.TF, self._queue(lambda m, t: c.on_tf(m, False, t)))
        self.last_image = time.monotonic()
        # Parameters were checked before they were set (declare_settings): apply them, in turn
        # with the frames.
        self.add_post_set_parameters_callback(
            lambda _: self.inbox.put(lambda: c.reconfigure(current_settings(self, 'keyframes')))
        )
        # Keyframes still waiting for odometry when the camera goes quiet go out with what is
        # known (a replay does it at the end of the bag).
        self.create_timer(0.5, self.on_quiet)

    def _queue(
        self, handler: Callable[[Any, int], list[Publication]], droppable: bool = False
    ) -> Callable[[Any], None]:
        """Return a callback that queues the message, stamped on arrival, for ``handler``."""

        def callback(msg: Any) -> None:
            stamp = now_ns(self)
            self.inbox.put(lambda: self.pubs.publish(handler(msg, stamp)), droppable)

        return callback

    def _image(self, msg: Any, log_ns: int) -> list[Publication]:
        out = self.component.on_dropped(self.inbox.dropped - self._dropped, log_ns)
        self._dropped = self.inbox.dropped
        return out + self.component.on_image(msg, log_ns)

    def on_quiet(self) -> None:
        """Send the waiting keyframes once no image has arrived for the component's wait."""
        if time.monotonic() - self.last_image > WAIT_NS / 1e9:
            self.inbox.put(self._flush)

    def _flush(self) -> None:
        if self.component.pending:
            self.pubs.publish(self.component.flush(now_ns(self)))

    def close(self) -> None:
        """Handle what has arrived, then stop the inbox's thread."""
        self.inbox.close()

    def destroy_node(self) -> None:
        """Stop the inbox's thread with the node."""
        self.close()
        Node.destroy_node(self)


def main(args: list[str] | None = None) -> None:
    """Run the keyframe node."""
    spin(KeyframeNode, args=args)


if __name__ == '__main__':
    main()
