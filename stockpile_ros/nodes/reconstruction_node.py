"""Reconstruction node: on a trigger, the sfm, dense and mesh stages run in a worker thread."""

from __future__ import annotations

from typing import Any

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from std_msgs.msg import Empty, String
from std_srvs.srv import Trigger
from stockpile_msgs.msg import PipelineStatus

from .. import topics
from ..publish import reconstruction_diagnostics, reconstruction_outputs, status
from ..recon.collector import CollectorState
from ..runner import RECON_STAGES, run_reconstruction
from .common import (
    LATCHED,
    Publishers,
    RclpyFactory,
    SingleRun,
    current_settings,
    declare_settings,
    now_ns,
    spin,
)

__all__ = ['ReconstructionNode', 'main']


class ReconstructionNode(Node):
    """Reconstruct the stored keyframes on request; one run at a time, the node stays responsive."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('stockpile_reconstruction', **kwargs)
        declare_settings(self, 'reconstruction')
        self.f = RclpyFactory()
        self.worker = SingleRun()
        self.keyframes = 0
        self.auto_started_at = 0
        self.pubs = Publishers(self, {
            topics.STATUS: 'stockpile_msgs/msg/PipelineStatus',
            topics.DIAGNOSTICS: 'diagnostic_msgs/msg/DiagnosticArray',
            topics.DENSE_CLOUD: 'sensor_msgs/msg/PointCloud2',
            topics.MESH: 'visualization_msgs/msg/MarkerArray',
            topics.MESH_READY: 'std_msgs/msg/String',
            topics.TF_STATIC: 'tf2_msgs/msg/TFMessage',
        })  # fmt: skip
        # The service answers while a run is in progress: its own group, never blocked by others.
        self.create_service(Trigger, topics.RECONSTRUCT_SERVICE, self.on_service,
                            callback_group=MutuallyExclusiveCallbackGroup())  # fmt: skip
        triggers = ReentrantCallbackGroup()
        self.create_subscription(Empty, topics.TRIGGER, self.on_trigger, 10,
                                 callback_group=triggers)  # fmt: skip
        self.create_subscription(PipelineStatus, topics.KEYFRAME_STATUS, self.on_keyframes,
                                 LATCHED, callback_group=triggers)  # fmt: skip

    def start(self, why: str) -> tuple[bool, str]:
        """Start a run in the worker thread unless one is running; return whether and why."""
        if not self.worker.start(self.run, now_ns(self)):
            return False, 'a reconstruction is already running; wait for it to finish'
        self.get_logger().info(f'reconstruction started ({why})')
        return True, f'reconstruction started ({why})'

    def on_service(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        """``std_srvs/Trigger``: start, or refuse with the reason."""
        response.success, response.message = self.start('service')
        return response

    def on_trigger(self, msg: Empty) -> None:
        """Trigger topic (recorded triggers replay)."""
        ok, message = self.start('trigger topic')
        if not ok:
            self.get_logger().warning(f'trigger refused: {message}')

    def on_keyframes(self, msg: PipelineStatus) -> None:
        """Track the keyframe count; start on our own after ``auto_trigger_keyframes``."""
        self.keyframes = int(msg.keyframes)
        threshold = int(self.get_parameter('auto_trigger_keyframes').value)
        if threshold > 0 and self.keyframes >= threshold and self.auto_started_at == 0:
            self.auto_started_at = self.keyframes
            self.start(f'{self.keyframes} keyframes')

    def run(self, stamp_ns: int) -> None:
        """Run the stages (worker thread); publish progress, failures and results."""
        settings = current_settings(self, 'reconstruction')
        f = self.f
        held = CollectorState(keyframes=self.keyframes)  # as last reported by the keyframe node

        def on_stage(stage: str, index: int, seconds: float | None) -> None:
            if seconds is None:
                self.pubs.publish(
                    [
                        status(
                            f,
                            now_ns(self),
                            'RECONSTRUCTING',
                            stage,
                            held,
                            f'running {stage}',
                            progress=index / len(RECON_STAGES),
                        )
                    ]
                )

        outcome = run_reconstruction(settings, on_stage)
        self.pubs.publish(reconstruction_diagnostics(f, stamp_ns, outcome))
        if not outcome.ok:
            self.get_logger().error(f'{outcome.stage}: {outcome.reason}. {outcome.advice}')
            self.pubs.publish(
                [status(f, stamp_ns, 'FAILED', outcome.stage, held, outcome.reason, outcome.advice)]
            )
            return
        self.pubs.publish(
            reconstruction_outputs(
                f,
                stamp_ns,
                settings.work_dir,
                settings.frame_id,
                int(settings.values['display_max_faces']),
            )
        )
        self.pubs.publish([(topics.MESH_READY, String(data=str(settings.work_dir)))])
        self.pubs.publish([status(f, stamp_ns, 'SEGMENTING', 'mesh', held, 'mesh ready')])


def main(args: list[str] | None = None) -> None:
    """Run the reconstruction node."""
    spin(ReconstructionNode, args=args)


if __name__ == '__main__':
    main()
