"""Structure-from-Motion of the keyframes with pycolmap: features, matching, mapping, a report.

Intrinsics from CameraInfo, when the keyframes that carry one all carry the same one, are given to
COLMAP as a fixed camera (PINHOLE, OPENCV, FULL_OPENCV or OPENCV_FISHEYE); otherwise one shared
SIMPLE_RADIAL camera is self-calibrated. Photos get one SIMPLE_RADIAL camera per image size
(portrait and landscape shots of one phone), started from their EXIF focal length where they have
one and refined by bundle adjustment, and are matched as an unordered set. COLMAP puts the centre
of the top-left pixel at (0.5, 0.5), ROS and OpenCV at (0, 0): principal points are shifted by
half a pixel on the way in and out.
"""

from __future__ import annotations

import math
import shutil
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import numpy.typing as npt
import pycolmap
from PIL import Image

from ..artefacts import KeyframeRecord, ModelImages, SparseSummary, save
from ..camera import CameraModel
from ..errors import CaptureError
from ..ranges import Range
from .calibration import PlanarView, target_focal

__all__ = [
    'SfmOptions',
    'SparseModel',
    'View',
    'focal_uncertainty',
    'load_sparse',
    'model_figures',
    'pin_focal',
    'resampled_poses',
    'run_sfm',
]


@dataclass(frozen=True)
class SfmOptions:
    """Tuning of :func:`run_sfm`.

    Attributes:
        max_image_size: Longest side [px] images are downscaled to for feature extraction
            (keypoints are scaled back to full resolution by COLMAP).
        max_features: SIFT features per image.
        matcher: ``"sequential"`` (each keyframe against the next ``overlap`` ones),
            ``"exhaustive"`` (every pair) or ``"auto"``: sequential for a bag or a video; for
            photos (an unordered set) exhaustive up to ``exhaustive_max`` of them, else
            vocabulary-tree retrieval when ``vocab_tree`` is given, else sequential in name
            order (phones number photos as they are taken), with a note in sparse.json.
        overlap: Sequential matching window.
        vocab_tree: Path of a COLMAP vocabulary tree (nothing is downloaded); when given,
            sequential matching also detects loops with it, and large photo sets are matched by
            retrieval.
        exhaustive_max: Largest photo set ``"auto"`` matches exhaustively (every pair: the
            cost grows as the square of the number).
        mapper: ``"incremental"`` or ``"global"`` (GLOMAP).
        num_threads: Threads for feature extraction and the global mapper. Matching and the
            incremental mapper run on one, so that a rerun gives the same model.
        min_features: Below this mean number of features per keyframe the capture is textureless.
        use_camera_info: Use CameraInfo intrinsics when present (fixed camera).
        min_triangulation_angle: Below this median (over points) of the widest angle between
            the rays that see a point [deg], the motion is degenerate (a rotation on the spot).
        log_level: COLMAP's log threshold (0 info, 1 warnings, 2 errors).

    """

    max_image_size: Annotated[int, Range(64, 16384)] = 1024
    max_features: Annotated[int, Range(64, 65536)] = 4096
    matcher: Literal['auto', 'sequential', 'exhaustive'] = 'auto'
    overlap: Annotated[int, Range(1, 1000)] = 8
    vocab_tree: str = ''
    exhaustive_max: Annotated[int, Range(2, 100000)] = 50
    mapper: Literal['incremental', 'global'] = 'incremental'
    num_threads: Annotated[int, Range(-1, 256)] = 2
    min_features: Annotated[int, Range(0, 65536)] = 150
    use_camera_info: bool = True
    min_triangulation_angle: Annotated[float, Range(0.0, 90.0)] = 8.0
    log_level: Annotated[int, Range(0, 3)] = 1


@dataclass
class View:
    """One registered keyframe.

    Attributes:
        name: Image file name (as in ``keyframes/``).
        camera: Intrinsics in the OpenCV convention (principal point of pixel centres at 0).
        rotation: 3x3 world-to-camera rotation.
        translation: World-to-camera translation.
        point_ids: Ids of the 3D points it observes.

    """

    name: str
    camera: CameraModel
    rotation: npt.NDArray[np.float64]
    translation: npt.NDArray[np.float64]
    point_ids: npt.NDArray[np.int64]

    @property
    def center(self) -> npt.NDArray[np.float64]:
        """Optical centre in model coordinates."""
        return np.asarray(-self.rotation.T @ self.translation, dtype=np.float64)


