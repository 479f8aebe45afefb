"""The scale policy: printed targets and odometry, each with its uncertainty, pooled.

Also which keyframes lie off the odometry path (left out of the dense and mesh stages) and where
the stockpile frame lies in the odometry frame.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np
import numpy.typing as npt

from ..artefacts import MeshInfo, SparseSummary, WorkFolder, load
from ..camera import CameraModel
from ..geometry import Similarity, umeyama
from .keyframes import KeyframeStore
from .options import ReconOptions
from .scale import (
    BarSpec,
    MarkerDetections,
    MarkerSpec,
    ScaleEstimate,
    TargetSpec,
    combine,
    detect_charuco,
    detect_markers,
    marker_scale,
    off_path,
    pool_targets,
    replicate_spread,
    scale_from_markers,
    scale_from_odometry,
    scale_from_target,
)
from .sfm import SparseModel, resampled_poses

__all__ = ['estimate_scale', 'odom_from_stockpile', 'on_path']


F64 = npt.NDArray[np.float64]


def _odometry_pairs(
    store: KeyframeStore, model: SparseModel
) -> tuple[list[str], npt.NDArray[np.int64], F64, F64]:
    """Return registered keyframes with odometry by stamp: names, stamps, centres, positions."""
    # Only keyframes whose camera the transforms placed: the base is not where the camera is.
    rows = sorted(
        (r.stamp_ns, r.file, r.odometry)
        for r in store.records
        if r.odometry and r.odometry.camera_position is not None and r.file in model.views
    )
    names = [name for _, name, _ in rows]
    stamps = np.array([stamp for stamp, _, _ in rows], dtype=np.int64)
    centres = np.array([model.views[name].center for name in names]).reshape(-1, 3)
    positions = np.array([odo.camera_position for _, _, odo in rows], dtype=np.float64).reshape(
        -1, 3
    )
    return names, stamps, centres, positions


def _path_extent(positions: F64) -> float:
    return float(np.linalg.norm(positions.max(axis=0) - positions.min(axis=0)))


def on_path(
    work: WorkFolder, model: SparseModel, options: ReconOptions
) -> tuple[SparseModel, list[str]]:
    """Return the model without its keyframes that lie off the odometry path, and their names.

    See :func:`.scale.off_path`; a keyframe within ``odometry_tolerance`` of the path's extent of
    where odometry puts it is always kept. The dense and mesh stages both start from this model,
    so a misregistered view neither adds a ghost surface nor bends the scale.
    """
    if not options.use_odometry:
        return model, []
    names, _, centres, positions = _odometry_pairs(KeyframeStore(work.keyframes), model)
    if len(names) < 4:
        return model, []
    off = off_path(centres, positions, options.odometry_tolerance * _path_extent(positions))
    dropped = [name for name, o in zip(names, off, strict=True) if o]
    views = {n: v for n, v in model.views.items() if n not in dropped}
    return (replace(model, views=views) if dropped else model), dropped


def _target_scale(
    work: WorkFolder, model: SparseModel, options: ReconOptions, sparse: SparseSummary | None
) -> tuple[ScaleEstimate | None, dict[str, Any]]:
    """Scale from the boards and markers of ``options.target``, pooled, with what each gave.

    What the model adds to the targets' own uncertainty, the part ``model``, is the spread of
    the pooled scale over copies of the model bundle-adjusted again on random halves of its
    points (:func:`.sfm.resampled_poses`, :func:`.scale.replicate_spread`): a target's scale is
    carried to the whole model through poses and depths that rest on the focal length, and a
    self-calibrated focal length is the largest part of it. Where no copies can be made the
    focal length's covariance (:func:`.sfm.focal_uncertainty`) stands in as the part ``focal``.
    """
    store = KeyframeStore(work.keyframes)
    boards = [t for t in options.target if isinstance(t, TargetSpec)]
    markers = [t for t in options.target if isinstance(t, (MarkerSpec, BarSpec))]
    dictionaries = [t.dictionary for t in markers]
    board_hits: list[dict[str, tuple[npt.NDArray[np.int64], F64]]] = [{} for _ in boards]
    marker_hits: dict[str, MarkerDetections] = {}
    for record in store.records:
        if record.file not in model.views:
            continue
        image = store.image(record)
        for board, hits in zip(boards, board_hits, strict=True):
            ids, px = detect_charuco(image, board)
            if len(ids):
                hits[record.file] = (ids, px)
        if markers:
            found = detect_markers(image, dictionaries)
            if found:
                marker_hits[record.file] = found
    poses = {n: (v.camera, v.rotation, v.translation) for n, v in model.views.items()}
    estimates: dict[str, ScaleEstimate] = {}
    details: dict[str, Any] = {}
    names = {}
    for i, (board, hits) in enumerate(zip(boards, board_hits, strict=True)):
        estimate = scale_from_target(hits, poses, board)
        name = f'charuco {i}' if len(boards) > 1 else 'charuco'
        names[name] = i
        details[name] = {'views_with_corners': len(hits),
                         'estimate': None if estimate is None else estimate.__dict__}  # fmt: skip
        if estimate is not None:
            estimates[name] = estimate
    if markers:
        estimate = scale_from_markers(marker_hits, poses, markers,
                                      size_uncertainty=options.target_size_uncertainty)  # fmt: skip
        seen = sorted({f'{d}:{m}' for hits in marker_hits.values() for d, m in hits})
        details['markers'] = {
            'specs': [t.text() for t in markers],
            'views_with_markers': len(marker_hits),
            'markers_seen': seen,
            'estimate': None if estimate is None else estimate.__dict__,
        }
        if estimate is not None:
            estimates['markers'] = estimate

    def pooled_scale(replicate: Mapping[str, tuple[CameraModel, F64, F64]]) -> float | None:
        """Pool the targets' scales with other poses, each weighed as in the model."""
        again = {}
        for name, estimate in estimates.items():
            if name == 'markers':
                value = marker_scale(marker_hits, replicate, markers)
            else:
                board = scale_from_target(board_hits[names[name]], replicate, boards[names[name]])
                value = None if board is None else board.metres_per_unit
            if value is None:
                return None
            again[name] = replace(estimate, metres_per_unit=value)
        pooled = pool_targets(again)
        return None if pooled is None else pooled.metres_per_unit

    pooled = pool_targets(estimates)
    if pooled is not None and pooled.rel_uncertainty is not None:
        fixed = sparse is not None and sparse.camera.startswith('fixed')
        # A focal length the targets measured is held in the copies as in the model, and its
        # own uncertainty is a part of its own (a focal length off by a share moves the scale
        # by about as much).
        pinned = [
            e['rel_uncertainty'] for e in (sparse.target_focal if sparse else []) if e['used']
        ]
        replicates = resampled_poses(work.sparse, refine_intrinsics=not (fixed or pinned))
        spread = replicate_spread(poses, replicates, pooled_scale)
        focal = max(pinned) if pinned else (sparse.focal_rel_uncertainty if sparse else None)
        parts = {'model': spread} if spread is not None else {}
        if focal is not None and (pinned or spread is None):
            parts['focal'] = focal
        if parts:
            extra = math.hypot(*parts.values())
            pooled = replace(pooled, rel_uncertainty=math.hypot(pooled.rel_uncertainty, extra),
                             parts={**pooled.parts, **parts})  # fmt: skip
        details['model_replicates'] = len(replicates)
    details['views'] = len(model.views)
    return pooled, details


