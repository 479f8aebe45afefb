"""``stockpile evaluate``: score a segmentation result against the simulator's ground truth."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..tools.evaluation import EvaluationOptions, MatchOptions, evaluate, format_table

__all__ = ['DESCRIPTION', 'add_arguments', 'run']

DESCRIPTION = """\
Score a segmentation result (RESULT_DIR with report.json + segments.ply) against the truth
written by `stockpile simulate` (TRUTH: the <BAG>_truth folder with truth.json + scene.ply).

1. The reported keyframes are paired with the true cameras by stamp and a similarity transform of
   their centres (Umeyama, with scale) takes the result into the truth frame. With fewer than 3
   pairs the two are compared unaligned, which needs both to claim the same frame.
2. Each result face takes the label of the nearest true surface within a distance gate; face
   areas give the surface IoU of every result/true rock pair; a one-to-one assignment with
   IoU >= --min-iou decides detected, missed (visible fraction >= --visible) and false rocks, and
   merges and splits are counted. The same figures are given again over the rocks of interest:
   the visible true rocks at least as large (b) as the smallest rock the run segmented for
   (report.json's segmentation.scale.min_rock_b) or --min-b; smaller true rocks are left aside as
   barely visible ones are, and a result rock made of several of them is a false rock (a
   cluster).
3. Matched rocks are compared on a, b, c and volume in truth metres (a result that claims metric
   units as reported; an unscaled one multiplied by the alignment scale), with D50 and the scale.

The table goes to stdout; --json FILE writes the full figures (schema stockpile-evaluation/1).
Nothing is written into RESULT_DIR.
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the arguments of ``stockpile evaluate``."""
    defaults, match = EvaluationOptions(), MatchOptions()
    parser.add_argument('result', metavar='RESULT_DIR', help='result folder (or its report.json)')
    parser.add_argument('truth', metavar='TRUTH', help='truth folder (or its truth.json)')
    parser.add_argument('--json', metavar='FILE', type=Path, help='write the figures as JSON')
    parser.add_argument(
        '--stamp-tolerance-ms',
        type=float,
        metavar='MS',
        default=defaults.stamp_tolerance_ns / 1e6,
        help='pair a keyframe with the nearest true camera within this (default %(default)g ms)',
    )
    parser.add_argument(
        '--max-distance',
        type=float,
        metavar='M',
        help='distance gate of the label transfer in metres '
        f'(default {defaults.gate_fraction:g} x the pile extent)',
    )
    parser.add_argument(
        '--min-iou',
        type=float,
        metavar='IOU',
        default=match.min_iou,
        help='surface IoU a match needs (default %(default)g)',
    )
    parser.add_argument(
        '--visible',
        type=float,
        metavar='FRACTION',
        default=match.visible_threshold,
        help='true rocks seen less than this fraction are not counted as missed '
        '(default %(default)g)',
    )
    parser.add_argument(
        '--min-b',
        type=float,
        metavar='M',
        help='smallest rock of interest in truth metres (default: the one the run segmented for; '
        '0 counts every visible rock)',
    )


def run(args: argparse.Namespace) -> int:
    """Evaluate, print the table, write the JSON if asked; returns 0."""
    options = EvaluationOptions(
        stamp_tolerance_ns=round(args.stamp_tolerance_ms * 1e6),
        max_distance=args.max_distance,
        match=MatchOptions(min_iou=args.min_iou, visible_threshold=args.visible),
        min_b=args.min_b,
    )
    evaluation = evaluate(args.result, args.truth, options)
    print(format_table(evaluation))
    if args.json is not None:
        args.json.write_text(json.dumps(evaluation, indent=1, allow_nan=False) + '\n')
        print(f'figures written to {args.json}')
    return 0
