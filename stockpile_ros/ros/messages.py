"""Builders of ROS messages, written once for rosbags and rclpy.

rosbags message classes and rclpy message classes share field names; they differ in how they want
primitive arrays. A :class:`MessageFactory` hides that difference, so every builder here serves the
bag writer and the live nodes alike. The rosbags factory lives here; the rclpy one in
:mod:`stockpile_ros.nodes`.
"""

from __future__ import annotations

from typing import Any, Protocol

import cv2
import numpy as np
import numpy.typing as npt
from rosbags.typesys.store import Typestore

from ..camera import CameraModel

__all__ = [
    'MessageFactory',
    'RosbagsFactory',
    'camera_info',
    'compressed_image',
    'header',
    'image',
    'odometry',
    'pose',
    'stamp',
    'tf_message',
    'transform_stamped',
]


class MessageFactory(Protocol):
    """What a builder needs from a message library."""

    def cls(self, msgtype: str) -> Any:
        """Return the message class of ``pkg/msg/Name``."""

    def u8(self, data: npt.NDArray[np.uint8] | bytes) -> Any:
        """Convert bytes to the library's ``uint8[]`` value."""

    def f64(self, data: npt.ArrayLike) -> Any:
        """Convert numbers to the library's ``float64[]`` value."""

    def u32(self, data: npt.ArrayLike) -> Any:
        """Convert non-negative integers to the library's ``uint32[]`` value."""


class RosbagsFactory:
    """Message factory over a rosbags typestore (numpy arrays for primitive arrays)."""

    def __init__(self, store: Typestore):
        self.store = store

    def cls(self, msgtype: str) -> Any:
        """Return the rosbags dataclass of ``msgtype``."""
        return self.store.types[msgtype]

    def u8(self, data: npt.NDArray[np.uint8] | bytes) -> Any:
        """Return a uint8 numpy array."""
        if isinstance(data, bytes):
            return np.frombuffer(data, dtype=np.uint8)
        return np.ascontiguousarray(data, dtype=np.uint8).reshape(-1)

    def f64(self, data: npt.ArrayLike) -> Any:
        """Return a float64 numpy array."""
        return np.asarray(data, dtype=np.float64).reshape(-1)

    def u32(self, data: npt.ArrayLike) -> Any:
        """Return a uint32 numpy array."""
        return np.asarray(data, dtype=np.uint32).reshape(-1)