def estimate_scale(
    work: WorkFolder, model: SparseModel, options: ReconOptions
) -> tuple[ScaleEstimate, dict[str, Any]]:
    """Scale of the model from the target and/or odometry, with what each gave."""
    store = KeyframeStore(work.keyframes)
    details: dict[str, Any] = {}
    target = None
    if options.target:
        path = work.sparse / 'sparse.json'
        sparse = load(SparseSummary, path) if path.exists() else None
        target, details['target'] = _target_scale(work, model, options, sparse)
    odometry = None
    if options.use_odometry:
        names, stamps, centres, positions = _odometry_pairs(store, model)
        odometry_only = [r.odometry for r in store.records if r.odometry is not None]
        unplaced = sum(1 for odo in odometry_only if odo.camera_position is None)
        if unplaced:
            # Odometry without a /tf link from its base to the camera: no camera centre is known.
            details['odometry'] = {'keyframes_without_camera_pose': unplaced}
        if names:
            odometry = scale_from_odometry(
                dict(zip(stamps.tolist(), centres, strict=True)), stamps, positions,
                calibration=options.odometry_scale_uncertainty,
            )  # fmt: skip
            details['odometry'] = {
                'keyframes': len(names),
                'keyframes_without_camera_pose': unplaced,
                'estimate': None if odometry is None else odometry.__dict__,
            }
            extent = _path_extent(positions)
            if odometry is not None and odometry.rms_residual > options.odometry_tolerance * extent:
                # The SfM path does not have the odometry's shape: one of them is wrong
                # (misregistered keyframes, say, on repeating texture); its scale would be too.
                details['odometry']['rejected'] = (
                    f'SfM camera path differs from odometry by {odometry.rms_residual:.3f} m rms '
                    f'over a {extent:.2f} m path'
                )
                odometry = None
    return combine(target, odometry), details


def odom_from_stockpile(work: WorkFolder) -> tuple[str, Similarity] | None:
    """Where the ``stockpile`` frame lies in the odometry frame, from the keyframes seen in both.

    Fits the keyframes' optical centres in the stockpile frame (``mesh.json``) onto their odometry
    camera positions (``keyframes.jsonl``). The fit is rigid (scale 1) when the mesh is metric.

    Returns:
        The odometry frame's name and the similarity, or None without odometry on at least three
        registered keyframes.

    """
    info = load(MeshInfo, work.mesh / 'mesh.json')
    in_stockpile = {k.file: k.position for k in info.keyframes if k.file}
    src, dst, frame = [], [], ''
    for record in KeyframeStore(work.keyframes).records:
        odo = record.odometry
        if odo is None or odo.camera_position is None or record.file not in in_stockpile:
            continue
        src.append(in_stockpile[record.file])
        dst.append(odo.camera_position)
        frame = odo.frame_id
    if len(src) < 3:
        return None
    sim = umeyama(np.asarray(src, dtype=np.float64), np.asarray(dst, dtype=np.float64))
    if info.scale.metric:
        centre_s, centre_d = np.mean(src, axis=0), np.mean(dst, axis=0)
        sim = Similarity(1.0, sim.rotation, centre_d - sim.rotation @ centre_s)
    return frame, sim
