"""The cart's frames from ``/tf_static`` and ``/tf`` (bag or live), and camera centres from them.

A recorded bag and a live node feed the same :class:`TransformTree` with ``tf2_msgs/TFMessage``
messages (rosbags and rclpy messages share the field names), so a camera on a mast, static or
moving, is placed the same way in replay and on the cart.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation, Slerp

from ..artefacts import OdometryEntry

__all__ = [
    'MAX_GAP_NS',
    'PoseSeries',
    'TransformTree',
    'odometry_entry',
    'pose_matrix',
    'valid_pose',
]

F64 = npt.NDArray[np.float64]

#: Largest stamp gap a moving transform is interpolated across [ns].
MAX_GAP_NS = 200_000_000


def valid_pose(position: Any, quat_xyzw: Any) -> tuple[list[float], list[float]] | None:
    """Return the position and the unit quaternion, or None when they are not a pose.

    A zero (or non-finite) quaternion or a non-finite position comes from a driver that has no
    fix yet; it is not a rotation and must not reach a fit.
    """
    pos = np.asarray(position, dtype=np.float64).reshape(-1)
    quat = np.asarray(quat_xyzw, dtype=np.float64).reshape(-1)
    norm = float(np.linalg.norm(quat)) if np.all(np.isfinite(quat)) else 0.0
    if pos.size != 3 or quat.size != 4 or not np.all(np.isfinite(pos)) or norm < 1e-6:
        return None
    return [float(v) for v in pos], [float(v) for v in quat / norm]


def pose_matrix(position: Any, quat_xyzw: Any) -> F64:
    """4x4 homogeneous transform of a position and an ``x, y, z, w`` quaternion."""
    out = np.eye(4)
    out[:3, :3] = Rotation.from_quat(np.asarray(quat_xyzw, dtype=np.float64)).as_matrix()
    out[:3, 3] = np.asarray(position, dtype=np.float64)
    return out


@dataclass
class PoseSeries:
    """Poses of one frame over time, interpolated linearly (positions) and by slerp."""

    stamps: npt.NDArray[np.int64]
    positions: F64
    rotations: Rotation

    @classmethod
    def build(cls, samples: list[tuple[int, Any, Any]]) -> PoseSeries:
        """Series of ``(stamp_ns, position, quat_xyzw)`` samples in any order (repeats dropped)."""
        samples = sorted(samples, key=lambda s: s[0])
        stamps = np.array([s[0] for s in samples], dtype=np.int64)
        keep = np.concatenate([[True], np.diff(stamps) > 0])
        kept = [s for s, k in zip(samples, keep, strict=True) if k]
        return cls(
            stamps[keep],
            np.array([s[1] for s in kept], dtype=np.float64).reshape(-1, 3),
            Rotation.from_quat(np.array([s[2] for s in kept], dtype=np.float64).reshape(-1, 4)),
        )

    def at(self, stamp_ns: int, max_gap_ns: int) -> tuple[F64, Rotation] | None:
        """Pose at ``stamp_ns``; None outside the series or across a gap over ``max_gap_ns``."""
        k = int(np.searchsorted(self.stamps, stamp_ns))
        if k < len(self.stamps) and self.stamps[k] == stamp_ns:
            return self.positions[k], self.rotations[k]
        if k == 0 or k == len(self.stamps) or self.stamps[k] - self.stamps[k - 1] > max_gap_ns:
            return None
        w = (stamp_ns - self.stamps[k - 1]) / (self.stamps[k] - self.stamps[k - 1])
        position = (1 - w) * self.positions[k - 1] + w * self.positions[k]
        times = self.stamps[k - 1 : k + 1].astype(np.float64)
        return position, Slerp(times, self.rotations[k - 1 : k + 1])(float(stamp_ns))


class TransformTree:
    """Static and moving transforms, each child frame with its one parent.

    Args:
        skip_child: A child frame whose transforms are not kept (the odometry's moving frame,
            which the odometry itself gives).
        history: Samples kept per moving transform (a live node runs for hours).

    """

    def __init__(self, skip_child: str = '', history: int = 2000) -> None:
        self.skip_child = skip_child.lstrip('/')
        self.static: dict[str, tuple[str, F64]] = {}
        self._samples: dict[str, tuple[str, deque[tuple[int, Any, Any]]]] = {}
        self._series: dict[str, PoseSeries] = {}
        self._history = history

    def add(self, msg: Any, static: bool, log_ns: int) -> int:
        """Take in one ``tf2_msgs/TFMessage``; a zero stamp means ``log_ns`` (when it arrived).

        Returns:
            Transforms left out because they are not a pose (a non-finite value or a zero
            quaternion), which would poison every camera position computed through them.

        """
        bad = 0
        for tf in msg.transforms:
            child = tf.child_frame_id.lstrip('/')
            parent = tf.header.frame_id.lstrip('/')
            t, q = tf.transform.translation, tf.transform.rotation
            pose = valid_pose([t.x, t.y, t.z], [q.x, q.y, q.z, q.w])
            if pose is None:
                bad += 1
                continue
            pos, quat = pose
            if static:
                self.static[child] = (parent, pose_matrix(pos, quat))
            elif child != self.skip_child:
                stamp = tf.header.stamp.sec * 1_000_000_000 + tf.header.stamp.nanosec
                if child not in self._samples:
                    self._samples[child] = (parent, deque(maxlen=self._history or None))
                self._samples[child][1].append((stamp or log_ns, pos, quat))
                self._series.pop(child, None)
        return bad

    def _moving(self, child: str, stamp_ns: int) -> tuple[str, F64] | None:
        parent, samples = self._samples[child]
        if child not in self._series:
            self._series[child] = PoseSeries.build(list(samples))
        pose = self._series[child].at(stamp_ns, MAX_GAP_NS)
        return None if pose is None else (parent, pose_matrix(pose[0], pose[1].as_quat()))

    def covers(self, parent: str, child: str, stamp_ns: int) -> bool:
        """Whether ``child`` links to ``parent`` with samples on both sides of ``stamp_ns``.

        Then :meth:`chain` at that stamp is final: no transform still to come changes it.
        """
        frame = child.lstrip('/')
        for _ in range(len(self.static) + len(self._samples) + 1):
            if frame == parent:
                return True
            if frame in self.static:
                frame = self.static[frame][0]
            elif frame in self._samples:
                up, samples = self._samples[frame]
                stamps = [sample[0] for sample in samples]
                if not min(stamps) <= stamp_ns <= max(stamps):
                    return False
                frame = up
            else:
                return False
        return False

    def chain(self, parent: str, child: str, stamp_ns: int) -> F64 | None:
        """4x4 transform ``child`` -> ``parent`` at ``stamp_ns``; None when not connected."""
        out = np.eye(4)
        frame = child.lstrip('/')
        for _ in range(len(self.static) + len(self._samples) + 1):
            if frame == parent:
                return out
            if frame in self.static:
                frame, step = self.static[frame]
            elif frame in self._samples:
                link = self._moving(frame, stamp_ns)
                if link is None:
                    return None
                frame, step = link
            else:
                return None
            out = step @ out
        return None


def odometry_entry(
    tree: TransformTree,
    position: Any,
    quat_xyzw: Any,
    frame_id: str,
    base_frame: str,
    camera_frame: str,
    stamp_ns: int,
) -> OdometryEntry:
    """Return the ``keyframes.jsonl`` odometry entry of a base pose at ``stamp_ns``.

    ``camera_position`` and ``camera_orientation_xyzw`` (the camera's optical frame in the
    odometry frame) are present only when ``tree`` links ``camera_frame`` to ``base_frame``: the
    base's own position is never a camera centre.
    """
    entry = OdometryEntry(
        position=[float(v) for v in np.asarray(position, dtype=np.float64)],
        orientation_xyzw=[float(v) for v in np.asarray(quat_xyzw, dtype=np.float64)],
        frame_id=frame_id,
        child_frame_id=base_frame,
    )
    if not camera_frame:
        return entry
    base_to_camera = tree.chain(base_frame.lstrip('/'), camera_frame, stamp_ns)
    if base_to_camera is not None:
        cam = pose_matrix(position, quat_xyzw) @ base_to_camera
        entry.camera_position = [float(v) for v in cam[:3, 3]]
        quat = Rotation.from_matrix(cam[:3, :3]).as_quat()
        entry.camera_orientation_xyzw = [float(v) for v in quat]
    return entry
