"""Keyframe collection from a live or recorded stream: the one code path of node and replay.

Coverage, 0..1, says how much of the way around the pile the accepted keyframes reach:

- with odometry, the share of the 36 ten-degree heading sectors swept by the camera between
  consecutive keyframes (yaw of the odometry orientation, shorter arc between neighbours); a
  camera that keeps the pile in view while circling it turns its heading as far as it goes
  around, so a full orbit gives 1 and a 90 degree arc about 0.25;
- without odometry, the parallax summed over the accepted keyframes (median tracked corner
  displacement, in image widths) over ``full_parallax``: a rough proxy that grows with the
  distance travelled across the view, not with the angle around the pile.
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from ..artefacts import KeyframeRecord, OdometryEntry
from ..camera import Frame
from .keyframes import Decision, KeyframeSelector, KeyframeStore, SelectorOptions
from .transforms import MAX_GAP_NS, PoseSeries, TransformTree, odometry_entry

__all__ = [
    'HEADING_SECTORS',
    'CollectorState',
    'KeyframeCollector',
    'OdometryBuffer',
    'camera_orientation',
    'heading_coverage',
]

HEADING_SECTORS = 36


def _yaw(quat_xyzw: Any) -> float:
    x, y, z, w = (float(v) for v in quat_xyzw)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def camera_orientation(odometry: OdometryEntry | None) -> npt.NDArray[np.float64] | None:
    """Camera-to-world rotation of a ``keyframes.jsonl`` odometry entry, None without a camera.

    Only the camera's own orientation (``camera_orientation_xyzw``, placed by the transforms from
    the odometry's base to the camera) counts: the base turns with the cart, not with a mast.
    """
    if odometry is None or odometry.camera_orientation_xyzw is None:
        return None
    return np.asarray(Rotation.from_quat(odometry.camera_orientation_xyzw).as_matrix())


def heading_coverage(yaws: list[float]) -> float:
    """Share of :data:`HEADING_SECTORS` sectors swept by consecutive headings [rad]."""
    if not yaws:
        return 0.0
    width = 2 * math.pi / HEADING_SECTORS
    hit = np.zeros(HEADING_SECTORS, dtype=bool)
    hit[int((yaws[0] % (2 * math.pi)) // width) % HEADING_SECTORS] = True
    for a, b in itertools.pairwise(yaws):
        step = (b - a + math.pi) % (2 * math.pi) - math.pi
        n = max(1, math.ceil(abs(step) / (width / 2)))
        for t in np.linspace(0.0, 1.0, n + 1):
            hit[int(((a + t * step) % (2 * math.pi)) // width) % HEADING_SECTORS] = True
    # One sector is hit by any single keyframe: count the sweep beyond it.
    return float(max(0, int(hit.sum()) - 1) / (HEADING_SECTORS - 1))


@dataclass
class CollectorState:
    """What the collector holds.

    Attributes:
        frames: Frames pushed.
        keyframes: Keyframes stored (resumed ones included).
        coverage: 0..1, see the module documentation.
        coverage_source: ``"odometry"`` or ``"parallax"``.
        decisions: Count of each decision reason.
        last: The last decision, None before the first frame.

    """

    frames: int = 0
    keyframes: int = 0
    coverage: float = 0.0
    coverage_source: str = 'parallax'
    decisions: dict[str, int] = field(default_factory=dict)
    last: Decision | None = None


class KeyframeCollector:
    """Select keyframes from frames as they come and store them in ``keyframes/``.

    Resumes from what the folder already holds (the selector continues from its last keyframe).

    Args:
        folder: The work folder's ``keyframes/``.
        options: Selector thresholds.
        full_parallax: Summed parallax [image widths] counted as full coverage without odometry.

    """

    def __init__(
        self, folder: str | Path, options: SelectorOptions | None = None, full_parallax: float = 6.0
    ) -> None:
        self.store = KeyframeStore(folder)
        self.selector = KeyframeSelector(options)
        self.full_parallax = full_parallax
        self.state = CollectorState(keyframes=len(self.store.records))
        self._parallax = 0.0
        self._yaws = [
            _yaw(r.odometry.orientation_xyzw) for r in self.store.records if r.odometry is not None
        ]
        if self.store.records:
            last = self.store.records[-1]
            self.selector.resume(self.store.image(last), len(self.store.records),
                                 camera_orientation(last.odometry))  # fmt: skip
        self._update_coverage()

    def _update_coverage(self) -> None:
        if self._yaws:
            self.state.coverage = heading_coverage(self._yaws)
            self.state.coverage_source = 'odometry'
        else:
            self.state.coverage = min(1.0, self._parallax / self.full_parallax)
            self.state.coverage_source = 'parallax'

    def select(self, frame: Frame, odometry: OdometryEntry | None = None) -> Decision:
        """Offer one frame to the selector and count its decision; nothing is stored yet.

        A live stream stores an accepted frame once its odometry is known (:meth:`keep`).

        Args:
            frame: The decoded frame; its ``camera`` (None: a field of view is assumed) turns
                pixels into rays for the viewing angle.
            odometry: The odometry entry at the frame's stamp when it is known already; its
                camera orientation gives the rotation between this frame and the last keyframe
                (None: the rotation is fitted to the tracked corners).

        """
        decision = self.selector.push(frame.image, frame.camera, camera_orientation(odometry))
        self.state.frames += 1
        self.state.decisions[decision.reason] = self.state.decisions.get(decision.reason, 0) + 1
        self.state.last = decision
        return decision

    def keep(
        self, frame: Frame, decision: Decision, odometry: OdometryEntry | None = None
    ) -> KeyframeRecord:
        """Store an accepted frame as the next keyframe, with its odometry entry (or None)."""
        record = self.store.add(frame, odometry=odometry, reason=decision.reason,
                                 sharpness=decision.sharpness)  # fmt: skip
        self.state.keyframes = len(self.store.records)
        if math.isfinite(decision.parallax):
            self._parallax += decision.parallax
        if odometry is not None:
            self._yaws.append(_yaw(odometry.orientation_xyzw))
        self._update_coverage()
        return record

    def push(self, frame: Frame, odometry: OdometryEntry | None = None) -> Decision:
        """Offer one frame; store it at once when it is a keyframe (odometry known up front).

        Args:
            frame: The decoded frame (its ``camera`` is stored with it; None: self-calibration).
            odometry: The ``keyframes.jsonl`` odometry entry at the frame's stamp, or None.

        Returns:
            The selector's decision.

        """
        decision = self.select(frame, odometry)
        if decision.accepted:
            self.keep(frame, decision, odometry)
        return decision


class OdometryBuffer:
    """Recent odometry poses of a live stream, interpolated at frame stamps.

    A pose is read
    between the samples on both sides of the frame's stamp (:meth:`covers` says when the later one
    has arrived), and the camera's pose when ``tree`` (fed from ``/tf_static`` and ``/tf``) links
    the camera's frame to the odometry's moving frame.

    Args:
        size: Poses kept.
        max_gap_ns: Largest gap between the two samples interpolated across [ns].

    """

    def __init__(self, size: int = 400, max_gap_ns: int = MAX_GAP_NS) -> None:
        self.max_gap_ns = max_gap_ns
        self.tree = TransformTree()
        self._poses: deque[tuple[int, Any, Any]] = deque(maxlen=size)
        self._frames = ('', '')
        self._series: PoseSeries | None = None

    @property
    def latest_ns(self) -> int | None:
        """Stamp of the newest sample, None before the first."""
        return max(s[0] for s in self._poses) if self._poses else None

    def push(
        self,
        stamp_ns: int,
        position: Sequence[float],
        orientation_xyzw: Sequence[float],
        frame_id: str,
        child_frame_id: str,
    ) -> None:
        """Add one pose (any order: the series is sorted by stamp)."""
        self._poses.append((int(stamp_ns), [float(v) for v in position],
                            [float(v) for v in orientation_xyzw]))  # fmt: skip
        self._frames = (frame_id, child_frame_id)
        self._series = None

    def covers(self, stamp_ns: int, camera_frame: str = '') -> bool:
        """Whether samples at or before and at or after ``stamp_ns`` have arrived.

        With ``camera_frame``, the transforms from the odometry's moving frame to the camera too
        (a camera on a moving mast). Then :meth:`at` is final: no sample still to come can change
        what it returns.
        """
        stamps = [s[0] for s in self._poses]
        if not stamps or not min(stamps) <= stamp_ns <= max(stamps):
            return False
        return not camera_frame or self.tree.covers(self._frames[1].lstrip('/'), camera_frame,
                                                    stamp_ns)  # fmt: skip

    def at(self, stamp_ns: int, camera_frame: str = '') -> OdometryEntry | None:
        """Return the ``keyframes.jsonl`` odometry entry at ``stamp_ns``.

        None unless samples on both sides lie within ``max_gap_ns`` of each other. With
        ``camera_frame``, the entry holds the camera's position and orientation when the
        transforms link that frame to the odometry's moving frame.
        """
        if not self._poses:
            return None
        if self._series is None:
            self._series = PoseSeries.build(list(self._poses))
        pose = self._series.at(stamp_ns, self.max_gap_ns)
        if pose is None:
            return None
        position, rotation = pose
        frame_id, child = self._frames
        return odometry_entry(self.tree, position, rotation.as_quat(), frame_id, child,
                              camera_frame, stamp_ns)  # fmt: skip
