"""Score a result folder against the simulator's truth: alignment, detection, sizes, D50, scale.

The outcome is a JSON-ready dict (schema ``stockpile-evaluation/1``, described in
``docs/formats.md``). Relative errors are fractions (0.05 = 5 %) except in keys ending in ``_pct``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .align import Alignment, align_trajectories, rotation_angle
from .inputs import ResultSide, TruthSide, load_result, load_truth
from .match import OFF_SURFACE, MatchOptions, RockMatching, match_rocks, transfer_labels
from .metrics import RockErrors, relative_error, rock_errors, summarise

__all__ = ['SCHEMA', 'EvaluationOptions', 'evaluate', 'evaluate_sides', 'pile_extent']

SCHEMA = 'stockpile-evaluation/1'


@dataclass(frozen=True)
class EvaluationOptions:
    """Settings of an evaluation.

    Attributes:
        stamp_tolerance_ns: A keyframe pairs with the nearest true camera within this [ns].
        max_distance: Distance gate of the label transfer [m]; None for ``gate_fraction`` times the
            pile extent.
        gate_fraction: Gate as a share of the pile extent, when ``max_distance`` is None.
        match: Thresholds of the rock matching.
        min_b: The smallest rock of interest of the detection figures ``of_interest`` [true
            m]; None for the one the run segmented for (its report's
            ``segmentation.scale.min_rock_b``, times the length factor). True rocks under it
            are left aside there as the barely visible ones are, and a result rock made of
            several of them is a false rock (a cluster).

    """

    stamp_tolerance_ns: int = 5_000_000
    max_distance: float | None = None
    gate_fraction: float = 0.02
    match: MatchOptions = field(default_factory=MatchOptions)
    min_b: float | None = None


def pile_extent(truth: TruthSide) -> float:
    """Diagonal of the axis-aligned box around the true rocks' meshes [m] (whole scene if none)."""
    scene = truth.scene
    faces = scene.faces[scene.labels > 0]
    if len(faces) == 0:
        faces = scene.faces
    if len(faces) == 0:
        return 0.0
    points = scene.vertices[np.unique(faces)]
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def _stat(values: npt.NDArray[np.float64], how: str) -> float | None:
    if len(values) == 0:
        return None
    if how == 'rmse':
        return float(np.sqrt(np.mean(values**2)))
    return float(np.median(values) if how == 'median' else np.max(values))


def _ratio(num: float | None, den: float) -> float | None:
    return None if num is None or den <= 0 else num / den


def _alignment_dict(alignment: Alignment, extent: float) -> dict[str, Any]:
    ce = alignment.centre_errors
    rmse, median = _stat(ce, 'rmse'), _stat(ce, 'median')
    oe = np.degrees(alignment.orientation_errors)
    return {
        'method': alignment.method,
        'note': alignment.note,
        'keyframes': alignment.keyframes,
        'matched_keyframes': alignment.matched,
        'scale': alignment.scale,
        'rotation': alignment.rotation.reshape(-1).tolist(),
        'rotation_deg': math.degrees(rotation_angle(alignment.rotation)),
        'translation': alignment.translation.tolist(),
        'pile_extent_m': extent,
        'centre_rmse_m': rmse,
        'centre_median_m': median,
        'centre_max_m': _stat(ce, 'max'),
        'centre_rmse_rel_extent': _ratio(rmse, extent),
        'centre_median_rel_extent': _ratio(median, extent),
        'orientation_median_deg': _stat(oe, 'median'),
        'orientation_max_deg': _stat(oe, 'max'),
    }


def _scale_dict(result: ResultSide, alignment: Alignment) -> dict[str, Any]:
    # Result length per true length; 1.05 = the result is 5 % too large.
    ratio = 1.0 / alignment.scale
    judged = result.metric and alignment.method != 'identity'
    if result.metric:
        note = 'the result claims metric units: its sizes are compared as reported'
    else:
        note = 'the result is unscaled: its sizes are multiplied by the alignment scale'
    if alignment.method == 'identity':
        note += '; no alignment, so the scale was not measured'
    return {
        'method': result.scale_method,
        'metric': result.metric,
        'result_per_true_length': ratio,
        'error': ratio - 1.0 if judged else None,
        'abs_error': abs(ratio - 1.0) if judged else None,
        'sizes_rescaled': not result.metric,
        'note': note,
    }


