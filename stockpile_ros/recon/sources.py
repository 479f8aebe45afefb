"""Frames and odometry from what a person hands over: a ROS 2 bag, a folder of photos, a video file.

Bags carry CameraInfo and odometry; odometry is given for ``base_link`` and turned into camera
positions with the transforms from ``/tf_static`` and ``/tf`` (a camera on a moving mast included).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation, Slerp

from ..camera import Frame
from ..errors import StockpileError

__all__ = ['IMAGE_SUFFIXES', 'VIDEO_SUFFIXES', 'OdometryTrack', 'iter_frames', 'source_kind']

IMAGE_SUFFIXES = ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.tiff')
VIDEO_SUFFIXES = ('.mp4', '.mov', '.avi', '.mkv', '.webm', '.m4v')


def source_kind(source: Path) -> str:
    """``"bag"``, ``"photos"`` or ``"video"``.

    Raises:
        StockpileError: The path is none of them.

    """
    if source.is_dir():
        if (
            (source / 'metadata.yaml').exists()
            or any(source.glob('*.mcap'))
            or any(source.glob('*.db3'))
        ):
            return 'bag'
        if any(p.suffix.lower() in IMAGE_SUFFIXES for p in source.iterdir()):
            return 'photos'
    elif source.suffix.lower() in ('.mcap', '.db3'):
        return 'bag'
    elif source.suffix.lower() in VIDEO_SUFFIXES and source.exists():
        return 'video'
    raise StockpileError(
        f'{source}: not a ROS 2 bag, a folder of photos or a video file '
        f'({", ".join(VIDEO_SUFFIXES)})'
    )


def _photos(folder: Path) -> Iterator[Frame]:
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    for index, path in enumerate(files):
        bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if bgr is None:
            continue
        # Photos carry no stamps worth trusting; their order is their time.
        yield Frame(
            index * 1_000_000_000,
            cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB),
            path.name,
            None,
            str(folder),
            index,
        )


def _video(path: Path) -> Iterator[Frame]:
    capture = cv2.VideoCapture(str(path))
    if not capture.isOpened():
        raise StockpileError(f'{path}: OpenCV cannot open this video')
    index = 0
    try:
        while True:
            ok, bgr = capture.read()
            if not ok:
                break
            stamp = round(capture.get(cv2.CAP_PROP_POS_MSEC) * 1e6)
            yield Frame(
                stamp, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), path.name, None, str(path), index
            )
            index += 1
    finally:
        capture.release()


def iter_frames(source: Path, topic: str | None = None) -> Iterator[Frame]:
    """Frames of a bag (one image topic), a folder of photos (sorted by name) or a video."""
    kind = source_kind(source)
    if kind == 'bag':
        from ..bagio.reader import read_frames

        yield from read_frames(source, topic)
    elif kind == 'photos':
        yield from _photos(source)
    else:
        yield from _video(source)


def _matrix(position: Any, quat_xyzw: Any) -> npt.NDArray[np.float64]:
    out = np.eye(4)
    out[:3, :3] = Rotation.from_quat(np.asarray(quat_xyzw, dtype=np.float64)).as_matrix()
    out[:3, 3] = np.asarray(position, dtype=np.float64)
    return out


@dataclass
class _PoseSeries:
    """Poses of one frame over time, interpolated linearly (positions) and by slerp."""

    stamps: npt.NDArray[np.int64]
    positions: npt.NDArray[np.float64]
    rotations: Rotation

    @classmethod
    def build(cls, samples: list[tuple[int, Any, Any]]) -> _PoseSeries:
        samples = sorted(samples, key=lambda s: s[0])
        stamps = np.array([s[0] for s in samples], dtype=np.int64)
        keep = np.concatenate([[True], np.diff(stamps) > 0])
        kept = [s for s, k in zip(samples, keep, strict=True) if k]
        return cls(
            stamps[keep],
            np.array([s[1] for s in kept], dtype=np.float64).reshape(-1, 3),
            Rotation.from_quat(np.array([s[2] for s in kept], dtype=np.float64).reshape(-1, 4)),
        )

    def at(self, stamp_ns: int, max_gap_ns: int) -> tuple[npt.NDArray[np.float64], Rotation] | None:
        k = int(np.searchsorted(self.stamps, stamp_ns))
        if k < len(self.stamps) and self.stamps[k] == stamp_ns:
            return self.positions[k], self.rotations[k]
        if k == 0 or k == len(self.stamps) or self.stamps[k] - self.stamps[k - 1] > max_gap_ns:
            return None
        w = (stamp_ns - self.stamps[k - 1]) / (self.stamps[k] - self.stamps[k - 1])
        position = (1 - w) * self.positions[k - 1] + w * self.positions[k]
        times = self.stamps[k - 1 : k + 1].astype(np.float64)
        return position, Slerp(times, self.rotations[k - 1 : k + 1])(float(stamp_ns))


class _TransformTree:
    """The ``/tf_static`` and ``/tf`` edges of a bag below the odometry's moving frame."""

    def __init__(self, bag: Path, skip_child: str) -> None:
        from ..bagio.reader import read_messages

        self.static: dict[str, tuple[str, npt.NDArray[np.float64]]] = {}
        moving: dict[str, tuple[str, list[tuple[int, Any, Any]]]] = {}
        for topic in ('/tf_static', '/tf'):
            try:
                for _, _, log_ns, msg in read_messages(bag, [topic]):
                    for tf in msg.transforms:
                        child = tf.child_frame_id.lstrip('/')
                        parent = tf.header.frame_id.lstrip('/')
                        t, q = tf.transform.translation, tf.transform.rotation
                        pos, quat = [t.x, t.y, t.z], [q.x, q.y, q.z, q.w]
                        if topic == '/tf_static':
                            self.static[child] = (parent, _matrix(pos, quat))
                        elif child != skip_child:
                            stamp = tf.header.stamp.sec * 1_000_000_000 + tf.header.stamp.nanosec
                            moving.setdefault(child, (parent, []))[1].append(
                                (stamp or log_ns, pos, quat)
                            )
            except StockpileError:
                continue
        self.moving = {c: (p, _PoseSeries.build(s)) for c, (p, s) in moving.items()}

    def chain(self, parent: str, child: str, stamp_ns: int) -> npt.NDArray[np.float64] | None:
        """4x4 transform ``child`` -> ``parent`` at ``stamp_ns``; None when not connected."""
        out = np.eye(4)
        frame = child.lstrip('/')
        for _ in range(len(self.static) + len(self.moving) + 1):
            if frame == parent:
                return out
            if frame in self.static:
                frame, step = self.static[frame]
            elif frame in self.moving:
                frame, series = self.moving[frame]
                pose = series.at(stamp_ns, 200_000_000)
                if pose is None:
                    return None
                step = _matrix(pose[0], pose[1].as_quat())
            else:
                return None
            out = step @ out
        return None


