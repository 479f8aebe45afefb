"""The reconstruction stages chained over the work folder of ``docs/formats.md``.

``keyframes/`` -> ``sparse/`` -> ``dense/`` -> ``mesh/``; every stage reads only what the previous
ones wrote, so any stage can be rerun alone, and the keyframe stage resumes after a restart.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated, Any

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
    StageResult,
    from_json,
    load,
    save,
    to_json,
)
from ..errors import CaptureError, StockpileError
from ..geometry import Similarity, umeyama
from ..meshio import LabelledMesh, write_labelled_mesh
from ..progress import progress
from ..ranges import Range
from ..ros.images import DEFAULT_MAX_PIXELS
from .collector import KeyframeCollector
from .dense import DenseOptions, run_dense
from .exif import read_intrinsics
from .gates import GateOptions, registration_gate
from .ground import fit_ground, pile_mask, stockpile_transform
from .keyframes import KeyframeStore, SelectorOptions
from .scale import (
    BarSpec,
    MarkerDetections,
    MarkerSpec,
    ScaleEstimate,
    Target,
    TargetSpec,
    combine,
    detect_charuco,
    detect_markers,
    off_path,
    pool_targets,
    scale_from_markers,
    scale_from_odometry,
    scale_from_target,
)
from .sfm import SfmOptions, SparseModel, load_sparse, run_sfm
from .sources import iter_frames, photo_files, source_kind
from .surface import PoissonOptions, poisson_surface

__all__ = [
    'STAGES',
    'ReconOptions',
    'WorkFolder',
    'estimate_scale',
    'odom_from_stockpile',
    'reconstruct',
    'run_dense_stage',
    'run_keyframes',
    'run_mesh_stage',
    'run_sfm_stage',
]

F64 = npt.NDArray[np.float64]

STAGES = ('keyframes', 'sfm', 'dense', 'mesh')


@dataclass(frozen=True)
class ReconOptions:
    """Everything the stages can be tuned with.

    Attributes:
        topic: Image topic of a bag (None: the one with most messages).
        selector: Keyframe selection.
        sfm: Structure-from-Motion.
        dense: Dense stereo.
        gate: The registration gate after Structure-from-Motion.
        poisson: Surface.
        target: The scale targets in view, '' for none (sizes in metres):
            aruco:DICT:ID:SIZE_M (one marker, the edge of its black square),
            aruco:DICT:*:SIZE_M (every marker of the dictionary), apriltag:36h11:ID:SIZE_M,
            bar:DICT:ID1:ID2:DIST_M (two markers whose centres are DIST_M apart) or
            charuco:SXxSY:SQUARE_M:MARKER_M[:DICT]; several joined by commas.
        use_odometry: Scale from the bag's odometry when it has some.
        odometry_scale_uncertainty: Relative standard deviation of the odometry's own scale
            (wheel radius, tyre pressure, slip; 1-2 % for wheel odometry), added in quadrature
            to the fit's: the fit against the SfM path cannot see it.
        target_size_uncertainty: Relative standard deviation of a printed marker's or bar's
            true size, added in quadrature to the spread of its detections (0.3 %: a 150 mm
            marker checked with a ruler to 0.5 mm).
        odometry_tolerance: Odometry is not used for the scale when the keyframe path, scaled
            onto it, differs from it by more than this share of its extent (rms). A keyframe
            further than this share from where odometry puts it, after the fit to the others, is
            left out of the dense and mesh stages (see ``on_path``).
        crop_radius: Points farther (horizontally) from the pile centre than this multiple of
            the pile's radius (95 % of what rises above a tenth of its height) are left out of the
            surface,
            and never farther than the farthest camera (0 keeps all): far ground seen at grazing
            angles only costs Poisson resolution.
        max_image_pixels: Largest image accepted, width x height, checked from the header
            before it is decoded (a bag's image or a photo that claims more is refused with the
            reason): bounds what one image can cost in memory, 3 bytes a pixel and a few copies.

    """

    topic: str | None = None
    selector: SelectorOptions = field(default_factory=SelectorOptions)
    sfm: SfmOptions = field(default_factory=SfmOptions)
    dense: DenseOptions = field(default_factory=DenseOptions)
    gate: GateOptions = field(default_factory=GateOptions)
    poisson: PoissonOptions = field(default_factory=PoissonOptions)
    target: tuple[Target, ...] = ()
    use_odometry: bool = True
    odometry_scale_uncertainty: Annotated[float, Range(0.0, 0.5)] = 0.02
    target_size_uncertainty: Annotated[float, Range(0.0, 0.2)] = 0.003
    crop_radius: Annotated[float, Range(0.0, 100.0)] = 1.5
    odometry_tolerance: Annotated[float, Range(0.0, 10.0)] = 0.05
    max_image_pixels: Annotated[int, Range(10_000, 1_000_000_000)] = DEFAULT_MAX_PIXELS


@dataclass(frozen=True)
class WorkFolder:
    """Paths of the work folder."""

    root: Path

    @property
    def capture(self) -> Path:
        """The keyframe node's own copy of what it selected (PNGs, ``keyframes.jsonl``)."""
        return self.root / 'capture'

    @property
    def keyframes(self) -> Path:
        """PNG keyframes and ``keyframes.jsonl``: what the reconstruction runs on."""
        return self.root / 'keyframes'

    @property
    def photos(self) -> Path:
        """``photos.json``: each photo of a photo folder, its keyframe and EXIF intrinsics."""
        return self.root / 'photos.json'

    @property
    def sparse(self) -> Path:
        """COLMAP model and ``sparse.json``."""
        return self.root / 'sparse'

    @property
    def dense(self) -> Path:
        """``dense.ply`` and ``dense.json``."""
        return self.root / 'dense'

    @property
    def mesh(self) -> Path:
        """``mesh.ply`` and ``mesh.json``."""
        return self.root / 'mesh'

    @property
    def surface(self) -> Path:
        """The segmentation's copy of the surface it received (``mesh.ply``, ``mesh.json``)."""
        return self.root / 'surface'


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
        # Photos were taken on purpose: keep every sharp one.
        selector_options = replace(selector_options, min_spacing=1, min_parallax=0.0)
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
    store: KeyframeStore, model: SparseModel, options: ReconOptions
) -> tuple[ScaleEstimate | None, dict[str, Any]]:
    """Scale from the boards and markers of ``options.target``, pooled, with what each gave."""
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
    for i, (board, hits) in enumerate(zip(boards, board_hits, strict=True)):
        estimate = scale_from_target(hits, poses, board)
        name = f'charuco {i}' if len(boards) > 1 else 'charuco'
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
    pooled = pool_targets(estimates)
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
        target, details['target'] = _target_scale(store, model, options)
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
                record.stamp_ns,
                [float(v) for v in position],
                [float(v) for v in quat],
                record.file,
            )
        )
    return out


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
        model_to_stockpile=SimilarityRecord(
            float(sim.scale),
            [float(v) for v in sim.rotation.ravel()],
            [float(v) for v in sim.translation],
        ),
        keyframes=_keyframe_poses(model, work, sim.scale, sim.rotation, sim.translation),
        keyframes_off_path=dropped,
        poisson=to_json(poisson),
    )
    save(info, work.mesh / 'mesh.json')
    return info


