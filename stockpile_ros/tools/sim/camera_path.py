"""Paths a camera cart drives past a pile, and the camera poses along them.

The cart (``base_link``, on the ground, x forward, z up) carries a mast with the camera looking to
its left, tilted down towards the pile. One height: a single pass. Two heights: a pass, a stop
while the mast moves to the second height, and a pass back (the cart reverses along its own track).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ...errors import StockpileError
from .pile import rotation_z

__all__ = [
    'OPTICAL_IN_LINK',
    'CartPath',
    'PathConfig',
    'auto_distance',
    'quat_from_matrix',
    'rotation_y',
]

PATH_KINDS = ('arc', 'straight', 'orbit')

# camera_link (x forward, y left, z up) -> camera_optical_frame (x right, y down, z forward).
OPTICAL_IN_LINK = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def rotation_y(angle: float) -> npt.NDArray[np.float64]:
    """Rotation by ``angle`` [rad] about y."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def quat_from_matrix(r: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Return the unit quaternion (x, y, z, w) of a rotation matrix, with w >= 0."""
    m = np.asarray(r, dtype=np.float64)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
    quat = np.asarray(q)
    quat /= np.linalg.norm(quat)
    return quat if quat[3] >= 0 else -quat


@dataclass(frozen=True)
class PathConfig:
    """Where and how the cart drives.

    Attributes:
        kind: ``arc``, ``straight`` or ``orbit`` (a full circle).
        heights: Camera heights above the ground, one per pass [m].
        distance: Radius of arc and orbit, or distance of the straight line from the pile
            centre [m]; None: chosen from the pile's size by :func:`auto_distance`.
        arc_degrees: Angle swept by an arc.
        length: Length of a straight pass [m].
        aim_height: Height of the point the camera aims at above the pile centre [m].
        heading: Direction (world yaw, rad) from the pile centre to the middle of the path.
        transition: Stop between two passes while the mast moves [s].

    """

    kind: str = 'arc'
    heights: tuple[float, ...] = (1.0,)
    distance: float | None = None
    arc_degrees: float = 120.0
    length: float = 4.0
    aim_height: float = 0.1
    heading: float = -np.pi / 2
    transition: float = 1.0


def auto_distance(pile_radius: float) -> float:
    """Distance of the path from the pile centre that keeps the whole pile in view, close up [m].

    Args:
        pile_radius: Largest horizontal distance of any rock point from the pile centre [m].

    """
    return max(0.8, 1.3 * pile_radius + 0.45)


class CartPath:
    """Poses of the cart and its camera as functions of time.

    Args:
        cfg: The path.
        duration: Total time from the first to the last frame [s].

    """

    def __init__(self, cfg: PathConfig, duration: float):
        if cfg.kind not in PATH_KINDS:
            raise StockpileError(f'unknown path {cfg.kind!r}; use one of {", ".join(PATH_KINDS)}')
        if cfg.distance is None or cfg.distance <= 0:
            raise StockpileError('the path needs a positive distance from the pile')
        if len(cfg.heights) not in (1, 2) or min(cfg.heights) <= 0:
            raise StockpileError('give one or two positive camera heights')
        transition = cfg.transition if len(cfg.heights) == 2 else 0.0
        self.pass_time = (duration - transition) / len(cfg.heights)
        if self.pass_time <= 0:
            raise StockpileError(f'duration {duration} s is too short for the path')
        self.cfg = cfg
        self.distance = float(cfg.distance)
        self.duration = duration
        self.transition = transition

    def _progress(self, t: float) -> tuple[float, int, float]:
        """Track parameter s in [0, 1], pass index, and mast blend (0: first height, 1: second)."""
        t = float(np.clip(t, 0.0, self.duration))
        if t <= self.pass_time or len(self.cfg.heights) == 1:
            return min(t / self.pass_time, 1.0), 0, 0.0
        if t <= self.pass_time + self.transition:
            blend = (t - self.pass_time) / self.transition
            return 1.0, 0, 0.5 - 0.5 * np.cos(np.pi * blend)
        s = 1.0 - (t - self.pass_time - self.transition) / self.pass_time
        return max(s, 0.0), 1, 1.0

    def base_pose(self, t: float) -> tuple[npt.NDArray[np.float64], float]:
        """Cart position (z = 0) and yaw [rad] in the world frame at time ``t``."""
        s, _, _ = self._progress(t)
        c = self.cfg
        if c.kind == 'straight':
            along = np.array([np.cos(c.heading + np.pi / 2), np.sin(c.heading + np.pi / 2), 0.0])
            out = np.array([np.cos(c.heading), np.sin(c.heading), 0.0]) * self.distance
            return out + along * c.length * (s - 0.5), float(c.heading + np.pi / 2)
        span = np.radians(c.arc_degrees) if c.kind == 'arc' else 2 * np.pi
        phi = c.heading + span * (s - 0.5)
        pos = np.array([np.cos(phi), np.sin(phi), 0.0]) * self.distance
        return pos, float(phi + np.pi / 2)

    def mount(self, t: float) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Return the translation and rotation of ``camera_link`` in ``base_link`` at time ``t``."""
        _, _, blend = self._progress(t)
        hs = self.cfg.heights
        height = hs[0] if len(hs) == 1 else (1 - blend) * hs[0] + blend * hs[1]
        tilt = np.arctan2(height - self.cfg.aim_height, self.distance)
        # Looking left (+90 deg yaw), pitched down by the tilt.
        rot = rotation_z(np.pi / 2) @ rotation_y(tilt)
        return np.array([0.0, 0.0, height]), rot

    def camera_pose(self, t: float) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Optical centre and camera-to-world rotation of the optical frame at time ``t``."""
        base, yaw = self.base_pose(t)
        trans, rot = self.mount(t)
        r_base = rotation_z(yaw)
        return base + r_base @ trans, r_base @ rot @ OPTICAL_IN_LINK
