"""``stockpile replay``: bags through the node set's components, photos and video alike."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..components import result_lines
from ..recon.sources import source_kind
from ..replay import ReplaySummary, replay
from .parameters import add_parameter_arguments, add_run_arguments, settings_from_args

__all__ = ['DESCRIPTION', 'add_arguments', 'run']

DESCRIPTION = """Measure the rocks of SOURCE: a ROS 2 bag, a folder of photos (JPEG, PNG, HEIC)
or a video file.

A bag is replayed through the same components the nodes run: frames in
bag order through the keyframe selector, the reconstruction at every recorded trigger
(std_msgs/Empty on stockpile/trigger) or once at the end, then segmentation and measurement.

Writes OUT/work/ (keyframes, sparse, dense, mesh), OUT/result/ (report.json, rocks.csv, ...)
and OUT/replay.mcap, a bag with every topic the nodes publish plus the input camera, camera
info and transforms, for Foxglove (dashboards/foxglove_layout.json) or RViz.

Photos and video have no ROS stream: every sharp photo (the keyframe selector for a video) becomes
a keyframe in OUT/work/, then the same reconstruction and segmentation write OUT/result/; no
output bag is written. Photos are matched as an unordered set, with the focal length of their EXIF
as the camera's starting point. Without a target (--set recon.target=aruco:DICT_4X4_50:0:0.15,
docs/field_capture.md) the sizes are in model units, not metres.

Parameters are those of the nodes (config/stockpile.yaml); --set overrides one, e.g.
--set sfm.max_features=2048 --set gradation.spec_class=III. The exit status is 0 when a result
was produced, 1 when the capture could not be reconstructed or segmented (the reason is printed
and written as diagnostics into the output bag)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add this subcommand's arguments."""
    parser.add_argument(
        'source', type=Path, help='ROS 2 bag (folder, .mcap or .db3), folder of photos or video'
    )
    parser.add_argument('--out', type=Path, required=True, help='output folder')
    parser.add_argument(
        '--topic', help='image topic of a bag (default: the one with most messages)'
    )
    add_parameter_arguments(parser)
    add_run_arguments(parser, 'OUT')


def _print_summary(s: ReplaySummary) -> None:
    for line in s.problems:
        print(f'stockpile replay: {line}', file=sys.stderr)
    calib = 'CameraInfo' if s.camera_info else 'self-calibrated (no usable CameraInfo)'
    if s.image_topic:
        print(f'{s.bag}: {s.frames} frames of {s.image_topic} ({s.skipped} skipped), '
              f'{s.keyframes} keyframes, coverage {s.coverage:.2f}, '
              f'intrinsics {calib}')  # fmt: skip
    cloud = s.recon.mesh.cloud if s.recon and s.recon.mesh else None
    if s.cloud_topic and cloud:
        stream = cloud.get('stream', {})
        print(f'{s.bag}: {stream.get("placed")} of {stream.get("messages")} point clouds of '
              f'{s.cloud_topic} placed in {stream.get("frame_id")}, {cloud["points_used"]} points '
              f'meshed (spacing {cloud["spacing"]:.3g} m)')  # fmt: skip
    sfm = s.recon.sparse if s.recon else None
    if sfm:
        print(f'registered {sfm.registered}/{s.keyframes} keyframes, '
              f'reprojection {sfm.mean_reprojection_error_px:.2f} px')  # fmt: skip
    if s.report is not None:
        scale = s.report.scale
        note = '' if scale.metric else ': every size is in model units, not metres'
        print(f'scale: {scale.summary()}{note}')
        for line in result_lines(s.report):
            print(line)
        print(f'result: {s.result_dir}')
    else:
        print('no result: the capture could not be reconstructed and segmented', file=sys.stderr)
    print(f'work folder: {s.work_dir}')
    print(f'output bag: {s.output_bag}')


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    settings = settings_from_args(args)
    if source_kind(args.source) != 'bag':
        from ..photos import replay_source, summary_lines

        photos = replay_source(args.source, args.out, settings, resume=args.resume,
                               fresh=args.fresh)  # fmt: skip
        out, err = summary_lines(photos)
        for line in err:
            print(line, file=sys.stderr)
        for line in out:
            print(line)
        return 0 if photos.ok else 1
    summary = replay(args.source, args.out, settings, args.topic,
                     resume=args.resume, fresh=args.fresh)  # fmt: skip
    _print_summary(summary)
    return 0 if summary.ok else 1
