"""The reconstruction component: keyframes in; on a trigger sfm, dense, mesh; the surface out.

Keyframes arrive as ``Keyframe`` messages and are written into this component's own work folder,
so it needs nothing from the keyframe node's disk. A ``PointCloud2`` stream (a depth camera, a
LiDAR) is accumulated in the odometry frame as it comes (:mod:`stockpile_ros.cloud.accumulate`,
with the odometry and ``/tf`` it needs); a run meshes that cloud instead of running
Structure-from-Motion when ``cloud.source`` says so (``auto``: clouds arrived, no keyframe
held). A run publishes, in this order: one ``RECONSTRUCTING`` status per stage, the stages'
diagnostics, then either a ``FAILED`` status or the dense cloud, the mesh markers, the stockpile
frame on ``/tf_static``, a ``SEGMENTING`` status and the ``SurfaceMesh`` for the segmentation.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from scipy.spatial.transform import Rotation

from ..artefacts import MeshInfo, WorkFolder
from ..cloud.accumulate import CloudAccumulator
from ..recon.collector import CollectorState
from ..recon.keyframes import KeyframeStore
from ..ros import topics
from ..ros.convert import CameraInfoError
from ..ros.images import ImageError
from ..ros.messages import MessageFactory, tf_message, transform_stamped
from ..ros.publications import (
    Publication,
    diagnostics,
    reconstruction_diagnostics,
    reconstruction_outputs,
    status,
)
from ..runner import RECON_STAGES, Outcome, run_cloud_reconstruction, run_reconstruction
from ..settings import Settings
from .handoff import read_keyframe, surface_message

__all__ = ['Emit', 'ReconstructionComponent']

Emit = Callable[[list[Publication]], None]
"""Where a long run sends what it publishes, as it goes (the node publishes, the replay writes)."""


class ReconstructionComponent:
    """Hold the keyframes received and reconstruct them on request.

    Args:
        settings: Parameters at start (work folder, auto trigger).
        f: Message factory.

    """

    def __init__(self, settings: Settings, f: MessageFactory) -> None:
        self.f = f
        self.work = WorkFolder(settings.work_dir)
        self.store = KeyframeStore(self.work.keyframes)
        self.auto_trigger = int(settings.values['auto_trigger_keyframes'])
        self.max_pixels = settings.recon.max_image_pixels
        self.announced = 0
        self.coverage = 0.0
        self._auto_started = False
        self._held = threading.Condition()
        self._stamps = {r.stamp_ns for r in self.store.records}
        self.clouds = CloudAccumulator(settings.cloud.max_points)
        self._cloud_lock = threading.Lock()
        self._noted: set[str] = set()

    @property
    def held(self) -> CollectorState:
        """Keyframes held and the coverage the keyframe node reported for them."""
        return CollectorState(keyframes=len(self.store.records), coverage=self.coverage)

    def on_keyframe(self, msg: Any, log_ns: int) -> list[Publication]:
        """Store one keyframe (a repeat of one held is ignored)."""
        try:
            received = read_keyframe(msg, self.max_pixels)
        except (ImageError, CameraInfoError) as exc:
            return [diagnostics(self.f, log_ns, 'keyframes', 'ERROR',
                                f'keyframe {msg.index} unusable: {exc}')]  # fmt: skip
        with self._held:
            if received.frame.stamp_ns not in self._stamps:
                self.store.add(received.frame, odometry=received.odometry,
                               reason=received.reason, sharpness=received.sharpness)  # fmt: skip
                self._stamps.add(received.frame.stamp_ns)
            self._held.notify_all()
        return []

    def on_cloud(self, msg: Any, log_ns: int) -> list[Publication]:
        """Accumulate one ``PointCloud2``; a diagnostic, once per reason, when it is unusable."""
        with self._cloud_lock:
            reason = self.clouds.on_cloud(msg, log_ns)
        if reason is None or reason in self._noted:
            return []
        self._noted.add(reason)
        return [diagnostics(self.f, log_ns, 'cloud', 'ERROR', f'point cloud skipped: {reason}')]

    def on_odometry(self, msg: Any, log_ns: int) -> list[Publication]:
        """Keep the odometry that places the clouds."""
        with self._cloud_lock:
            self.clouds.on_odometry(msg, log_ns)
        return []

    def on_tf(self, msg: Any, static: bool, log_ns: int) -> list[Publication]:
        """Keep the transforms that place the clouds (the sensor's mount on the cart)."""
        with self._cloud_lock:
            self.clouds.on_tf(msg, static, log_ns)
        return []

    def uses_cloud(self, settings: Settings) -> bool:
        """Whether a run now meshes the accumulated cloud rather than the keyframes."""
        source = settings.cloud.source
        if source == 'auto':
            return self.clouds.received and not self.store.records
        return source == 'cloud'

    def _run_cloud(
        self, settings: Settings, on_stage: Callable[[str, int, float | None], None]
    ) -> Outcome:
        with self._cloud_lock:
            cloud, viewpoints = self.clouds.cloud(settings.cloud.topic or topics.CLOUD)
            c = self.clouds.counts
            stream = {'frame_id': self.clouds.frame_id, 'messages': c.messages,
                      'placed': c.placed, 'unplaced': c.unplaced, 'bad': sum(c.bad.values()),
                      'thinned': c.thinned}  # fmt: skip
        return run_cloud_reconstruction(settings, cloud, viewpoints, on_stage, stream)

    def _stockpile_frame(self, stamp_ns: int, info: MeshInfo) -> list[Publication]:
        """``/tf_static``: the stockpile frame in the cloud's frame (the levelling, inverted)."""
        sim = info.model_to_stockpile.similarity()
        position = -sim.rotation.T @ sim.translation / sim.scale
        quat = Rotation.from_matrix(sim.rotation.T).as_quat()
        frame = self.clouds.frame_id or 'odom'
        transform = transform_stamped(self.f, stamp_ns, frame, 'stockpile', position, quat)
        return [(topics.TF_STATIC, tf_message(self.f, [transform]))]

    def on_keyframe_status(self, msg: Any) -> bool:
        """Track what the keyframe node reports; return True when it is time to auto-trigger."""
        self.announced = max(self.announced, int(msg.keyframes))
        self.coverage = float(msg.coverage)
        if self.auto_trigger > 0 and self.announced >= self.auto_trigger and not self._auto_started:
            self._auto_started = True
            return True
        return False

    def missing(self) -> int:
        """Keyframes announced by the keyframe node that have not arrived yet."""
        with self._held:
            return max(0, self.announced - len(self.store.records))

    def wait_for_keyframes(self, timeout_s: float) -> int:
        """Wait until every announced keyframe has arrived or ``timeout_s`` passed; return missing.

        A trigger can overtake the last keyframes on the network (they are large messages).
        """
        deadline = time.monotonic() + timeout_s
        with self._held:
            while len(self.store.records) < self.announced:
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self._held.wait(left)
            return max(0, self.announced - len(self.store.records))

    def run(self, settings: Settings, stamp_ns: int, emit: Emit) -> Outcome:
        """Reconstruct the keyframes held; everything published goes to ``emit`` as it happens.

        Args:
            settings: Parameters now (a node's may have changed since it started).
            stamp_ns: Stamp of the results (the trigger's).
            emit: Receives each group of publications.

        Returns:
            The reconstruction's outcome.

        """
        f, held = self.f, self.held

        def on_stage(stage: str, index: int, seconds: float | None) -> None:
            if seconds is None:
                progress = index / len(RECON_STAGES)
                emit([status(f, stamp_ns, 'RECONSTRUCTING', stage, held, f'running {stage}',
                             progress=progress)])  # fmt: skip

        cloud = self.uses_cloud(settings)
        outcome = (
            self._run_cloud(settings, on_stage) if cloud else run_reconstruction(settings, on_stage)
        )
        emit(reconstruction_diagnostics(f, stamp_ns, outcome))
        if not outcome.ok:
            emit([status(f, stamp_ns, 'FAILED', outcome.stage, held, outcome.reason,
                         outcome.advice)])  # fmt: skip
            return outcome
        frame_id = settings.frame_id
        max_faces = int(settings.values['display_max_faces'])
        emit(reconstruction_outputs(f, stamp_ns, self.work.root, frame_id, max_faces))
        if cloud and outcome.mesh is not None:
            emit(self._stockpile_frame(stamp_ns, outcome.mesh))
        surface = surface_message(f, self.work.mesh, stamp_ns, frame_id, held.keyframes,
                                  held.coverage)  # fmt: skip
        # The status first: the segmentation's own statuses follow the surface.
        emit([status(f, stamp_ns, 'SEGMENTING', 'segment', held, 'mesh ready; segmenting')])
        emit([(topics.SURFACE, surface)])
        return outcome