def stamp(f: MessageFactory, stamp_ns: int) -> Any:
    """Build ``builtin_interfaces/Time`` from nanoseconds."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return f.cls('builtin_interfaces/msg/Time')(sec=sec, nanosec=nanosec)


def header(f: MessageFactory, stamp_ns: int, frame_id: str) -> Any:
    """Build ``std_msgs/Header``."""
    return f.cls('std_msgs/msg/Header')(stamp=stamp(f, stamp_ns), frame_id=frame_id)


def image(f: MessageFactory, img: npt.NDArray[Any], stamp_ns: int, frame_id: str) -> Any:
    """Build ``sensor_msgs/Image`` from an HxWx3 uint8 RGB (``rgb8``) or HxW uint8 (``mono8``)."""
    if img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8:
        encoding = 'rgb8'
    elif img.ndim == 2 and img.dtype == np.uint8:
        encoding = 'mono8'
    else:
        raise ValueError(f'unsupported image array {img.dtype} {img.shape}')
    height, width = img.shape[:2]
    return f.cls('sensor_msgs/msg/Image')(
        header=header(f, stamp_ns, frame_id),
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=0,
        step=img.strides[0] if img.flags.c_contiguous else width * (3 if img.ndim == 3 else 1),
        data=f.u8(np.ascontiguousarray(img)),
    )


def compressed_image(
    f: MessageFactory,
    img: npt.NDArray[np.uint8],
    stamp_ns: int,
    frame_id: str,
    fmt: str = 'jpeg',
    quality: int = 90,
) -> Any:
    """Build ``sensor_msgs/CompressedImage`` (``jpeg`` or ``png``) from RGB or mono uint8."""
    bgr = cv2.cvtColor(img, cv2.COLOR_RGB2BGR) if img.ndim == 3 else img
    if fmt == 'jpeg':
        ok, buf = cv2.imencode('.jpg', bgr, [cv2.IMWRITE_JPEG_QUALITY, quality])
    elif fmt == 'png':
        ok, buf = cv2.imencode('.png', bgr)
    else:
        raise ValueError(f'unsupported compressed format {fmt!r}; use jpeg or png')
    if not ok:
        raise ValueError(f'OpenCV could not encode the image as {fmt}')
    return f.cls('sensor_msgs/msg/CompressedImage')(
        header=header(f, stamp_ns, frame_id), format=fmt, data=f.u8(buf)
    )


def camera_info(f: MessageFactory, cam: CameraModel, stamp_ns: int) -> Any:
    """Build ``sensor_msgs/CameraInfo`` (R identity, P = [K | 0])."""
    p = np.zeros((3, 4))
    p[:, :3] = cam.k
    roi = f.cls('sensor_msgs/msg/RegionOfInterest')(
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
    )
    return f.cls('sensor_msgs/msg/CameraInfo')(
        header=header(f, stamp_ns, cam.frame_id),
        height=cam.height,
        width=cam.width,
        distortion_model=cam.distortion_model,
        d=f.f64(cam.d),
        k=f.f64(cam.k),
        r=f.f64(np.eye(3)),
        p=f.f64(p),
        binning_x=0,
        binning_y=0,
        roi=roi,
    )


def pose(f: MessageFactory, position: npt.ArrayLike, quat_xyzw: npt.ArrayLike) -> Any:
    """Build ``geometry_msgs/Pose``."""
    x, y, z = (float(v) for v in np.asarray(position, dtype=float))
    qx, qy, qz, qw = (float(v) for v in np.asarray(quat_xyzw, dtype=float))
    return f.cls('geometry_msgs/msg/Pose')(
        position=f.cls('geometry_msgs/msg/Point')(x=x, y=y, z=z),
        orientation=f.cls('geometry_msgs/msg/Quaternion')(x=qx, y=qy, z=qz, w=qw),
    )


def odometry(
    f: MessageFactory,
    stamp_ns: int,
    position: npt.ArrayLike,
    quat_xyzw: npt.ArrayLike,
    frame_id: str = 'odom',
    child_frame_id: str = 'base_link',
    position_sigma: float = 0.0,
) -> Any:
    """Build ``nav_msgs/Odometry`` with an isotropic position covariance (twist left zero)."""
    cov = np.zeros((6, 6))
    cov[0, 0] = cov[1, 1] = cov[2, 2] = position_sigma**2
    zero3 = f.cls('geometry_msgs/msg/Vector3')(x=0.0, y=0.0, z=0.0)
    twist = f.cls('geometry_msgs/msg/Twist')(linear=zero3, angular=zero3)
    return f.cls('nav_msgs/msg/Odometry')(
        header=header(f, stamp_ns, frame_id),
        child_frame_id=child_frame_id,
        pose=f.cls('geometry_msgs/msg/PoseWithCovariance')(
            pose=pose(f, position, quat_xyzw), covariance=f.f64(cov)
        ),
        twist=f.cls('geometry_msgs/msg/TwistWithCovariance')(
            twist=twist, covariance=f.f64(cov * 0)
        ),
    )


def transform_stamped(
    f: MessageFactory,
    stamp_ns: int,
    frame_id: str,
    child_frame_id: str,
    translation: npt.ArrayLike,
    quat_xyzw: npt.ArrayLike,
) -> Any:
    """Build ``geometry_msgs/TransformStamped`` (the pose of ``child_frame_id`` in ``frame_id``)."""
    x, y, z = (float(v) for v in np.asarray(translation, dtype=float))
    qx, qy, qz, qw = (float(v) for v in np.asarray(quat_xyzw, dtype=float))
    return f.cls('geometry_msgs/msg/TransformStamped')(
        header=header(f, stamp_ns, frame_id),
        child_frame_id=child_frame_id,
        transform=f.cls('geometry_msgs/msg/Transform')(
            translation=f.cls('geometry_msgs/msg/Vector3')(x=x, y=y, z=z),
            rotation=f.cls('geometry_msgs/msg/Quaternion')(x=qx, y=qy, z=qz, w=qw),
        ),
    )


def tf_message(f: MessageFactory, transforms: list[Any]) -> Any:
    """Build ``tf2_msgs/TFMessage``."""
    return f.cls('tf2_msgs/msg/TFMessage')(transforms=transforms)
