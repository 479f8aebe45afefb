"""Reconstruction node: keyframes in; on a trigger sfm, dense and mesh run in a worker thread."""

from __future__ import annotations

from typing import Any

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from std_srvs.srv import Trigger

from ..components import ReconstructionComponent
from ..ros import topics
from ..ros.publications import diagnostics
from .common import (
    Publishers,
    RclpyFactory,
    SingleRun,
    current_settings,
    declare_settings,
    now_ns,
    spin,
    subscribe,
)

__all__ = ['KEYFRAME_WAIT_S', 'ReconstructionNode', 'main']

KEYFRAME_WAIT_S = 10.0
"""How long a run waits for keyframes announced but still on the network (a slow Wi-Fi link)."""


class ReconstructionNode(Node):
    """Reconstruct the keyframes received, on request; one run at a time, callbacks stay free."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('stockpile_reconstruction', **kwargs)
        declare_settings(self, 'reconstruction')
        self.f = RclpyFactory()
        self.component = ReconstructionComponent(current_settings(self, 'reconstruction'), self.f)
        self.worker = SingleRun()
        self.pubs = Publishers(self, 'reconstruction')
        # The service answers while a run is in progress: its own group, never blocked by others.
        self.create_service(Trigger, topics.RECONSTRUCT_SERVICE, self.on_service,
                            callback_group=MutuallyExclusiveCallbackGroup())  # fmt: skip
        subscribe(self, topics.TRIGGER, self.on_trigger, MutuallyExclusiveCallbackGroup())
        subscribe(self, topics.KEYFRAMES, self.on_keyframe)
        subscribe(self, topics.KEYFRAME_STATUS, self.on_keyframe_status)

    def start(self, why: str) -> tuple[bool, str]:
        """Start a run in the worker thread unless one is running; return whether and why."""
        if not self.worker.start(self.run, now_ns(self)):
            return False, 'a reconstruction is already running; wait for it to finish'
        # Through Node: mypy lets untyped calls into rclpy's own names only.
        Node.get_logger(self).info(f'reconstruction started ({why})')
        return True, f'reconstruction started ({why})'

    def on_service(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        """``std_srvs/Trigger``: start, or refuse with the reason."""
        response.success, response.message = self.start('service')
        return response

    def on_trigger(self, msg: Any) -> None:
        """Trigger topic (recorded triggers replay)."""
        ok, message = self.start('trigger topic')
        if not ok:
            Node.get_logger(self).warning(f'trigger refused: {message}')

    def on_keyframe(self, msg: Any) -> None:
        """Store the keyframe in this node's work folder."""
        self.pubs.publish(self.component.on_keyframe(msg, now_ns(self)))

    def on_keyframe_status(self, msg: Any) -> None:
        """Track the keyframes announced; start on our own after ``auto_trigger_keyframes``."""
        if self.component.on_keyframe_status(msg):
            self.start(f'{msg.keyframes} keyframes')

    def run(self, stamp_ns: int) -> None:
        """Run the stages (worker thread); publish progress, failures and results as they come."""
        missing = self.component.wait_for_keyframes(KEYFRAME_WAIT_S)
        if missing:
            text = f'{missing} announced keyframes did not arrive within {KEYFRAME_WAIT_S:.0f} s'
            self.pubs.publish([diagnostics(self.f, stamp_ns, 'keyframes', 'WARN', text)])
        settings = current_settings(self, 'reconstruction')
        self.component.run(settings, stamp_ns, self.pubs.publish)

    def close(self) -> None:
        """Wait for a run in progress (shutdown)."""
        self.worker.join()


def main(args: list[str] | None = None) -> None:
    """Run the reconstruction node."""
    spin(ReconstructionNode, args=args)


if __name__ == '__main__':
    main()
