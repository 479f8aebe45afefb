"""Segmentation node: when a mesh is ready, rocks, measures and gradation are published."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from rclpy.node import Node
from std_msgs.msg import String

from .. import topics
from ..publish import capture_warnings, diagnostics, segmentation_outputs, status
from ..runner import run_segmentation
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

__all__ = ['SegmentationNode', 'main']


class SegmentationNode(Node):
    """Segment each mesh announced on ``mesh_ready`` (in a worker) and publish the results."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('stockpile_segmentation', **kwargs)
        declare_settings(self, 'segmentation')
        self.f = RclpyFactory()
        self.worker = SingleRun()
        self.pubs = Publishers(self, {
            topics.STATUS: 'stockpile_msgs/msg/PipelineStatus',
            topics.DIAGNOSTICS: 'diagnostic_msgs/msg/DiagnosticArray',
            topics.SEGMENTED_CLOUD: 'sensor_msgs/msg/PointCloud2',
            topics.ROCK_MARKERS: 'visualization_msgs/msg/MarkerArray',
            topics.ROCKS: 'stockpile_msgs/msg/RockArray',
            topics.GRADATION: 'stockpile_msgs/msg/Gradation',
        })  # fmt: skip
        self.create_subscription(String, topics.MESH_READY, self.on_mesh_ready, LATCHED)

    def on_mesh_ready(self, msg: String) -> None:
        """Start segmenting the work folder named in the message, unless a run is going on."""
        if not self.worker.start(self.run, Path(msg.data), now_ns(self)):
            self.get_logger().warning('mesh ready while segmenting: refused, finish first')

    def run(self, work_dir: Path, stamp_ns: int) -> None:
        """Segment, measure and publish (worker thread)."""
        settings = dataclasses.replace(current_settings(self, 'segmentation'), work_dir=work_dir)
        f = self.f
        outcome = run_segmentation(settings)
        if not outcome.ok or outcome.analysis is None:
            self.get_logger().error(f'segment: {outcome.reason}. {outcome.advice}')
            self.pubs.publish([
                diagnostics(f, stamp_ns, 'segment', 'ERROR', outcome.reason,
                            {'advice': outcome.advice}),
                status(f, stamp_ns, 'FAILED', 'segment', None, outcome.reason, outcome.advice),
            ])  # fmt: skip
            return
        report = outcome.analysis.report
        self.pubs.publish(
            segmentation_outputs(
                f,
                stamp_ns,
                outcome.analysis,
                settings.frame_id,
                int(settings.values['display_max_faces']),
            )
        )
        rocks = len(report['rocks'])
        if report['warnings']:
            self.get_logger().warning(' '.join(report['warnings']))
        self.pubs.publish(capture_warnings(f, stamp_ns, report))
        self.pubs.publish([
            diagnostics(f, stamp_ns, 'segment', 'OK', f'{rocks} rocks',
                        {'rocks': rocks, 'd50': report['gradation'].get('d50')}),
            status(f, stamp_ns, 'DONE', 'segment', None,
                   f'{rocks} rocks; result in {work_dir / "result"}'),
        ])  # fmt: skip


def main(args: list[str] | None = None) -> None:
    """Run the segmentation node."""
    spin(SegmentationNode, args=args)


if __name__ == '__main__':
    main()