@dataclass
class SparseModel:
    """The registered views and sparse points of a COLMAP model, as numpy arrays.

    Attributes:
        views: Registered views by image name.
        point_ids: Ids of the 3D points (row order of ``points``).
        points: Nx3 positions in model coordinates.
        colors: Nx3 uint8 colours.

    """

    views: dict[str, View]
    point_ids: npt.NDArray[np.int64]
    points: npt.NDArray[np.float64]
    colors: npt.NDArray[np.uint8]


_OPENCV_MODELS = {
    # COLMAP model -> (parameter layout); parameters after the intrinsics are OpenCV's order.
    'SIMPLE_PINHOLE': ('f', 'cx', 'cy'),
    'PINHOLE': ('fx', 'fy', 'cx', 'cy'),
    'SIMPLE_RADIAL': ('f', 'cx', 'cy', 'k1'),
    'RADIAL': ('f', 'cx', 'cy', 'k1', 'k2'),
    'OPENCV': ('fx', 'fy', 'cx', 'cy', 'k1', 'k2', 'p1', 'p2'),
    'FULL_OPENCV': ('fx', 'fy', 'cx', 'cy', 'k1', 'k2', 'p1', 'p2', 'k3', 'k4', 'k5', 'k6'),
    'OPENCV_FISHEYE': ('fx', 'fy', 'cx', 'cy', 'k1', 'k2', 'k3', 'k4'),
}


def _colmap_camera(camera: CameraModel) -> tuple[str, list[float]]:
    """COLMAP model name and parameters for a CameraInfo model."""
    fx, fy, cx, cy = camera.fx, camera.fy, camera.cx + 0.5, camera.cy + 0.5
    d = [float(v) for v in np.asarray(camera.d).ravel()]
    if camera.distortion_model == 'equidistant' and any(d):
        return 'OPENCV_FISHEYE', [fx, fy, cx, cy, *(d + [0.0] * 4)[:4]]
    if not any(d):
        return 'PINHOLE', [fx, fy, cx, cy]
    if len(d) <= 4 or (len(d) == 5 and d[4] == 0.0):
        return 'OPENCV', [fx, fy, cx, cy, *(d + [0.0] * 4)[:4]]
    d8 = (d + [0.0] * 8)[:8]
    return 'FULL_OPENCV', [fx, fy, cx, cy, *d8[:4], d8[4], d8[5], d8[6], d8[7]]


def _opencv_camera(camera: pycolmap.Camera) -> CameraModel:
    """OpenCV-convention camera model of a COLMAP camera."""
    name = str(camera.model_name)
    if name not in _OPENCV_MODELS:
        raise ValueError(f'COLMAP camera model {name} is not supported')
    values = dict(zip(_OPENCV_MODELS[name], (float(v) for v in camera.params), strict=True))
    fx = values.get('fx', values.get('f', 0.0))
    fy = values.get('fy', values.get('f', 0.0))
    k = np.array(
        [[fx, 0.0, values['cx'] - 0.5], [0.0, fy, values['cy'] - 0.5], [0.0, 0.0, 1.0]],
    )
    if name == 'OPENCV_FISHEYE':
        d = [values[key] for key in ('k1', 'k2', 'k3', 'k4')]
        return CameraModel(int(camera.width), int(camera.height), k, np.array(d), 'equidistant')
    keys = ('k1', 'k2', 'p1', 'p2', 'k3', 'k4', 'k5', 'k6')
    d = [values.get(key, 0.0) for key in keys]
    while d and d[-1] == 0.0 and len(d) > 5:
        d.pop()
    model = 'rational_polynomial' if len(d) == 8 else 'plumb_bob'
    if not any(d):
        d = []
    return CameraModel(int(camera.width), int(camera.height), k, np.array(d), model)


