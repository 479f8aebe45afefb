"""The keyframe component: camera, camera info, odometry and tf in; keyframes and a status out.

The same object runs inside the keyframe node (rclpy messages) and the replay (rosbags messages).
A frame the selector keeps waits until odometry, and the transforms from the odometry's base to
the camera, have samples on both sides of its stamp, and a CameraInfo at or after it has come, so
that its pose is interpolated between the samples on both sides and its camera is the one of its
stamp, whatever order the topics arrive in (live, the image often overtakes its CameraInfo, and
odometry the /tf of the same instant). Once the frames have moved past it by more than
:data:`WAIT_NS` it goes out with what is known (a bag without odometry, a camera without
CameraInfo).
"""

from __future__ import annotations

import dataclasses
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from ..artefacts import WorkFolder
from ..camera import CameraModel, Frame
from ..recon.collector import KeyframeCollector, OdometryBuffer
from ..recon.keyframes import Decision
from ..recon.transforms import valid_pose
from ..ros import topics
from ..ros.convert import CameraInfoError, camera_model_from_msg, message_stamp_ns
from ..ros.images import ImageError, decode_image
from ..ros.messages import MessageFactory
from ..ros.publications import Publication, diagnostics, keyframe_status
from ..settings import Settings
from .handoff import keyframe_image, keyframe_message

__all__ = ['WAIT_NS', 'KeyframeComponent', 'KeyframeCounts']

WAIT_NS = 2_000_000_000
"""How far the camera's stamps may run ahead of a kept frame's odometry, transforms and
CameraInfo before it goes out with what is known [ns]. Stream time, not a measurement rule: a
recording without odometry waits this long per keyframe. Live, the keyframe node queues every
topic in arrival order (``nodes.common.Inbox``), so the odometry is not held back behind a burst
of images and the wait runs out only when a stream is missing.
"""


@dataclass
class KeyframeCounts:
    """What the component saw beyond the collector's state.

    Attributes:
        camera_info: Usable CameraInfo messages.
        skipped: Frames that could not be decoded, by reason.
        without_odometry: Keyframes sent without an odometry pose although odometry was asked for.
        with_camera: Keyframes sent with the intrinsics of a CameraInfo.
        bad_poses: Odometry samples and transforms left out (non-finite, zero quaternion).

    """

    camera_info: int = 0
    skipped: dict[str, int] = field(default_factory=dict)
    without_odometry: int = 0
    with_camera: int = 0
    bad_poses: int = 0


@dataclass
class _Pending:
    frame: Frame
    decision: Decision
    image: tuple[str, bytes]


