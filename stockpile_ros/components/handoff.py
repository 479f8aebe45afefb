"""What the components hand each other as messages: keyframes, and the surface to segment.

Keyframes travel as ``stockpile_msgs/Keyframe`` and the reconstructed surface as
``stockpile_msgs/SurfaceMesh``, so the keyframe node on the cart and the heavy stages on a base
station share nothing but DDS. Each receiving side writes what it gets into its own work folder,
in the formats of ``docs/formats.md``; the replay hands over the very same messages in-process.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from ..artefacts import KeyframeRecord, OdometryEntry
from ..camera import CameraModel, Frame
from ..meshio import LabelledMesh, read_labelled_mesh, write_labelled_mesh
from ..ros.convert import camera_model_from_msg, message_stamp_ns
from ..ros.images import decode_image
from ..ros.messages import MessageFactory, camera_info, header, pose

__all__ = [
    'ReceivedKeyframe',
    'keyframe_image',
    'keyframe_message',
    'read_keyframe',
    'read_surface',
    'surface_message',
]

_COMPRESSED_FORMATS = ('jpeg', 'png')


def keyframe_image(msg: Any, image: npt.NDArray[Any]) -> tuple[str, bytes]:
    """Return the bytes a keyframe carries: the camera's own JPEG/PNG, or PNG of a raw frame.

    Args:
        msg: The ``Image`` or ``CompressedImage`` the frame was decoded from.
        image: The decoded frame.

    Returns:
        The ``CompressedImage.format`` and data.

    """
    fmt = str(getattr(msg, 'format', '')).lower()
    kind = next((k for k in _COMPRESSED_FORMATS if k in fmt), None)
    if kind is not None and ';' not in fmt:
        # Passed on as recorded: no second lossy encoding, and a small message over Wi-Fi.
        return kind, bytes(memoryview(msg.data).cast('B'))
    bgr = cv2.cvtColor(image, cv2.COLOR_RGB2BGR) if image.ndim == 3 else image
    ok, buf = cv2.imencode('.png', bgr)
    if not ok:
        raise ValueError('OpenCV could not encode the keyframe as PNG')
    return 'png', buf.tobytes()


def _empty_camera_info(f: MessageFactory, stamp_ns: int, frame_id: str) -> Any:
    roi = f.cls('sensor_msgs/msg/RegionOfInterest')(
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
    )
    return f.cls('sensor_msgs/msg/CameraInfo')(
        header=header(f, stamp_ns, frame_id), height=0, width=0, distortion_model='',
        d=f.f64([]), k=f.f64(np.zeros(9)), r=f.f64(np.zeros(9)), p=f.f64(np.zeros(12)),
        binning_x=0, binning_y=0, roi=roi,
    )  # fmt: skip


def keyframe_message(
    f: MessageFactory,
    record: KeyframeRecord,
    number: int,
    frame_id: str,
    image: tuple[str, bytes],
) -> Any:
    """Build the ``Keyframe`` message of a stored keyframe.

    Args:
        f: Message factory.
        record: The keyframe as stored (stamp, camera, odometry, why it was kept).
        number: Its number in the capture (0 for the first).
        frame_id: The image's frame.
        image: Format and bytes, from :func:`keyframe_image`.

    """
    stamp = record.stamp_ns
    fmt, data = image
    odo = record.odometry
    base = (odo.position, odo.orientation_xyzw) if odo is not None else None
    camera_pose = None
    if odo is not None and odo.camera_position is not None and odo.camera_orientation_xyzw:
        camera_pose = (odo.camera_position, odo.camera_orientation_xyzw)
    cam: CameraModel | None = record.camera
    zero = ([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    return f.cls('stockpile_msgs/msg/Keyframe')(
        header=header(f, stamp, frame_id),
        index=int(number),
        frame_index=int(record.index),
        reason=record.reason,
        sharpness=float(record.sharpness),
        image=f.cls('sensor_msgs/msg/CompressedImage')(
            header=header(f, stamp, frame_id), format=fmt, data=f.u8(data)
        ),
        has_camera_info=cam is not None,
        camera_info=(
            camera_info(f, cam, stamp)
            if cam is not None
            else _empty_camera_info(f, stamp, frame_id)
        ),
        has_odometry=odo is not None,
        odom_frame_id=odo.frame_id if odo is not None else '',
        base_frame_id=odo.child_frame_id if odo is not None else '',
        base_pose=pose(f, *(base or zero)),
        has_camera_pose=camera_pose is not None,
        camera_pose=pose(f, *(camera_pose or zero)),
    )


@dataclass
class ReceivedKeyframe:
    """A keyframe as the reconstruction receives it.

    Attributes:
        index: Keyframe number in the capture.
        frame: The decoded image with its stamp, frame and camera.
        odometry: The ``keyframes.jsonl`` odometry entry, None without odometry.
        reason: Why the selector kept it.
        sharpness: Its sharpness.

    """

    index: int
    frame: Frame
    odometry: OdometryEntry | None
    reason: str
    sharpness: float


def _xyz(p: Any) -> list[float]:
    return [float(p.x), float(p.y), float(p.z)]


def _xyzw(q: Any) -> list[float]:
    return [float(q.x), float(q.y), float(q.z), float(q.w)]


def read_keyframe(msg: Any, max_pixels: int) -> ReceivedKeyframe:
    """Decode a ``Keyframe`` message (rosbags or rclpy); its image at most ``max_pixels``.

    Raises:
        ImageError: The image cannot be decoded.
        CameraInfoError: ``has_camera_info`` is set but the CameraInfo is unusable.

    """
    image = decode_image(msg.image, max_pixels)
    camera = camera_model_from_msg(msg.camera_info) if msg.has_camera_info else None
    odometry = None
    if msg.has_odometry:
        odometry = OdometryEntry(
            position=_xyz(msg.base_pose.position),
            orientation_xyzw=_xyzw(msg.base_pose.orientation),
            frame_id=str(msg.odom_frame_id),
            child_frame_id=str(msg.base_frame_id),
        )
        if msg.has_camera_pose:
            odometry.camera_position = _xyz(msg.camera_pose.position)
            odometry.camera_orientation_xyzw = _xyzw(msg.camera_pose.orientation)
    stamp = message_stamp_ns(msg, 0)
    frame = Frame(stamp, image, str(msg.header.frame_id), camera, '', int(msg.frame_index))
    return ReceivedKeyframe(int(msg.index), frame, odometry, str(msg.reason), float(msg.sharpness))


def surface_message(
    f: MessageFactory,
    mesh_dir: Path,
    stamp_ns: int,
    frame_id: str,
    keyframes: int,
    coverage: float,
) -> Any:
    """Build the ``SurfaceMesh`` message of a finished reconstruction's ``mesh/`` folder."""
    mesh = read_labelled_mesh(mesh_dir / 'mesh.ply')
    colors = b'' if mesh.colors is None else mesh.colors
    return f.cls('stockpile_msgs/msg/SurfaceMesh')(
        header=header(f, stamp_ns, frame_id),
        vertices=f.f64(mesh.vertices),
        faces=f.u32(mesh.faces),
        colors=f.u8(colors),
        info=(mesh_dir / 'mesh.json').read_text(),
        keyframes=int(keyframes),
        coverage=float(coverage),
    )


def read_surface(msg: Any, mesh_dir: Path) -> dict[str, Any]:
    """Write a ``SurfaceMesh`` message into ``mesh_dir`` (``mesh.ply``, ``mesh.json``).

    Returns:
        The parsed ``mesh.json``.

    Raises:
        ValueError: Arrays of the wrong length or face indices out of range.

    """
    vertices = np.asarray(msg.vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(msg.faces, dtype=np.int64).reshape(-1, 3)
    colors_raw = np.asarray(msg.colors, dtype=np.uint8)
    if len(faces) and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise ValueError(f'surface: face index out of range for {len(vertices)} vertices')
    colors = colors_raw.reshape(-1, 3) if colors_raw.size else None
    if colors is not None and len(colors) != len(vertices):
        raise ValueError(f'surface: {len(colors)} colours for {len(vertices)} vertices')
    info: dict[str, Any] = json.loads(str(msg.info))
    mesh_dir.mkdir(parents=True, exist_ok=True)
    labels = np.zeros(len(faces), dtype=np.int32)
    write_labelled_mesh(mesh_dir / 'mesh.ply', LabelledMesh(vertices, faces, labels, colors))
    (mesh_dir / 'mesh.json').write_text(str(msg.info))
    return info