def _shared_camera(records: list[KeyframeRecord]) -> CameraModel | None:
    """Return the CameraInfo model the keyframes share, None when none has one or they differ.

    Keyframes without one are taken to come from the same camera: a stream's first images often
    arrive before its first CameraInfo.
    """
    cameras = [r.camera for r in records if r.camera is not None]
    if not cameras:
        return None
    first = cameras[0]
    for cam in cameras[1:]:
        if (
            (cam.width, cam.height) != (first.width, first.height)
            or not np.allclose(cam.k, first.k)
            or not np.array_equal(np.asarray(cam.d), np.asarray(first.d))
        ):
            return None
    return first


def _feature_counts(database: Path) -> list[int]:
    """Count the keypoints of every image in a COLMAP database."""
    db = pycolmap.Database.open(str(database))
    try:
        return [int(db.num_keypoints_for_image(img.image_id)) for img in db.read_all_images()]
    finally:
        db.close()


def _verified_pairs(database: Path) -> int:
    db = pycolmap.Database.open(str(database))
    try:
        return int(db.num_verified_image_pairs())
    finally:
        db.close()


def _median_triangulation_angle(rec: pycolmap.Reconstruction) -> float:
    """Median over 3D points of the widest angle between two rays that see the point [deg]."""
    centres = {i: np.asarray(rec.image(i).projection_center()) for i in rec.reg_image_ids()}
    angles = []
    for point in rec.points3D.values():
        rays = np.array([centres[e.image_id] - point.xyz for e in point.track.elements])
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        angles.append(float(np.degrees(np.arccos(np.clip((rays @ rays.T).min(), -1.0, 1.0)))))
    return float(np.median(angles)) if angles else 0.0


def _import_photos(
    database: Path,
    image_dir: Path,
    names: list[str],
    reader: pycolmap.ImageReaderOptions,
    priors: dict[str, float],
) -> int:
    """Import photos with one camera per image size, its focal prior the photos' median.

    Returns:
        The number of photos with a focal prior.

    """
    groups: dict[tuple[int, int], list[str]] = {}
    for name in names:
        with Image.open(image_dir / name) as image:
            groups.setdefault(image.size, []).append(name)
    for group in groups.values():
        pycolmap.import_images(database, image_dir, camera_mode=pycolmap.CameraMode.SINGLE,
                               image_names=group, options=reader)  # fmt: skip
    db = pycolmap.Database.open(str(database))
    try:
        images = db.read_all_images()
        for camera in db.read_all_cameras():
            focal = [priors[i.name] for i in images
                     if i.camera_id == camera.camera_id and i.name in priors]  # fmt: skip
            if focal:
                params = list(camera.params)
                params[0] = float(np.median(focal))
                camera.params = params
                camera.has_prior_focal_length = True
                db.update_camera(camera)
    finally:
        db.close()
    return sum(1 for n in names if n in priors)


def _matcher(options: SfmOptions, count: int, unordered: bool) -> tuple[str, str]:
    """Return the matcher ``options.matcher`` means for ``count`` keyframes, with a note."""
    if options.matcher != 'auto':
        return options.matcher, ''
    if not unordered:
        return 'sequential', ''
    if count <= options.exhaustive_max:
        return 'exhaustive', ''
    if options.vocab_tree:
        return 'vocabtree', ''
    return 'sequential', (
        f'{count} photos, more than sfm.exhaustive_max={options.exhaustive_max} for exhaustive '
        f'matching and no sfm.vocab_tree for retrieval: each photo was matched with the next '
        f'{options.overlap} in name order, so photos taken out of order may not register'
    )


