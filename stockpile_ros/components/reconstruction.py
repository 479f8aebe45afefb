"""The reconstruction component: keyframes in; on a trigger sfm, dense, mesh; the surface out.

Keyframes arrive as ``Keyframe`` messages and are written into this component's own work folder,
so it needs nothing from the keyframe node's disk. A run publishes, in this order: one
``RECONSTRUCTING`` status per stage, the stages' diagnostics, then either a ``FAILED`` status or
the dense cloud, the mesh markers, the stockpile frame on ``/tf_static``, a ``SEGMENTING``
status and the ``SurfaceMesh`` for the segmentation.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from ..artefacts import WorkFolder
from ..recon.collector import CollectorState
from ..recon.keyframes import KeyframeStore
from ..ros import topics
from ..ros.convert import CameraInfoError
from ..ros.images import ImageError
from ..ros.messages import MessageFactory
from ..ros.publications import (
    Publication,
    diagnostics,
    reconstruction_diagnostics,
    reconstruction_outputs,
    status,
)
from ..runner import RECON_STAGES, Outcome, run_reconstruction
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

        outcome = run_reconstruction(settings, on_stage)
        emit(reconstruction_diagnostics(f, stamp_ns, outcome))
        if not outcome.ok:
            emit([status(f, stamp_ns, 'FAILED', outcome.stage, held, outcome.reason,
                         outcome.advice)])  # fmt: skip
            return outcome
        frame_id = settings.frame_id
        max_faces = int(settings.values['display_max_faces'])
        emit(reconstruction_outputs(f, stamp_ns, self.work.root, frame_id, max_faces))
        surface = surface_message(f, self.work.mesh, stamp_ns, frame_id, held.keyframes,
                                  held.coverage)  # fmt: skip
        # The status first: the segmentation's own statuses follow the surface.
        emit([status(f, stamp_ns, 'SEGMENTING', 'segment', held, 'mesh ready; segmenting')])
        emit([(topics.SURFACE, surface)])
        return outcome
