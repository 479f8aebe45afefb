"""``stockpile reconstruct``: keyframes, SfM, dense cloud and metric Poisson mesh of a capture."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from ..recon.dense import DenseOptions
from ..recon.keyframes import SelectorOptions
from ..recon.pipeline import STAGES, ReconOptions, reconstruct
from ..recon.scale import TargetSpec
from ..recon.sfm import SfmOptions
from ..recon.surface import PoissonOptions

__all__ = ['DESCRIPTION', 'add_arguments', 'run']

DESCRIPTION = """\
Reconstruct the pile from SOURCE (a ROS 2 bag, a folder of photos or a video file) into the
work folder DIR: keyframes/ (kept as they are selected), sparse/ (COLMAP model, sparse.json),
dense/dense.ply and mesh/mesh.ply + mesh/mesh.json (metric when a target or odometry gives the
scale, z up, ground at z = 0). Each stage reads what the previous one wrote, so a stage can be
rerun alone with --stage (SOURCE is needed only by the keyframes stage).

examples:
  stockpile reconstruct run.mcap --work out/ --target charuco:5x4:0.1:0.075:DICT_4X4_50
  stockpile reconstruct photos/ --work out/ --matcher exhaustive
  stockpile reconstruct --work out/ --stage mesh --poisson-depth 10
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``stockpile reconstruct``."""
    parser.add_argument('source', nargs='?', type=Path, help='bag, folder of photos or video')
    parser.add_argument('--work', required=True, type=Path, metavar='DIR', help='work folder')
    parser.add_argument('--stage', choices=(*STAGES, 'all'), default='all', help='stage to run')
    parser.add_argument('--topic', help='image topic of a bag (default: the busiest)')
    parser.add_argument(
        '--target',
        metavar='SPEC',
        help='ChArUco board in view, charuco:SXxSY:SQUARE_M:MARKER_M[:DICT], '
        'e.g. charuco:5x4:0.1:0.075:DICT_4X4_50',
    )
    parser.add_argument(
        '--no-odometry', action='store_true', help='do not take the scale from odometry'
    )
    k = parser.add_argument_group('keyframes')
    ks = SelectorOptions()
    k.add_argument('--max-keyframes', type=int, default=ks.max_keyframes)
    k.add_argument(
        '--min-parallax',
        type=float,
        default=ks.min_parallax,
        help='displacement (share of the width) that makes a keyframe',
    )
    k.add_argument(
        '--blur-ratio',
        type=float,
        default=ks.blur_ratio,
        help='sharpness below this share of the recent median is blurred',
    )
    s = parser.add_argument_group('structure from motion')
    ss = SfmOptions()
    s.add_argument('--matcher', choices=('sequential', 'exhaustive'), default=ss.matcher)
    s.add_argument('--overlap', type=int, default=ss.overlap, help='sequential window')
    s.add_argument('--vocab-tree', default='', help='vocabulary tree for loop detection')
    s.add_argument('--mapper', choices=('incremental', 'global'), default=ss.mapper)
    s.add_argument('--max-image-size', type=int, default=ss.max_image_size)
    s.add_argument('--max-features', type=int, default=ss.max_features)
    s.add_argument('--threads', type=int, default=ss.num_threads)
    s.add_argument('--self-calibrate', action='store_true', help='ignore CameraInfo intrinsics')
    d = parser.add_argument_group('dense and surface')
    dd, pp = DenseOptions(), PoissonOptions()
    d.add_argument('--dense-width', type=int, default=dd.work_width, help='stereo width [px]')
    d.add_argument(
        '--dense-partners',
        type=int,
        default=dd.partners,
        help='depth maps per keyframe, each with its own partner view (1: faster)',
    )
    d.add_argument('--poisson-depth', type=int, default=pp.depth)
    d.add_argument('--trim-quantile', type=float, default=pp.density_quantile)
    d.add_argument('--target-faces', type=int, default=pp.target_faces, help='0: no simplifying')


def _options(args: argparse.Namespace) -> ReconOptions:
    return ReconOptions(
        topic=args.topic,
        selector=SelectorOptions(
            max_keyframes=args.max_keyframes,
            min_parallax=args.min_parallax,
            blur_ratio=args.blur_ratio,
        ),
        sfm=SfmOptions(
            max_image_size=args.max_image_size,
            max_features=args.max_features,
            matcher=args.matcher,
            overlap=args.overlap,
            vocab_tree=args.vocab_tree,
            mapper=args.mapper,
            num_threads=args.threads,
            use_camera_info=not args.self_calibrate,
        ),
        dense=DenseOptions(work_width=args.dense_width, partners=args.dense_partners),
        poisson=PoissonOptions(
            depth=args.poisson_depth,
            density_quantile=args.trim_quantile,
            target_faces=args.target_faces,
        ),
        target=TargetSpec.parse(args.target) if args.target else None,
        use_odometry=not args.no_odometry,
    )


def _summary(name: str, result: dict[str, Any], seconds: float) -> None:
    shown = {k: v for k, v in result.items() if k not in ('keyframes', 'unregistered')}
    print(f'{name}: {seconds:.1f} s {json.dumps(shown, default=str)}', flush=True)


def run(args: argparse.Namespace) -> int:
    """Run the requested stages; returns 0 on success."""
    reconstruct(args.source, args.work, _options(args), args.stage, report=_summary)
    return 0