def run_sfm(
    image_dir: Path,
    records: list[KeyframeRecord],
    out_dir: Path,
    options: SfmOptions,
    *,
    priors: dict[str, float] | None = None,
    unordered: bool = False,
) -> SparseSummary:
    """Reconstruct the keyframes; writes the model and ``sparse.json`` into ``out_dir``.

    Args:
        image_dir: The ``keyframes/`` folder.
        records: The keyframes, in capture order.
        out_dir: The ``sparse/`` folder (its previous content is replaced).
        options: Tuning.
        priors: Focal length [px] by keyframe name (from EXIF): the start of a refined camera.
        unordered: The keyframes are photos, not a sequence: one camera per image size, and
            ``"auto"`` matching as for photos.

    Returns:
        The content of ``sparse.json``.

    Raises:
        CaptureError: Too few keyframes, too few features, no initial pair or too few
            registered keyframes; the keyframes on disk are left as they are.

    """
    names = [r.file for r in records]
    advice_more = (
        'Record again moving the camera sideways along the pile (not only rotating), slowly '
        'enough for sharp frames, with the pile filling most of the view'
    )
    if len(names) < 3:
        raise CaptureError(
            'sfm', f'only {len(names)} keyframe(s) were kept, at least 3 are needed', advice_more
        )
    pycolmap.logging.minloglevel = options.log_level
    if out_dir.exists():
        shutil.rmtree(out_dir)
    out_dir.mkdir(parents=True)
    database = out_dir / 'database.db'

    reader = pycolmap.ImageReaderOptions()
    camera = _shared_camera(records) if options.use_camera_info and not unordered else None
    fixed = camera is not None
    if camera is not None:
        model, params = _colmap_camera(camera)
        reader.camera_model = model
        reader.camera_params = ','.join(f'{p:.10g}' for p in params)
    else:
        reader.camera_model = 'SIMPLE_RADIAL'
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.max_image_size = options.max_image_size
    extraction.num_threads = options.num_threads
    extraction.sift.max_num_features = options.max_features
    # Images enter the database in capture order first: parallel extraction would number them in
    # the order they finish, and the mapper's choices depend on the numbering.
    pycolmap.Database.open(str(database)).close()
    with_prior = 0
    if unordered:
        with_prior = _import_photos(database, image_dir, names, reader, priors or {})
    else:
        pycolmap.import_images(
            database,
            image_dir,
            camera_mode=pycolmap.CameraMode.SINGLE,
            image_names=names,
            options=reader,
        )
    pycolmap.extract_features(
        database,
        image_dir,
        image_names=names,
        camera_mode=pycolmap.CameraMode.SINGLE,
        reader_options=reader,
        extraction_options=extraction,
        device=pycolmap.Device.cpu,
    )
    counts = _feature_counts(database)
    mean_features = float(np.mean(counts)) if counts else 0.0
    if mean_features < options.min_features:
        raise CaptureError(
            'sfm',
            f'the keyframes have {mean_features:.0f} image features on average '
            f'(at least {options.min_features} needed): the views are blurred or textureless',
            'Check focus, exposure and motion blur; film textured surfaces (the pile), not sky or '
            'a blank wall',
        )

    matching = pycolmap.FeatureMatchingOptions()
    # One thread: threaded approximate matching gave different matches on each run of the same
    # keyframes (97921 or 100025 on the demo), so a rerun of the demo could report 14 rocks and
    # class I PASS, or 15 and FAIL; on one thread it costs no time there (33 s against 35 s).
    matching.num_threads = 1
    # COLMAP seeds RANSAC at random by default: with a fixed seed a rerun gives the same model.
    verification = pycolmap.TwoViewGeometryOptions()
    verification.ransac.random_seed = 0
    matcher, matcher_note = _matcher(options, len(names), unordered)
    if matcher == 'exhaustive':
        pycolmap.match_exhaustive(
            database,
            matching_options=matching,
            verification_options=verification,
            device=pycolmap.Device.cpu,
        )
    elif matcher == 'vocabtree':
        retrieval = pycolmap.VocabTreePairingOptions()
        retrieval.vocab_tree_path = options.vocab_tree
        pycolmap.match_vocabtree(
            database,
            matching_options=matching,
            pairing_options=retrieval,
            verification_options=verification,
            device=pycolmap.Device.cpu,
        )
    elif matcher == 'sequential':
        pairing = pycolmap.SequentialPairingOptions()
        pairing.overlap = options.overlap
        pairing.quadratic_overlap = True
        if options.vocab_tree:
            pairing.loop_detection = True
            pairing.vocab_tree_path = options.vocab_tree
        pycolmap.match_sequential(
            database,
            matching_options=matching,
            pairing_options=pairing,
            verification_options=verification,
            device=pycolmap.Device.cpu,
        )
    else:
        raise ValueError(f'unknown matcher {matcher!r}')

    models_dir = out_dir / 'models'
    models_dir.mkdir()
    if options.mapper == 'incremental':
        mapping = pycolmap.IncrementalPipelineOptions()
        # One thread: threaded bundle adjustment sums in a varying order, and the rounding
        # differences change which points are kept (a rerun gave 10341 points instead of 10345).
        mapping.num_threads = 1
        mapping.random_seed = 0
        if fixed:
            mapping.ba_refine_focal_length = False
            mapping.ba_refine_principal_point = False
            mapping.ba_refine_extra_params = False
        models = pycolmap.incremental_mapping(database, image_dir, models_dir, options=mapping)
    elif options.mapper == 'global':
        glob = pycolmap.GlobalPipelineOptions()
        glob.num_threads = options.num_threads
        glob.random_seed = 0
        models = pycolmap.global_mapping(database, image_dir, models_dir, options=glob)
    else:
        raise ValueError(f'unknown mapper {options.mapper!r}')
    shutil.rmtree(models_dir, ignore_errors=True)

    if not models:
        pairs = _verified_pairs(database)
        raise CaptureError(
            'sfm',
            f'no initial pair of keyframes could be reconstructed ({pairs} geometrically verified '
            f'pairs among {len(names)} keyframes): too little overlap, or pure rotation',
            advice_more,
        )
    ranked = sorted(models.values(), key=lambda rec: -rec.num_reg_images())
    best = ranked[0]
    registered = int(best.num_reg_images())
    report = SparseSummary(
        registered=registered,
        total=len(names),
        registered_fraction=registered / len(names),
        models=len(models),
        points=int(best.num_points3D()),
        mean_reprojection_error_px=float(best.compute_mean_reprojection_error()),
        mean_features=mean_features,
        camera=_camera_text(fixed, with_prior, len(names)),
        cameras=[_camera_report(cam) for cam in best.cameras.values()],
        matcher=matcher,
        matcher_note=matcher_note,
        mapper=options.mapper,
        unregistered=sorted(set(names) - {best.image(i).name for i in best.reg_image_ids()}),
        # Every model, the largest (the one kept) first: which keyframes landed where (also what
        # the registration gate reads).
        model_images=[
            ModelImages(
                int(rec.num_reg_images()), sorted(rec.image(i).name for i in rec.reg_image_ids())
            )
            for rec in ranked
        ],
        median_triangulation_angle_deg=_median_triangulation_angle(best),
        focal_rel_uncertainty=None if fixed else focal_uncertainty(best),
    )
    best.write(out_dir)
    save(report, out_dir / 'sparse.json')
    if report.median_triangulation_angle_deg < options.min_triangulation_angle:
        raise CaptureError(
            'sfm',
            'the keyframes see the scene from nearly one place (median triangulation angle '
            f'{report.median_triangulation_angle_deg:.1f} degrees): depth cannot be measured '
            'from a rotation on the spot',
            advice_more,
        )
    return report


