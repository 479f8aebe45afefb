"""Keyframe node: camera (raw or compressed), camera info, odometry and tf in; keyframes stored."""

from __future__ import annotations

from typing import Any

from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from tf2_msgs.msg import TFMessage

from .. import topics
from ..bagio.images import ImageError, decode_image
from ..bagio.reader import CameraInfoError, camera_model_from_msg, message_stamp_ns
from ..camera import CameraModel, Frame
from ..publish import diagnostics, keyframe_status
from ..recon.collector import KeyframeCollector, OdometryBuffer
from ..recon.pipeline import WorkFolder
from .common import Publishers, RclpyFactory, current_settings, declare_settings, now_ns, spin

__all__ = ['KeyframeNode', 'main']


class KeyframeNode(Node):
    """Select and store keyframes; publish how many are held and how well the pile is covered."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('stockpile_keyframes', **kwargs)
        declare_settings(self, 'keyframes')
        settings = current_settings(self, 'keyframes')
        self.f = RclpyFactory()
        self.collector = KeyframeCollector(
            WorkFolder(settings.work_dir).keyframes,
            settings.recon.selector,
            float(settings.values['coverage_full_parallax']),
        )
        self.odometry = OdometryBuffer()
        self.camera: CameraModel | None = None
        self.noted: set[str] = set()
        self.pubs = Publishers(self, {
            topics.KEYFRAME_STATUS: 'stockpile_msgs/msg/PipelineStatus',
            topics.DIAGNOSTICS: 'diagnostic_msgs/msg/DiagnosticArray',
        })  # fmt: skip
        if settings.values['compressed']:
            image_type: Any = CompressedImage
            image_topic = topics.IMAGE + topics.COMPRESSED_SUFFIX
        else:
            image_type, image_topic = Image, topics.IMAGE
        self.create_subscription(image_type, image_topic, self.on_image, qos_profile_sensor_data)
        self.create_subscription(CameraInfo, topics.CAMERA_INFO, self.on_info,
                                 qos_profile_sensor_data)  # fmt: skip
        self.create_subscription(Odometry, topics.ODOMETRY, self.on_odometry,
                                 qos_profile_sensor_data)  # fmt: skip
        # The QoS tf2's own listener uses: static transforms are latched.
        tf_static = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                               durability=DurabilityPolicy.TRANSIENT_LOCAL)  # fmt: skip
        self.create_subscription(TFMessage, topics.TF_STATIC, self.on_tf_static, tf_static)
        self.create_subscription(TFMessage, topics.TF, self.on_tf, QoSProfile(depth=100))

    def note(self, key: str, level: str, text: str) -> None:
        """Publish a diagnostic and log it, once per ``key``."""
        if key in self.noted:
            return
        self.noted.add(key)
        self.get_logger().warning(text)
        self.pubs.publish([diagnostics(self.f, now_ns(self), key, level, text)])

    def on_info(self, msg: CameraInfo) -> None:
        """Keep the latest usable camera model."""
        try:
            self.camera = camera_model_from_msg(msg)
        except CameraInfoError as exc:
            self.note('camera_info', 'WARN', f'{exc}; frames are self-calibrated')

    def on_odometry(self, msg: Odometry) -> None:
        """Buffer the pose for the frames to come."""
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        stamp = message_stamp_ns(msg, now_ns(self))
        frames = (msg.header.frame_id, msg.child_frame_id)
        self.odometry.push(stamp, (p.x, p.y, p.z), (q.x, q.y, q.z, q.w), *frames)

    def on_tf_static(self, msg: TFMessage) -> None:
        """Keep the cart's fixed transforms (the camera mount)."""
        self.odometry.tree.add(msg, static=True, log_ns=now_ns(self))

    def on_tf(self, msg: TFMessage) -> None:
        """Keep the cart's moving transforms (a camera on a moving mast)."""
        self.odometry.tree.add(msg, static=False, log_ns=now_ns(self))

    def on_image(self, msg: Any) -> None:
        """Offer the frame to the collector and publish the status."""
        try:
            image = decode_image(msg)
        except ImageError as exc:
            self.note(f'camera: {exc}', 'ERROR', f'frame skipped: {exc}')
            return
        stamp = message_stamp_ns(msg, now_ns(self))
        camera = self.camera
        if camera is None:
            self.note(
                'camera_info', 'WARN', 'no CameraInfo yet: intrinsics will be self-calibrated'
            )
        elif not camera.fits(image):
            self.note('camera_size', 'WARN', 'CameraInfo size differs from the images: ignored')
            camera = None
        frame = Frame(stamp, image, msg.header.frame_id, camera, topics.IMAGE,
                      self.collector.state.frames)  # fmt: skip
        self.collector.push(frame, self.odometry.at(stamp, msg.header.frame_id))
        self.pubs.publish([keyframe_status(self.f, stamp, self.collector.state)])


def main(args: list[str] | None = None) -> None:
    """Run the keyframe node."""
    spin(KeyframeNode, args=args)


if __name__ == '__main__':
    main()
