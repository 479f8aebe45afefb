"""A PointCloud2 stream (a depth camera, a LiDAR) accumulated in the odometry frame.

Each cloud waits, as a keyframe does, until odometry has samples on both sides of its stamp and
the transforms link its frame to the odometry's moving one; it is then moved into the odometry
frame with the sensor's pose interpolated at its stamp, and every point keeps the direction to
the sensor that saw it (normals are turned that way). A cloud that no pose can place is dropped
and counted, never placed where the cart was not. Without any odometry the sensor is taken as
fixed: every cloud must then share one frame, which becomes the accumulated one (a scanner on a
tripod). Past ``max_points`` the accumulated cloud is thinned on a voxel grid of its own spacing.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ..recon.collector import OdometryBuffer
from ..recon.transforms import pose_matrix, valid_pose
from ..ros.convert import message_stamp_ns
from ..ros.outputs import pointcloud2_arrays
from .mesh import point_spacing
from .read import Cloud

__all__ = ['CloudAccumulator', 'CloudCounts']

F64 = npt.NDArray[np.float64]

# How far the stream may run past a cloud before it is placed with what is known [ns]: stream
# time, as for keyframes (components.keyframes.WAIT_NS).
_WAIT_NS = 2_000_000_000
# Thinning shrinks the cloud to this share of max_points, so that it does not run again soon.
_THIN_TO = 0.5


@dataclass
class CloudCounts:
    """What the accumulator saw.

    Attributes:
        messages: PointCloud2 messages received.
        placed: Messages moved into the accumulated frame.
        unplaced: Messages dropped: no pose for their stamp and frame, or another frame than the
            first one without odometry.
        bad: Messages that could not be decoded (no x, y, z; short data), by reason.
        points: Points held now.
        thinned: Times the cloud was thinned to stay under ``max_points``.

    """

    messages: int = 0
    placed: int = 0
    unplaced: int = 0
    bad: dict[str, int] = field(default_factory=dict)
    points: int = 0
    thinned: int = 0


@dataclass
class _Pending:
    stamp_ns: int
    frame: str
    points: F64
    colors: npt.NDArray[np.uint8] | None


class CloudAccumulator:
    """PointCloud2 messages, odometry and transforms in; one cloud in the odometry frame out.

    Args:
        max_points: Most points held.

    """

    def __init__(self, max_points: int) -> None:
        self.max_points = max_points
        self.odometry = OdometryBuffer()
        self.counts = CloudCounts()
        self.frame_id = ''
        self._pending: list[_Pending] = []
        self._points: list[F64] = []
        self._towards: list[F64] = []
        self._colors: list[npt.NDArray[np.uint8] | None] = []
        self._latest_ns = 0
        self._odometry_seen = False

    @property
    def received(self) -> bool:
        """Whether any cloud arrived."""
        return self.counts.messages > 0

    def on_odometry(self, msg: Any, log_ns: int) -> None:
        """Buffer one ``nav_msgs/Odometry`` pose."""
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        pose = valid_pose((p.x, p.y, p.z), (q.x, q.y, q.z, q.w))
        if pose is None:
            return
        self._odometry_seen = True
        self.odometry.push(message_stamp_ns(msg, log_ns), *pose, str(msg.header.frame_id),
                           str(msg.child_frame_id))  # fmt: skip
        self._resolve(final=False)

    def on_tf(self, msg: Any, static: bool, log_ns: int) -> None:
        """Keep the cart's transforms (the sensor's mount)."""
        self.odometry.tree.add(msg, static=static, log_ns=log_ns)
        self._resolve(final=False)

    def on_cloud(self, msg: Any, log_ns: int) -> str | None:
        """Take one ``sensor_msgs/PointCloud2``; return why it cannot be used, None when it can."""
        self.counts.messages += 1
        try:
            points, colors, _ = pointcloud2_arrays(msg)
        except ValueError as exc:
            reason = str(exc)
            self.counts.bad[reason] = self.counts.bad.get(reason, 0) + 1
            return reason
        xyz = np.asarray(points, dtype=np.float64)
        # Depth cameras mark pixels without a return with NaN.
        good = np.isfinite(xyz).all(axis=1)
        stamp = message_stamp_ns(msg, log_ns)
        self._latest_ns = max(self._latest_ns, stamp)
        self._pending.append(_Pending(stamp, str(msg.header.frame_id).lstrip('/'), xyz[good],
                                      None if colors is None else colors[good]))  # fmt: skip
        self._resolve(final=False)
        return None

    def _pose(self, item: _Pending) -> F64 | None:
        """4x4 sensor-to-accumulated-frame transform at the cloud's stamp, None when unknown."""
        if not self._odometry_seen:
            self.frame_id = self.frame_id or item.frame
            return np.eye(4) if item.frame == self.frame_id else None
        entry = self.odometry.at(item.stamp_ns, item.frame)
        if entry is None:
            return None
        self.frame_id = entry.frame_id.lstrip('/')
        if item.frame == self.frame_id:
            return np.eye(4)  # already in the odometry frame
        if entry.camera_position is None or entry.camera_orientation_xyzw is None:
            return None
        return pose_matrix(entry.camera_position, entry.camera_orientation_xyzw)

    def _resolve(self, final: bool) -> None:
        while self._pending:
            item = self._pending[0]
            ready = (not self._odometry_seen or self.odometry.covers(item.stamp_ns, item.frame)
                     or self._latest_ns - item.stamp_ns > _WAIT_NS)  # fmt: skip
            if not (ready or final):
                return
            self._pending.pop(0)
            pose = self._pose(item)
            if pose is None:
                self.counts.unplaced += 1
                continue
            moved = item.points @ pose[:3, :3].T + pose[:3, 3]
            towards = pose[:3, 3] - moved
            towards /= np.maximum(np.linalg.norm(towards, axis=1, keepdims=True), 1e-12)
            self._points.append(moved)
            self._towards.append(towards)
            self._colors.append(item.colors)
            self.counts.placed += 1
            self.counts.points += len(moved)
            if self.counts.points > self.max_points:
                self._thin()

    def _thin(self) -> None:
        """Merge points closer than the cloud's spacing, coarser until under the budget."""
        import open3d

        o3d: Any = open3d
        points, towards, colors = self._stacked()
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        pcd.normals = o3d.utility.Vector3dVector(towards)
        if colors is not None:
            pcd.colors = o3d.utility.Vector3dVector(colors / 255.0)
        voxel, _ = point_spacing(points[:: max(1, len(points) // 200_000)])
        while len(pcd.points) > _THIN_TO * self.max_points:
            voxel = max(voxel * 1.5, 1e-9)
            pcd = pcd.voxel_down_sample(voxel)
        self._points = [np.asarray(pcd.points, dtype=np.float64)]
        normals = np.asarray(pcd.normals, dtype=np.float64)
        self._towards = [normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True),
                                              1e-12)]  # fmt: skip
        kept = np.asarray(pcd.colors)
        self._colors = [None if colors is None else
                        np.clip(np.round(kept * 255), 0, 255).astype(np.uint8)]  # fmt: skip
        self.counts.points = len(self._points[0])
        self.counts.thinned += 1

    def _stacked(self) -> tuple[F64, F64, npt.NDArray[np.uint8] | None]:
        points = np.concatenate(self._points) if self._points else np.zeros((0, 3))
        towards = np.concatenate(self._towards) if self._towards else np.zeros((0, 3))
        colors = None
        if self._colors and all(c is not None for c in self._colors):
            colors = np.concatenate([c for c in self._colors if c is not None])
        return points, towards, colors

    def cloud(self, source: str) -> tuple[Cloud, F64]:
        """Place every cloud still waiting, and return the accumulated cloud and viewpoints.

        Returns:
            The cloud (in :attr:`frame_id`, metres) and, per point, a point one metre towards
            the sensor that saw it (for :func:`~.mesh.mesh_cloud`'s ``viewpoints``).

        """
        self._resolve(final=True)
        points, towards, colors = self._stacked()
        return Cloud(points, None, colors, source, 'pointcloud2'), points + towards