def _camera_text(fixed: bool, with_prior: int, total: int) -> str:
    if fixed:
        return 'fixed from CameraInfo'
    if with_prior:
        return f'SIMPLE_RADIAL from the EXIF focal length of {with_prior}/{total} photos, refined'
    return 'self-calibrated SIMPLE_RADIAL'


def _camera_report(camera: pycolmap.Camera) -> dict[str, Any]:
    return {
        'width': int(camera.width),
        'height': int(camera.height),
        'model': str(camera.model_name),
        'params': [float(v) for v in camera.params],
        'prior_focal_length': bool(camera.has_prior_focal_length),
    }


def model_figures(sparse_dir: Path) -> tuple[list[dict[str, Any]], float]:
    """Return the cameras (as ``sparse.json`` lists them) and mean reprojection error [px].

    For the summary of a model adjusted again after :func:`run_sfm` (see :func:`pin_focal`).
    """
    rec = pycolmap.Reconstruction(str(sparse_dir))
    cameras = [_camera_report(cam) for cam in rec.cameras.values()]
    return cameras, float(rec.compute_mean_reprojection_error())


def focal_uncertainty(rec: pycolmap.Reconstruction) -> float | None:
    """Relative standard deviation of the focal length bundle adjustment refined, the worst camera.

    The covariance of the camera parameters is the inverse of the bundle adjustment's normal
    equations (three points fix the model's free similarity) for residuals of 1 px, scaled by the
    model's own residual variance per image coordinate (from each point's mean reprojection
    error). A self-calibrated focal length off by some share changes the depth of every point
    against its width by about as much, and with it a scale measured on a target and carried to
    the rest of the model.

    Returns:
        The share, or None when the covariance cannot be computed (a degenerate model).

    """
    config = pycolmap.BundleAdjustmentConfig()
    for image_id in rec.reg_image_ids():
        config.add_image(image_id)
    config.fix_gauge(pycolmap.BundleAdjustmentGauge.THREE_POINTS)
    adjuster = pycolmap.create_default_ceres_bundle_adjuster(
        pycolmap.BundleAdjustmentOptions(), config, rec
    )
    options = pycolmap.BACovarianceOptions()
    options.params = pycolmap.BACovarianceOptionsParams.ALL
    covariance = pycolmap.estimate_ba_covariance(options, rec, adjuster)
    errors = np.array([p.error for p in rec.points3D.values()], dtype=np.float64)
    if covariance is None or not errors.size:
        return None
    variance = float(np.mean(errors**2)) / 2
    shares = []
    for camera in rec.cameras.values():
        block = covariance.get_other_params_cov(camera.params)
        # The focal length is the first refined parameter of every model run_sfm refines.
        if block is not None and block.size and block[0, 0] > 0:
            shares.append(math.sqrt(float(block[0, 0]) * variance) / float(camera.params[0]))
    return max(shares) if shares else None