def reconstruct(
    source: Path | None,
    work_dir: Path,
    options: ReconOptions,
    stage: str = 'all',
    report: Callable[[str, StageResult, float], None] | None = None,
    keyframe_stage: Callable[[Path, WorkFolder, ReconOptions], KeyframeSummary] | None = None,
) -> dict[str, StageResult]:
    """Run one stage or all of them in order.

    Args:
        source: Bag, folder of photos or video (needed by the keyframe stage only).
        work_dir: The work folder.
        options: Tuning.
        stage: One of :data:`STAGES` or ``"all"``.
        report: Called after each stage with its name, result and duration [s].
        keyframe_stage: Runs the keyframe stage (:func:`run_keyframes` by default; the command
            line hands bags to the keyframe component, :mod:`stockpile_ros.bagdrive`).

    Returns:
        Each stage's result by name.

    """
    if stage != 'all' and stage not in STAGES:
        raise StockpileError(f'unknown stage {stage!r}; choose from {", ".join(STAGES)}, all')
    work = WorkFolder(work_dir)
    results: dict[str, StageResult] = {}
    for name in STAGES if stage == 'all' else (stage,):
        start = time.perf_counter()
        if name == 'keyframes':
            if source is None:
                raise StockpileError('the keyframes stage needs a SOURCE (bag, photos or video)')
            results[name] = (keyframe_stage or run_keyframes)(source, work, options)
        elif name == 'sfm':
            results[name] = run_sfm_stage(work, options)
        elif name == 'dense':
            results[name] = run_dense_stage(work, options)
        else:
            results[name] = run_mesh_stage(work, options)
        if report is not None:
            report(name, results[name], time.perf_counter() - start)
    return results