class KeyframeComponent:
    """Select keyframes from a camera stream and hand them on as ``Keyframe`` messages.

    Args:
        settings: Parameters (selector, odometry use, work folder).
        f: Message factory of the library the messages are built with.

    """

    def __init__(self, settings: Settings, f: MessageFactory) -> None:
        self.f = f
        self.use_odometry = settings.recon.use_odometry
        self.max_pixels = settings.recon.max_image_pixels
        self.collector = KeyframeCollector(
            WorkFolder(settings.work_dir).capture,
            settings.recon.selector,
            float(settings.values['coverage_full_parallax']),
        )
        self.odometry = OdometryBuffer()
        self._cameras: deque[tuple[int, CameraModel]] = deque(maxlen=64)
        self.counts = KeyframeCounts()
        self._pending: list[_Pending] = []
        self._seen = 0
        self._size: tuple[int, ...] | None = None
        records = self.collector.store.records
        # Resumed: frames up to the last one kept are the same recording again.
        self._resume_after = records[-1].stamp_ns if records else None
        self._latest_frame_ns = 0
        self._noted: set[str] = set()

    def reconfigure(self, settings: Settings) -> None:
        """Take changed parameters (a node's ``ros2 param set``) from the next frame on."""
        self.use_odometry = settings.recon.use_odometry
        self.max_pixels = settings.recon.max_image_pixels
        self.collector.selector.reconfigure(settings.recon.selector)

    @property
    def pending(self) -> int:
        """Keyframes kept but still waiting for their odometry."""
        return len(self._pending)

    def _note(self, key: str, level: str, text: str, stamp_ns: int) -> list[Publication]:
        """Return a diagnostic, once per ``key``."""
        if key in self._noted:
            return []
        self._noted.add(key)
        return [diagnostics(self.f, stamp_ns, key.split(':')[0], level, text)]

    def on_camera_info(self, msg: Any, log_ns: int) -> list[Publication]:
        """Keep the latest usable camera model."""
        try:
            camera = camera_model_from_msg(msg)
        except CameraInfoError as exc:
            return self._note('camera_info:bad', 'WARN', f'{exc}; frames are self-calibrated',
                              log_ns)  # fmt: skip
        self._cameras.append((message_stamp_ns(msg, log_ns), camera))
        self.counts.camera_info += 1
        return self._resolve(final=False)

    def on_odometry(self, msg: Any, log_ns: int) -> list[Publication]:
        """Buffer the pose; send the keyframes it completes."""
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        stamp = message_stamp_ns(msg, log_ns)
        pose = valid_pose((p.x, p.y, p.z), (q.x, q.y, q.z, q.w))
        if pose is None:
            return self._bad_poses(1, 'odometry', log_ns)
        frames = (str(msg.header.frame_id), str(msg.child_frame_id))
        self.odometry.push(stamp, *pose, *frames)
        return self._resolve(final=False)

    def on_tf(self, msg: Any, static: bool, log_ns: int) -> list[Publication]:
        """Keep the cart's transforms (``/tf_static``: the camera mount; ``/tf``: a moving mast)."""
        return self._bad_poses(self.odometry.tree.add(msg, static=static, log_ns=log_ns),
                               'tf', log_ns)  # fmt: skip

    def _bad_poses(self, count: int, what: str, stamp_ns: int) -> list[Publication]:
        if not count:
            return []
        self.counts.bad_poses += count
        return self._note(f'odometry:{what}', 'WARN',
                          f'{what}: a pose with a non-finite value or a zero quaternion was left '
                          'out (the driver has no fix yet?); later ones like it are counted in '
                          'the summary', stamp_ns)  # fmt: skip

    def on_image(self, msg: Any, log_ns: int) -> list[Publication]:
        """Offer one frame to the selector; return the status and any keyframes completed."""
        stamp = message_stamp_ns(msg, log_ns)
        index = self._seen
        self._seen += 1
        if self._resume_after is not None and stamp <= self._resume_after:
            return []
        try:
            image = decode_image(msg, self.max_pixels)
        except ImageError as exc:
            reason = str(exc)
            self.counts.skipped[reason] = self.counts.skipped.get(reason, 0) + 1
            return self._note(f'camera:{reason}', 'ERROR', f'frame skipped: {reason}', stamp)
        size = image.shape[:2]
        if self._size is None:
            self._size = size
        elif size != self._size:
            # One capture, one camera: SfM and the intrinsics assume it.
            reason = (f'image size changed from {self._size[1]}x{self._size[0]} to '
                      f'{size[1]}x{size[0]}')  # fmt: skip
            self.counts.skipped[reason] = self.counts.skipped.get(reason, 0) + 1
            text = f'frames skipped: {reason} (one capture, one camera)'
            return self._note(f'camera:{reason}', 'ERROR', text, stamp)
        frame = Frame(stamp, image, str(msg.header.frame_id), None, topics.IMAGE, index)
        decision = self.collector.select(frame)
        self._latest_frame_ns = max(self._latest_frame_ns, stamp)
        if decision.accepted:
            self._pending.append(_Pending(frame, decision, keyframe_image(msg, image)))
        out = self._resolve(final=False)
        out.append(self.status(stamp))
        return out

    def on_dropped(self, count: int, log_ns: int) -> list[Publication]:
        """Count frames a live node had to drop because it fell behind the camera."""
        if not count:
            return []
        reason = 'the keyframe node fell behind the camera'
        self.counts.skipped[reason] = self.counts.skipped.get(reason, 0) + count
        return self._note('camera:behind', 'WARN',
                          f'{reason}: frames dropped (a slower computer? fewer pixels with '
                          'recon.max_image_pixels); later drops are counted in the summary',
                          log_ns)  # fmt: skip

    def _camera(self, frame: Frame) -> tuple[CameraModel | None, list[Publication]]:
        """Return the CameraInfo nearest the frame's stamp if it fits the image, and why not."""
        if not self._cameras:
            return None, self._note('camera_info:none', 'WARN',
                                    'no CameraInfo for the images: the intrinsics are '
                                    'self-calibrated by Structure-from-Motion',
                                    frame.stamp_ns)  # fmt: skip
        _, camera = min(self._cameras, key=lambda c: abs(c[0] - frame.stamp_ns))
        if camera.fits(frame.image):
            return camera, []
        height, width = frame.image.shape[:2]
        return None, self._note('camera_info:size', 'WARN',
                                f'CameraInfo is {camera.width}x{camera.height} but the images '
                                f'are {width}x{height}: such frames are self-calibrated',
                                frame.stamp_ns)  # fmt: skip

    def status(self, stamp_ns: int) -> Publication:
        """Return the keyframe status; its count includes the keyframes waiting for odometry.

        A reconstruction waits for every keyframe announced, so the count must not leave out
        the last ones of a pass, still waiting when the trigger comes.
        """
        state = self.collector.state
        announced = dataclasses.replace(state, keyframes=state.keyframes + len(self._pending))
        return keyframe_status(self.f, stamp_ns, announced)

    def flush(self, stamp_ns: int) -> list[Publication]:
        """Send every waiting keyframe with the odometry known now, and count the frames skipped.

        For the end of a recording, where nothing more will complete them.
        """
        out = self._resolve(final=True)
        if out:
            out.append(self.status(stamp_ns))
        if self.counts.skipped:
            total = sum(self.counts.skipped.values())
            why = '; '.join(f'{n} x {reason}' for reason, n in self.counts.skipped.items())
            out.append(diagnostics(self.f, stamp_ns, 'camera', 'ERROR',
                                   f'{total} frames skipped: {why}'))  # fmt: skip
        return out

    def _ready(self, frame: Frame) -> bool:
        stamp = frame.stamp_ns
        odometry = not self.use_odometry or self.odometry.covers(stamp, frame.frame_id)
        camera = any(c[0] >= stamp for c in self._cameras)
        return (odometry and camera) or self._latest_frame_ns - stamp > WAIT_NS

    def _resolve(self, final: bool) -> list[Publication]:
        """Store and send the waiting keyframes whose odometry is known, in order."""
        out: list[Publication] = []
        while self._pending and (final or self._ready(self._pending[0].frame)):
            item = self._pending.pop(0)
            camera, notes = self._camera(item.frame)
            out += notes
            self.counts.with_camera += camera is not None
            frame = dataclasses.replace(item.frame, camera=camera)
            odometry = None
            if self.use_odometry:
                # The image's own frame (REP 104: its optical frame), as _ready waited for.
                odometry = self.odometry.at(frame.stamp_ns, frame.frame_id)
                if odometry is None:
                    self.counts.without_odometry += 1
            number = len(self.collector.store.records)
            record = self.collector.keep(frame, item.decision, odometry)
            msg = keyframe_message(self.f, record, number, frame.frame_id, item.image)
            out.append((topics.KEYFRAMES, msg))
        return out