Poses = dict[str, tuple[CameraModel, npt.NDArray[np.float64], npt.NDArray[np.float64]]]
"""Camera, world-to-camera rotation and translation per registered image name."""


def _poses(rec: pycolmap.Reconstruction) -> Poses:
    out: Poses = {}
    for image_id in rec.reg_image_ids():
        image = rec.image(image_id)
        pose = image.cam_from_world()
        out[image.name] = (
            _opencv_camera(rec.camera(image.camera_id)),
            np.asarray(pose.rotation.matrix(), dtype=np.float64),
            np.asarray(pose.translation, dtype=np.float64).reshape(3),
        )
    return out


def resampled_poses(
    sparse_dir: Path, rounds: int = 20, *, refine_intrinsics: bool = True, seed: int = 0
) -> list[Poses]:
    """Cameras and poses of the model bundle-adjusted again on random halves of its 3D points.

    How far the poses and a self-calibrated focal length move between halves of the points is
    what they rest on (delete-half jackknife: the spread of the half-sample estimates about their
    mean is the full estimate's variance). Unlike the covariance of :func:`focal_uncertainty`
    it assumes neither Gaussian residuals nor independent points: on simulated walks with a
    heavy tail of residuals (a sixth of the observations beyond 1 px, the median 0.35 px) the
    covariance put a self-calibrated focal length at 0.26-0.46 % while it was off by up to
    1.6 %; the half-samples spread by 0.3-0.95 %.

    Args:
        sparse_dir: The COLMAP model written by :func:`run_sfm`.
        rounds: Number of halves.
        refine_intrinsics: Refine the focal length and distortion (as the mapper did); False for
            a camera fixed from CameraInfo.
        seed: Seed of the random halves.

    Returns:
        One set of poses per half whose adjustment converged; empty for a model of under 20
        points or 3 views.

    """
    base = pycolmap.Reconstruction(str(sparse_dir))
    ids = np.asarray(sorted(base.points3D.keys()), dtype=np.int64)
    if len(ids) < 20 or base.num_reg_images() < 3:
        return []
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(rounds):
        rec = pycolmap.Reconstruction(base)
        for point_id in rng.permutation(ids)[: len(ids) // 2]:
            rec.delete_point3D(int(point_id))
        if _adjust(rec, refine_focal=refine_intrinsics, refine_extra=refine_intrinsics):
            out.append(_poses(rec))
    return out


def _adjust(rec: pycolmap.Reconstruction, *, refine_focal: bool, refine_extra: bool) -> bool:
    """Bundle-adjust every registered image of ``rec`` in place; whether it converged."""
    options = pycolmap.BundleAdjustmentOptions()
    options.print_summary = False
    options.refine_principal_point = False
    options.refine_focal_length = refine_focal
    options.refine_extra_params = refine_extra
    # One thread: the same model gives the same adjustment on every run.
    options.ceres.solver_options.num_threads = 1
    config = pycolmap.BundleAdjustmentConfig()
    for image_id in rec.reg_image_ids():
        config.add_image(image_id)
    config.fix_gauge(pycolmap.BundleAdjustmentGauge.THREE_POINTS)
    summary = pycolmap.create_default_ceres_bundle_adjuster(options, config, rec).solve()
    return bool(summary.is_solution_usable())


def pin_focal(
    sparse_dir: Path, planes: Mapping[str, list[PlanarView]], max_change: float = 0.1
) -> list[dict[str, Any]]:
    """Set each camera's focal length and k1 to what its images' target planes give; re-adjust.

    For each ``SIMPLE_RADIAL`` camera of the model (self-calibrated) whose registered images see
    at least :data:`.calibration.MIN_VIEWS` target planes, the focal length and k1 are measured
    on them (:func:`.calibration.target_focal`, the principal point held); when the focal length
    is within ``max_change`` of the model's, both replace the model's and the model is
    bundle-adjusted again with the intrinsics held. The model in ``sparse_dir`` is rewritten
    when any camera changed.

    Args:
        sparse_dir: The COLMAP model written by :func:`run_sfm`.
        planes: Target planes by image name (:func:`.calibration.planar_views`).
        max_change: Largest relative change of a focal length accepted.

    Returns:
        Per camera measured: the focal lengths before and after, the uncertainty, the views
        and whether it was used (for ``sparse.json``).

    """
    rec = pycolmap.Reconstruction(str(sparse_dir))
    by_camera: dict[int, list[PlanarView]] = {}
    for image_id in rec.reg_image_ids():
        image = rec.image(image_id)
        by_camera.setdefault(int(image.camera_id), []).extend(planes.get(image.name, []))
    out: list[dict[str, Any]] = []
    for camera_id, views in sorted(by_camera.items()):
        camera = rec.camera(camera_id)
        if str(camera.model_name) != 'SIMPLE_RADIAL':
            continue
        model = _opencv_camera(camera)
        found = target_focal(views, model)
        if found is None:
            continue
        used = abs(found.focal_px / model.fx - 1) <= max_change
        out.append({'camera_id': camera_id, 'sfm_focal_px': model.fx,
                    'sfm_k1': float(camera.params[3]), 'focal_px': found.focal_px, 'k1': found.k1,
                    'rel_uncertainty': found.rel_uncertainty, 'views': found.views,
                    'rms_px': found.rms_px, 'used': used})  # fmt: skip
        if used:
            params = np.array(camera.params, dtype=np.float64)
            params[0], params[3] = found.focal_px, found.k1
            camera.params = params.tolist()
    if any(entry['used'] for entry in out) and _adjust(rec, refine_focal=False, refine_extra=False):
        rec.write(str(sparse_dir))
    else:
        for entry in out:
            entry['used'] = False
    return out


def load_sparse(sparse_dir: Path) -> SparseModel:
    """Read the COLMAP model written by :func:`run_sfm` into numpy arrays."""
    rec = pycolmap.Reconstruction(str(sparse_dir))
    views: dict[str, View] = {}
    for image_id in rec.reg_image_ids():
        image = rec.image(image_id)
        pose = image.cam_from_world()
        ids = [p.point3D_id for p in image.points2D if p.has_point3D()]
        views[image.name] = View(
            name=image.name,
            camera=_opencv_camera(rec.camera(image.camera_id)),
            rotation=np.asarray(pose.rotation.matrix(), dtype=np.float64),
            translation=np.asarray(pose.translation, dtype=np.float64).reshape(3),
            point_ids=np.asarray(ids, dtype=np.int64),
        )
    pids = np.asarray(sorted(rec.points3D.keys()), dtype=np.int64)
    points = np.array([rec.points3D[int(i)].xyz for i in pids], dtype=np.float64).reshape(-1, 3)
    colors = np.array([rec.points3D[int(i)].color for i in pids], dtype=np.uint8).reshape(-1, 3)
    return SparseModel(views=views, point_ids=pids, points=points, colors=colors)