def _detection_dict(
    truth: TruthSide,
    result: ResultSide,
    matching: RockMatching,
    options: EvaluationOptions,
    min_b: float,
) -> dict[str, Any]:
    threshold, share = options.match.visible_threshold, options.match.major_share

    def visible(tid: int) -> bool:
        vf = truth.rocks[tid].visible_fraction
        return vf is None or vf >= threshold

    def fine(tid: int) -> bool:
        b = truth.rocks[tid].b
        return b is not None and b < min_b

    detected = {p[1] for p in matching.pairs}
    visible_ids = [t for t in truth.rocks if visible(t)]
    seen = matching.detection(visible_ids, [], share)
    fines = [t for t in truth.rocks if fine(t)]
    of_interest = [t for t in visible_ids if not fine(t)]
    asked = matching.detection(of_interest, fines, share)
    n_true, n_result = len(truth.rocks), len(result.rocks)
    return {
        'true_rocks': n_true,
        'true_rocks_visible': len(visible_ids),
        'visible_threshold': threshold,
        'result_rocks': n_result,
        'detected': len(detected),
        'detected_visible': len(seen.found),
        'precision': _ratio(len(detected), n_result),
        'recall': _ratio(len(detected), n_true),
        'precision_visible': seen.precision,
        'recall_visible': seen.recall,
        'of_interest': {
            'min_b_m': min_b,
            'source': 'report' if options.min_b is None else 'option',
            'true_rocks': asked.true_rocks,
            'true_rocks_under': len(fines),
            'result_rocks': asked.result_rocks,
            'detected': len(asked.found),
            'recall': asked.recall,
            'precision': asked.precision,
            'missed': sorted(set(of_interest) - {t for _, t in asked.found}),
            'clusters': sorted(asked.clusters),
        },
        'missed': sorted(t for t in visible_ids if t not in detected),
        'missed_hidden': sorted(t for t in truth.rocks if t not in detected and not visible(t)),
        'false': [{'id': r, 'lies_on': why} for r, why in sorted(matching.false_reasons.items())],
        'merges': [{'result_id': r, 'true_ids': t} for r, t in sorted(matching.merges.items())],
        'splits': [{'true_id': t, 'result_ids': r} for t, r in sorted(matching.splits.items())],
        'matches': [
            {'result_id': r, 'true_id': t, 'iou': iou}
            for r, t, iou in sorted(matching.pairs, key=lambda p: p[1])
        ],
    }


def _surface_dict(
    result: ResultSide,
    gate: float,
    true_labels: npt.NDArray[np.int64],
    areas: npt.NDArray[np.float64],
) -> dict[str, Any]:
    total_area = float(areas.sum())
    off_area = float(areas[true_labels == OFF_SURFACE].sum())
    listed = np.isin(result.mesh.labels, list(result.rocks))
    return {
        'max_distance_m': gate,
        'off_surface_area_share': _ratio(off_area, total_area),
        'faces_with_unlisted_ids': int(np.count_nonzero((result.mesh.labels > 0) & ~listed)),
    }


def _rock_dict(e: RockErrors) -> dict[str, Any]:
    return {
        'true_id': e.true_id,
        'result_id': e.result_id,
        'iou': e.iou,
        'visible_fraction': e.visible_fraction,
        'centroid_error_m': e.centroid_error,
        'true': e.true,
        'estimated': e.estimated,
        'relative_error': e.relative,
        'absolute_error': e.absolute,
    }


def evaluate_sides(
    result: ResultSide, truth: TruthSide, options: EvaluationOptions | None = None
) -> dict[str, Any]:
    """Evaluate a loaded result against a loaded truth; see :func:`evaluate`."""
    opts = options or EvaluationOptions()
    alignment = align_trajectories(
        result.keyframes, truth.cameras, result.frame_id, truth.frame_id, opts.stamp_tolerance_ns
    )
    extent = pile_extent(truth)
    gate = opts.max_distance if opts.max_distance is not None else opts.gate_fraction * extent
    mesh = result.mesh
    transfer = transfer_labels(alignment.apply(mesh.vertices), mesh.faces, truth.scene, gate)
    matching = match_rocks(
        mesh.labels[transfer.face], transfer, sorted(result.rocks), sorted(truth.rocks), opts.match
    )
    length_factor = 1.0 if result.metric else alignment.scale
    min_b = result.min_rock_b * length_factor if opts.min_b is None else opts.min_b
    errors = rock_errors(matching.pairs, result.rocks, truth.rocks, alignment, length_factor)
    summary = summarise(errors)
    threshold = opts.match.visible_threshold
    summary_visible = summarise(
        [e for e in errors if e.visible_fraction is None or e.visible_fraction >= threshold]
    )
    d50_result = None if result.d50 is None else result.d50 * length_factor
    d50_rel = relative_error(d50_result, truth.d50)
    d50_abs = None if d50_result is None or truth.d50 is None else d50_result - truth.d50
    return {
        'schema': SCHEMA,
        'result': str(result.path),
        'truth': str(truth.path),
        'options': asdict(opts),
        'alignment': _alignment_dict(alignment, extent),
        'scale': _scale_dict(result, alignment),
        'detection': _detection_dict(truth, result, matching, opts, min_b)
        | _surface_dict(result, gate, transfer.true_labels, transfer.areas),
        'sizes': {
            'length_factor': length_factor,
            'summary': summary,
            'summary_visible': summary_visible,
            'volume_mape_pct': summary['volume']['mean_abs_pct'],
            'rocks': [_rock_dict(e) for e in errors],
        },
        'gradation': {
            'd50_true_m': truth.d50,
            'd50_result_m': d50_result,
            'd50_error': d50_rel,
            'd50_abs_error_m': d50_abs,
        },
    }


def evaluate(
    result_path: str | Path, truth_path: str | Path, options: EvaluationOptions | None = None
) -> dict[str, Any]:
    """Score the result folder at ``result_path`` against the truth folder at ``truth_path``.

    1. The reported keyframes are paired with the true cameras by stamp and a similarity transform
       of their centres takes the result into the truth frame.
    2. Each result face takes the label of the nearest true surface (within a distance gate); the
       face areas give an overlap matrix and a one-to-one assignment on surface IoU, from which
       detected, missed and false rocks, merges and splits follow.
    3. Matched rocks are compared on a, b, c and volume, in truth metres: a result claiming metric
       units as reported, an unscaled one multiplied by the alignment scale. D50 likewise.

    Raises:
        EvaluationError: A folder cannot be read, or the result cannot be aligned to the truth.

    """
    return evaluate_sides(load_result(result_path), load_truth(truth_path), options)
