"""``stockpile replay``: a recorded bag through the node set's components, into an output MCAP."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..replay import ReplaySummary, replay
from .parameters import add_parameter_arguments, add_run_arguments, settings_from_args

__all__ = ['DESCRIPTION', 'add_arguments', 'run']

DESCRIPTION = """Replay a recorded ROS 2 bag through the same components the nodes run: frames in
bag order through the keyframe selector, the reconstruction at every recorded trigger
(std_msgs/Empty on stockpile/trigger) or once at the end, then segmentation and measurement.

Writes OUT/work/ (keyframes, sparse, dense, mesh), OUT/result/ (report.json, rocks.csv, ...)
and OUT/replay.mcap, a bag with every topic the nodes publish plus the input camera, camera
info and transforms, for Foxglove (dashboards/foxglove_layout.json) or RViz.

Parameters are those of the nodes (config/stockpile.yaml); --set overrides one, e.g.
--set sfm.max_features=2048 --set gradation.spec_class=III. The exit status is 0 when a result
was produced, 1 when the capture could not be reconstructed or segmented (the reason is printed
and written as diagnostics into the output bag)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add this subcommand's arguments."""
    parser.add_argument('bag', type=Path, help='ROS 2 bag (folder, .mcap or .db3)')
    parser.add_argument('--out', type=Path, required=True, help='output folder')
    parser.add_argument('--topic', help='image topic (default: the one with most messages)')
    add_parameter_arguments(parser)
    add_run_arguments(parser, 'OUT')


def _print_summary(s: ReplaySummary) -> None:
    for line in s.problems:
        print(f'stockpile replay: {line}', file=sys.stderr)
    calib = 'CameraInfo' if s.camera_info else 'self-calibrated (no usable CameraInfo)'
    print(f'{s.bag}: {s.frames} frames of {s.image_topic} ({s.skipped} skipped), '
          f'{s.keyframes} keyframes, coverage {s.coverage:.2f}, intrinsics {calib}')  # fmt: skip
    sfm = s.recon.results.get('sfm') if s.recon else None
    if sfm:
        error = sfm.get('mean_reprojection_error_px', float('nan'))
        print(f'registered {sfm.get("registered")}/{s.keyframes} keyframes, '
              f'reprojection {error:.2f} px')  # fmt: skip
    if s.report is not None:
        scale = s.report['scale']
        rel = scale.get('rel_uncertainty')
        unc = '' if rel is None else f' +/- {100 * rel:.1f} %'
        print(f'scale: {scale.get("method")}{unc}')
        g = s.report['gradation']
        d50 = 'undefined' if g.get('d50') is None else f'{g["d50"]:.3f} m'
        print(f'{len(s.report["rocks"])} rocks, D50 {d50}')
        spec = g.get('spec') or {}
        if spec.get('checked'):
            reasons = '; '.join(spec.get('reasons', []))
            verdict = 'PASS' if spec.get('passed') else f'FAIL: {reasons}'
            print(f'class {spec.get("class")}: {verdict}')
        print(f'result: {s.result_dir}')
    else:
        print('no result: the capture could not be reconstructed and segmented', file=sys.stderr)
    print(f'work folder: {s.work_dir}')
    print(f'output bag: {s.output_bag}')


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    summary = replay(args.bag, args.out, settings_from_args(args), args.topic,
                     resume=args.resume, fresh=args.fresh)  # fmt: skip
    _print_summary(summary)
    return 0 if summary.ok else 1
