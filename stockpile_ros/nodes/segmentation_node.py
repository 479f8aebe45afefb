"""Segmentation node: each surface received is cut into rocks, measured and published (worker)."""

from __future__ import annotations

from typing import Any

from rclpy.node import Node

from ..components import SegmentationComponent
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

__all__ = ['SegmentationNode', 'main']


class SegmentationNode(Node):
    """Segment each ``SurfaceMesh`` in a worker and publish rocks, markers and gradation."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('stockpile_segmentation', **kwargs)
        declare_settings(self, 'segmentation')
        self.f = RclpyFactory()
        self.component = SegmentationComponent(current_settings(self, 'segmentation'), self.f)
        self.worker = SingleRun()
        self.pubs = Publishers(self, 'segmentation')
        subscribe(self, topics.SURFACE, self.on_surface)

    def on_surface(self, msg: Any) -> None:
        """Take the surface and segment it, unless a segmentation is still running."""
        stamp = now_ns(self)
        if self.worker.busy:
            text = 'a surface arrived while segmenting the previous one: refused, finish first'
            self.pubs.publish([diagnostics(self.f, stamp, 'segment', 'WARN', text)])
            return
        failed = self.component.on_surface(msg, stamp)
        if failed:
            self.pubs.publish(failed)
            return
        self.worker.start(self.run, stamp)

    def run(self, stamp_ns: int) -> None:
        """Segment, measure and publish (worker thread)."""
        settings = current_settings(self, 'segmentation')
        self.component.run(settings, stamp_ns, self.pubs.publish)

    def close(self) -> None:
        """Wait for a run in progress (shutdown)."""
        self.worker.join()


def main(args: list[str] | None = None) -> None:
    """Run the segmentation node."""
    spin(SegmentationNode, args=args)


if __name__ == '__main__':
    main()