@dataclass
class OdometryTrack:
    """Odometry of a bag, interpolated at keyframe stamps.

    Attributes:
        poses: The moving frame's poses in the odometry frame.
        frame_id: Odometry frame.
        child_frame_id: Moving frame.
        camera_frame: The camera's optical frame.
        tree: Transforms from the camera up to the moving frame (static or over time).

    """

    poses: _PoseSeries
    frame_id: str
    child_frame_id: str
    camera_frame: str
    tree: _TransformTree

    @classmethod
    def from_bag(cls, bag: Path, camera_frame: str) -> OdometryTrack | None:
        """Read odometry (None when the bag has none or fewer than two poses)."""
        from ..bagio.reader import read_odometry

        poses = read_odometry(bag)
        if len(poses) < 2:
            return None
        base = poses[0].child_frame_id
        return cls(
            poses=_PoseSeries.build([(p.stamp_ns, p.position, p.orientation_xyzw) for p in poses]),
            frame_id=poses[0].frame_id,
            child_frame_id=base,
            camera_frame=camera_frame,
            tree=_TransformTree(bag, skip_child=base),
        )

    def at(self, stamp_ns: int, max_gap_ns: int = 200_000_000) -> dict[str, Any] | None:
        """Return the pose at ``stamp_ns`` as a ``keyframes.jsonl`` entry (None outside)."""
        pose = self.poses.at(stamp_ns, max_gap_ns)
        if pose is None:
            return None
        position, rotation = pose
        entry: dict[str, Any] = {
            'position': [float(v) for v in position],
            'orientation_xyzw': [float(v) for v in rotation.as_quat()],
            'frame_id': self.frame_id,
            'child_frame_id': self.child_frame_id,
        }
        base_to_camera = self.tree.chain(self.child_frame_id, self.camera_frame, stamp_ns)
        if base_to_camera is not None:
            cam = _matrix(position, rotation.as_quat()) @ base_to_camera
            entry['camera_position'] = [float(v) for v in cam[:3, 3]]
        return entry
