"""``stockpile reconstruct``: keyframes, SfM, dense cloud and metric Poisson mesh of a capture."""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

from ..artefacts import StageResult, to_json
from ..bagdrive import collect_keyframes
from ..recon.pipeline import STAGES, reconstruct
from ..runs import claim
from ..settings import write_effective
from .parameters import Alias, add_parameter_arguments, add_run_arguments, settings_from_args

__all__ = ['DESCRIPTION', 'add_arguments', 'run']

DESCRIPTION = """\
Reconstruct the pile from SOURCE (a ROS 2 bag, a folder of photos or a video file) into the
work folder DIR: keyframes/ (kept as they are selected), sparse/ (COLMAP model, sparse.json),
dense/dense.ply and mesh/mesh.ply + mesh/mesh.json (metric when a target or odometry gives the
scale, z up, ground at z = 0). Each stage reads what the previous one wrote, so a stage can be
rerun alone with --stage (SOURCE is needed only by the keyframes stage).

Parameters are those of the nodes (config/stockpile.yaml): --params FILE reads a parameters file,
--set NAME=VALUE sets one (e.g. --set poisson.depth=10 --set dense.work_width=960). Every value is
checked before a stage runs, and the values used are written to DIR/params.yaml.

examples:
  stockpile reconstruct run.mcap --work out/ --target charuco:5x4:0.1:0.075:DICT_4X4_50
  stockpile reconstruct photos/ --work out/ --matcher exhaustive
  stockpile reconstruct --work out/ --stage mesh --set poisson.depth=10
"""

# The convenience flags: each sets one table key, and only when it is given.
_ALIASES = (
    Alias('--work', 'work_dir', 'work folder', metavar='DIR', required=True),
    Alias('--target', 'recon.target', 'ChArUco board in view, '
          'charuco:SXxSY:SQUARE_M:MARKER_M[:DICT], e.g. charuco:5x4:0.1:0.075:DICT_4X4_50',
          metavar='SPEC'),
    Alias('--matcher', 'sfm.matcher', 'feature matching: sequential (video) or exhaustive '
          '(photos, small sets)'),
    Alias('--no-odometry', 'recon.use_odometry', 'do not take the scale from odometry',
          const=False),
)  # fmt: skip


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``stockpile reconstruct``."""
    parser.add_argument('source', nargs='?', type=Path, help='bag, folder of photos or video')
    parser.add_argument('--stage', choices=(*STAGES, 'all'), default='all', help='stage to run')
    parser.add_argument('--topic', help='image topic of a bag (default: the busiest)')
    add_parameter_arguments(parser, _ALIASES)
    add_run_arguments(parser, 'the work folder')


def _summary(name: str, result: StageResult, seconds: float) -> None:
    shown = {k: v for k, v in to_json(result).items() if k not in ('keyframes', 'unregistered')}
    print(f'{name}: {seconds:.1f} s {json.dumps(shown, default=str)}', flush=True)


def run(args: argparse.Namespace) -> int:
    """Run the requested stages; returns 0 on success."""
    settings = settings_from_args(args)
    # A later stage alone reruns the work folder's run (other parameters are the point of it).
    source = args.source if args.stage in ('all', 'keyframes') else None
    with claim(settings.work_dir, source, settings.values, resume=args.resume, fresh=args.fresh):
        # Written before the stages run, so that a failed run also says what it was asked to do.
        write_effective(settings, settings.work_dir)
        options = replace(settings.recon, topic=args.topic)
        reconstruct(args.source, settings.work_dir, options, args.stage, report=_summary,
                    keyframe_stage=collect_keyframes(settings))  # fmt: skip
    return 0
