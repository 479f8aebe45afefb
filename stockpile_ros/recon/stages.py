"""The reconstruction stages, each from the work folder's previous output to its own.

``keyframes/`` -> ``sparse/`` -> ``dense/`` -> ``mesh/`` (``docs/formats.md``); each takes and
returns the records of :mod:`stockpile_ros.artefacts`.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import open3d as o3d
from scipy.spatial.transform import Rotation

from ..artefacts import (
    DenseSummary,
    KeyframePose,
    KeyframeSummary,
    MeshInfo,
    ScaleRecord,
    SimilarityRecord,
    SparseSummary,
    WorkFolder,
    from_json,
    load,
    save,
    to_json,
)
from ..errors import CaptureError, StockpileError
from ..meshio import LabelledMesh, write_labelled_mesh
from ..progress import progress
from .calibration import planar_views
from .collector import KeyframeCollector
from .dense import run_dense
from .exif import read_intrinsics
from .gates import registration_gate
from .ground import fit_ground, pile_mask, stockpile_transform
from .keyframes import KeyframeStore
from .options import ReconOptions
from .scale import MarkerSpec, detect_markers
from .scaling import estimate_scale, on_path
from .sfm import SparseModel, load_sparse, model_figures, pin_focal, run_sfm
from .sources import iter_frames, photo_files, source_kind
from .surface import poisson_surface

__all__ = [
    'PHOTO_BLUR_SHARE',
    'photo_names',
    'run_dense_stage',
    'run_keyframes',
    'run_mesh_stage',
    'run_sfm_stage',
]


#: Share of ``selector.blur_ratio`` that a photo's sharpness is tested against (see run_keyframes).
PHOTO_BLUR_SHARE = 0.5


def run_keyframes(source: Path, work: WorkFolder, options: ReconOptions) -> KeyframeSummary:
    """Select keyframes from photos or a video into ``work.keyframes``, resuming from what is there.

    Bags go through the keyframe component instead, as the nodes take them
    (:func:`stockpile_ros.bagdrive.keyframes_from_bag`).

    Returns:
        Counts: frames seen, keyframes kept (in total and by this run), rejections by reason.

    Raises:
        StockpileError: ``source`` is a bag.
        CaptureError: No keyframe was kept.

    """
    kind = source_kind(source)
    if kind == 'bag':
        raise StockpileError(f'{source}: a bag; its keyframes come from stockpile_ros.bagdrive')
    selector_options = options.selector
    if kind == 'photos':
        # Photos were taken on purpose: keep every sharp one. Unlike a video's frames, the photos
        # before one show other views, whose sharpness differs by content: on the simulated walks
        # of tests/test_photos.py from 0.61 to 1.42 of their median (0.62-1.39 of the photos'
        # before each), while a Gaussian blur of 1.5 px took every one under 0.15 (1 px: 0.35,
        # 2 px: 0.07). The blur test's share is halved for them.
        selector_options = replace(
            selector_options,
            min_spacing=1,
            min_parallax=0.0,
            blur_ratio=PHOTO_BLUR_SHARE * selector_options.blur_ratio,
        )
    collector = KeyframeCollector(work.keyframes, selector_options)
    store = collector.store
    before = len(store.records)
    seen = 0
    frames = iter_frames(source, options.topic, max_pixels=options.max_image_pixels)
    for frame in progress(frames, 'keyframes', unit='frame'):
        seen += 1
        if frame.index <= store.last_index:
            continue
        collector.push(frame)
    reasons = collector.state.decisions
    if not store.records:
        raise CaptureError(
            'keyframes',
            f'no keyframe was kept out of {seen} frames (rejections: {reasons})',
            'Check that the source holds sharp images of the pile',
        )
    if kind == 'photos':
        _write_photos(source, work, store)
    return KeyframeSummary(seen, len(store.records), len(store.records) - before, dict(reasons))


def _write_photos(source: Path, work: WorkFolder, store: KeyframeStore) -> None:
    """Write ``photos.json``: every photo, the keyframe it became (None when rejected), its EXIF."""
    keyframe_of = {r.index: r.file for r in store.records}
    photos = []
    for index, path in enumerate(photo_files(source)):
        photos.append({**read_intrinsics(path).as_dict(), 'keyframe': keyframe_of.get(index)})
    info = {'schema': 'stockpile-photos/1', 'source': str(source), 'photos': photos}
    work.photos.write_text(json.dumps(info, indent=1) + '\n')


def photo_names(work: WorkFolder) -> dict[str, str]:
    """Photo file name by keyframe name (empty when the keyframes are not from photos)."""
    if not work.photos.exists():
        return {}
    photos = json.loads(work.photos.read_text())['photos']
    return {p['keyframe']: p['file'] for p in photos if p['keyframe']}


def _pin_focal_to_targets(
    work: WorkFolder, store: KeyframeStore, options: ReconOptions, registered: set[str]
) -> list[dict[str, Any]]:
    """Measure a self-calibrated focal length on the targets' views and hold the model to it.

    Only the ``registered`` keyframes (the model kept) are read. See :mod:`.calibration` and
    :func:`.sfm.pin_focal`.
    """
    dictionaries = [t.dictionary for t in options.target if isinstance(t, MarkerSpec)]
    planes = {}
    for record in store.records:
        if record.file in registered:
            image = store.image(record)
            markers = detect_markers(image, dictionaries) if dictionaries else {}
            planes[record.file] = planar_views(image, markers, options.target)
    return pin_focal(work.sparse, planes)


def run_sfm_stage(work: WorkFolder, options: ReconOptions) -> SparseSummary:
    """Structure-from-Motion of the stored keyframes into ``work.sparse``, then the gate.

    Keyframes from photos (``photos.json``) are an unordered set, with their EXIF focal lengths
    as the prior. The registration gate's report is added to ``sparse.json`` (``gate``) whether
    it passes or not, so that the dense stage, run on its own later, refuses a model that failed
    it.

    Raises:
        CaptureError: Structure-from-Motion failed, or its model failed the registration gate
            (:func:`.gates.registration_gate`; the pile centre is the median of the sparse
            points).

    """
    store = KeyframeStore(work.keyframes)
    noun = 'keyframes'
    if not work.photos.exists():
        report = run_sfm(work.keyframes, store.records, work.sparse, options.sfm)
    else:
        noun = 'photos'
        photos = json.loads(work.photos.read_text())['photos']
        priors = {
            p['keyframe']: float(p['focal_px']) for p in photos if p['keyframe'] and p['focal_px']
        }
        report = run_sfm(work.keyframes, store.records, work.sparse, options.sfm,
                         priors=priors, unordered=True)  # fmt: skip
        names = photo_names(work)
        for entry in report.model_images:
            entry.photos = [names.get(n, n) for n in entry.images]
        report.unregistered_photos = [names.get(n, n) for n in report.unregistered]
    if options.target and not report.camera.startswith('fixed'):
        registered = set(report.model_images[0].images) if report.model_images else set()
        report.target_focal = _pin_focal_to_targets(work, store, options, registered)
        used = [entry for entry in report.target_focal if entry['used']]
        if used:
            views = sum(entry['views'] for entry in used)
            report.camera += f'; focal length from the targets ({views} views), held'
            # The model was adjusted again with them: its cameras, not the self-calibrated ones.
            report.cameras, report.mean_reprojection_error_px = model_figures(work.sparse)
    model = load_sparse(work.sparse)
    gate = registration_gate(
        [r.file for r in store.records],
        [entry.images for entry in report.model_images],
        options.gate,
        centres={name: view.center for name, view in model.views.items()},
        pile_centre=np.median(model.points, axis=0) if len(model.points) else None,
        noun=noun,
    )
    report.gate = gate.as_dict()
    save(report, work.sparse / 'sparse.json')
    gate.check('sfm')
    return report


def run_dense_stage(work: WorkFolder, options: ReconOptions) -> DenseSummary:
    """Dense cloud of the registered keyframes into ``work.dense``.

    Raises:
        StockpileError: No sparse model.
        CaptureError: The sparse model failed the registration gate.

    """
    sparse_json = work.sparse / 'sparse.json'
    if not sparse_json.exists():
        raise StockpileError(f'{work.sparse}: no sparse model; run the sfm stage first')
    gate = load(SparseSummary, sparse_json).gate
    if gate and not gate['passed']:
        raise CaptureError('sfm', gate['reason'], gate['advice'])
    store = KeyframeStore(work.keyframes)
    model, dropped = on_path(work, load_sparse(work.sparse), options)
    order = [r.file for r in store.records]
    summary = run_dense(work.keyframes, work.sparse, model, order, work.dense, options.dense)
    summary.off_path = dropped
    save(summary, work.dense / 'dense.json')
    return summary


def _keyframe_poses(
    model: SparseModel,
    work: WorkFolder,
    sim_scale: float,
    sim_rot: npt.NDArray[np.float64],
    sim_t: npt.NDArray[np.float64],
) -> list[KeyframePose]:
    out = []
    for record in KeyframeStore(work.keyframes).records:
        view = model.views.get(record.file)
        if view is None:
            continue
        position = sim_scale * sim_rot @ view.center + sim_t
        quat = Rotation.from_matrix(sim_rot @ view.rotation.T).as_quat()
        out.append(
            KeyframePose(
                record.stamp_ns, [float(v) for v in position], [float(v) for v in quat], record.file
            )
        )
    return out


def run_mesh_stage(work: WorkFolder, options: ReconOptions) -> MeshInfo:
    """Scale, ground alignment and Poisson surface into ``work.mesh``; returns ``mesh.json``."""
    dense_path = work.dense / 'dense.ply'
    if not dense_path.exists():
        raise StockpileError(f'{dense_path}: missing; run the dense stage first')
    model, dropped = on_path(work, load_sparse(work.sparse), options)
    cloud = o3d.io.read_point_cloud(dense_path)
    points = np.asarray(cloud.points)
    scale, scale_details = estimate_scale(work, model, options)
    views = list(model.views.values())
    centres = np.array([v.center for v in views])
    ups = np.array([-v.rotation[1] for v in views])
    ground = fit_ground(points, centres, ups)
    sim = stockpile_transform(ground, points, centres, scale.metres_per_unit)
    normals = np.asarray(cloud.normals) @ sim.rotation.T
    colors = np.asarray(cloud.colors) if cloud.has_colors() else None
    local = sim.apply(points)
    keep = np.ones(len(local), dtype=bool)
    radius = None
    if options.crop_radius > 0:
        horizontal = np.linalg.norm(local[:, :2], axis=1)
        radius = float(np.max(np.linalg.norm(sim.apply(centres)[:, :2], axis=1)))
        above = pile_mask(local[:, 2])
        if np.count_nonzero(above) > 100:
            radius = min(radius, options.crop_radius * float(np.percentile(horizontal[above], 95)))
        keep = horizontal <= radius
    mesh, poisson = poisson_surface(
        local[keep], normals[keep], None if colors is None else colors[keep], options.poisson
    )
    poisson['crop_radius'] = radius
    poisson['points'] = int(keep.sum())
    work.mesh.mkdir(parents=True, exist_ok=True)
    vcol = np.asarray(mesh.vertex_colors)
    write_labelled_mesh(
        work.mesh / 'mesh.ply',
        LabelledMesh(
            vertices=np.asarray(mesh.vertices, dtype=np.float64),
            faces=np.asarray(mesh.triangles, dtype=np.int64),
            labels=np.zeros(len(mesh.triangles), dtype=np.int32),
            colors=np.clip(np.round(vcol * 255), 0, 255).astype(np.uint8) if len(vcol) else None,
        ),
    )
    info = MeshInfo(
        scale=from_json(ScaleRecord, to_json(scale.__dict__), 'scale'),
        units='m' if scale.method != 'none' else 'model',
        scale_details=to_json({**scale_details, 'note': scale.note}),
        ground_plane_model=[float(v) for v in ground.plane],
        ground_inliers=len(ground.inliers),
        model_to_stockpile=SimilarityRecord.of(sim),
        keyframes=_keyframe_poses(model, work, sim.scale, sim.rotation, sim.translation),
        keyframes_off_path=dropped,
        poisson=to_json(poisson),
    )
    save(info, work.mesh / 'mesh.json')
    return info
