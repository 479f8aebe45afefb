"""Keyframe node: camera (raw or compressed), camera info, odometry and tf in; keyframes out."""

from __future__ import annotations

import time
from typing import Any

from rclpy.node import Node

from .. import topics
from ..components import WAIT_NS, KeyframeComponent
from .common import (
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
    """Select keyframes and send each, with its image, camera and pose, to the reconstruction."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('stockpile_keyframes', **kwargs)
        declare_settings(self, 'keyframes')
        settings = current_settings(self, 'keyframes')
        self.component = KeyframeComponent(settings, RclpyFactory())
        self.pubs = Publishers(self, 'keyframes')
        compressed = bool(settings.values['compressed'])
        image = topics.IMAGE + (topics.COMPRESSED_SUFFIX if compressed else '')
        # One (mutually exclusive) callback group: the component sees one message at a time.
        subscribe(self, image, self.on_image)
        subscribe(self, topics.CAMERA_INFO, self.on_info)
        subscribe(self, topics.ODOMETRY, self.on_odometry)
        subscribe(self, topics.TF_STATIC, self.on_tf_static)
        subscribe(self, topics.TF, self.on_tf)
        self.last_image = time.monotonic()
        # Parameters were checked before they were set (declare_settings): apply them.
        self.add_post_set_parameters_callback(
            lambda _: self.component.reconfigure(current_settings(self, 'keyframes'))
        )
        # Keyframes still waiting for odometry when the camera goes quiet go out with what is
        # known (a replay does it at the end of the bag).
        self.create_timer(0.5, self.on_quiet)

    def on_image(self, msg: Any) -> None:
        """Offer the frame to the selector."""
        self.last_image = time.monotonic()
        self.pubs.publish(self.component.on_image(msg, now_ns(self)))

    def on_quiet(self) -> None:
        """Send the waiting keyframes once no image has come for the component's wait."""
        quiet = time.monotonic() - self.last_image > WAIT_NS / 1e9
        if quiet and self.component.pending:
            self.pubs.publish(self.component.flush(now_ns(self)))

    def on_info(self, msg: Any) -> None:
        """Keep the latest usable camera model."""
        self.pubs.publish(self.component.on_camera_info(msg, now_ns(self)))

    def on_odometry(self, msg: Any) -> None:
        """Buffer the pose; send the keyframes it completes."""
        self.pubs.publish(self.component.on_odometry(msg, now_ns(self)))

    def on_tf_static(self, msg: Any) -> None:
        """Keep the camera mount."""
        self.pubs.publish(self.component.on_tf(msg, True, now_ns(self)))

    def on_tf(self, msg: Any) -> None:
        """Keep the moving transforms (a camera on a moving mast)."""
        self.pubs.publish(self.component.on_tf(msg, False, now_ns(self)))


def main(args: list[str] | None = None) -> None:
    """Run the keyframe node."""
    spin(KeyframeNode, args=args)


if __name__ == '__main__':
    main()
