"""What the nodes and the replay read out of received messages: stamps and camera models.

Written once for rclpy and rosbags messages (the same field names).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..camera import CameraModel
from ..errors import StockpileError

__all__ = ['CameraInfoError', 'camera_model_from_msg', 'message_stamp_ns']


def message_stamp_ns(msg: Any, fallback_ns: int) -> int:
    """Return a message's header stamp in ns, or ``fallback_ns`` when it has none or it is zero."""
    header = getattr(msg, 'header', None)
    if header is None:
        return fallback_ns
    stamp = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    return stamp if stamp > 0 else fallback_ns


class CameraInfoError(StockpileError, ValueError):
    """A CameraInfo message that does not describe a usable camera."""


def camera_model_from_msg(msg: Any) -> CameraModel:
    """Build a :class:`CameraModel` from a ``sensor_msgs/CameraInfo``.

    Raises:
        CameraInfoError: Zero size, or an uncalibrated or malformed K.

    """
    k = np.asarray(msg.k, dtype=np.float64)
    if k.size != 9:
        raise CameraInfoError(f'CameraInfo K has {k.size} values, not 9')
    k = k.reshape(3, 3)
    width, height = int(msg.width), int(msg.height)
    if width <= 0 or height <= 0:
        raise CameraInfoError(f'CameraInfo size is {width}x{height}')
    if not np.all(np.isfinite(k)) or k[0, 0] <= 0 or k[1, 1] <= 0:
        raise CameraInfoError('CameraInfo is uncalibrated (K has no positive focal lengths)')
    return CameraModel(
        width=width,
        height=height,
        k=k,
        d=np.asarray(msg.d, dtype=np.float64).reshape(-1),
        distortion_model=str(msg.distortion_model),
        frame_id=str(msg.header.frame_id),
    )
