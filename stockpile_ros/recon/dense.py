"""Dense coloured point cloud with oriented normals from the registered keyframes, on the CPU.

Each keyframe is paired with a nearby keyframe at a useful baseline (or with several, one on each
side of it in capture order where it can be: ``DenseOptions.partners``); each pair is rectified
(``cv2.stereoRectify``, vertical pairs transposed, right-to-left pairs mirrored) and matched with
semi-global block matching (four symmetric paths) over the disparity range the sparse points
predict. Every depth map is then checked against the other depth maps of its keyframe and of the
neighbouring keyframes (each from its own pair): a point is kept only where two other pairs see
the same surface at the same depth. The survivors are fused on a voxel grid as they come (running
sums per voxel, so memory holds the fused cloud, never every point of every view); normals are
estimated from neighbours and turned towards the cameras that saw them.
With a CUDA build of pycolmap, COLMAP's PatchMatch stereo and fusion are used instead.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import cv2
import numpy as np
import numpy.typing as npt
import open3d as o3d
import pycolmap

from ..artefacts import DenseSummary, from_json, save
from ..camera import CameraModel
from ..errors import CaptureError
from ..progress import progress
from ..ranges import Range
from .sfm import SparseModel, View

__all__ = ['DenseOptions', 'DepthView', 'dense_cloud', 'refine_disparity', 'run_dense']

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class DenseOptions:
    """Tuning of the dense stage.

    Attributes:
        work_width: Width [px] keyframes are downscaled to for stereo matching.
        stride: Every ``stride``-th pixel (in both directions) becomes a point.
        pair_window: Partners are searched among this many keyframes before and after.
        partners: Depth maps per keyframe, each from its own partner view (see
            ``_pick_partners``). On eleven simulated piles two took the share of the visible
            rock surface that was reconstructed from 0.80 to 0.83 on average (most at the ends
            of a pass, which only the first or last few keyframes see) and found one more rock
            of 132, for twice the stereo time; the gradation did not get better (mean D50 error
            3.7 % -> 5.8 %, volume error 27 % -> 31 %, both within the pile-to-pile spread).
        target_baseline: Preferred baseline as a share of the median scene depth.
        check_window: Depth maps of this many keyframes on each side check a point.
        min_agree: Other depth maps (each from its own pair) that must agree with a point.
            Two, with ``depth_tolerance`` 0.004, took the median distance of the rock surface
            from the true one (bench/bench_surface.py, 800x600) from 0.83 to 0.68 % of the
            median b on an arc, 0.71 to 0.64 % on an orbit, 0.79 to 0.69 % on a straight pass
            and 1.76 to 1.55 % on a pile of rocks half that size, at about the same cost (a
            pair's depths scatter by about 0.15 % without bias); but the smoother surface
            joined touching rocks on the demo pile (recall 0.93 -> 0.71, 15 -> 10 rocks): the
            segmentation's valley and convexity rules were measured on the surface one pair
            and 1 % give, which is within 1 % of b already. One until the segmentation is
            measured on the stricter one.
        depth_tolerance: Relative depth difference counted as agreement (0.004 is about three
            times the scatter of a pair's depths, above).
        voxel: Fusion voxel edge in model units; 0 picks about two pixel footprints.
        use_gpu: Use COLMAP PatchMatch when pycolmap has CUDA.
        block_size: SGBM matching block edge [px] (odd).
        refine_window: Edge [px] of the window over which each SGBM disparity is refined to a
            sub-pixel value by Gauss-Newton steps on the intensity difference (0 keeps SGBM's
            own parabola fit, which pulls disparities towards whole pixels: a quarter-pixel
            shift came out 0.19-0.25 px off). With 9 the rock-surface error (see
            ``min_agree``) went from 0.68 to 0.63 % of b on the arc, 0.64 to 0.61 % on the
            orbit, 0.69 to 0.56 % on the straight pass and 1.55 to 1.35 % on the smaller rocks,
            and a pair's median depth bias from +0.02 to +0.004 %; but on a weakly textured
            ground (tests/recon_synth.py) it dropped two thirds of a pair's depths, and keeping
            SGBM's value there instead lost the gain on the arc (0.71 %): off until it keeps
            the coverage.
        refine_iterations: Gauss-Newton steps of that refinement.

    """

    work_width: Annotated[int, Range(64, 16384)] = 1280
    stride: Annotated[int, Range(1, 64)] = 2
    pair_window: Annotated[int, Range(1, 100)] = 30
    partners: Annotated[int, Range(1, 8)] = 1
    target_baseline: Annotated[float, Range(0.0, 10.0)] = 0.25
    check_window: Annotated[int, Range(0, 100)] = 3
    min_agree: Annotated[int, Range(0, 100)] = 1
    depth_tolerance: Annotated[float, Range(0.0, 1.0)] = 0.01
    voxel: Annotated[float, Range(0.0, 1e6)] = 0.0
    block_size: Annotated[int, Range(1, 31)] = 5
    refine_window: Annotated[int, Range(0, 31)] = 0
    refine_iterations: Annotated[int, Range(1, 20)] = 3
    use_gpu: bool = True


@dataclass
class DepthView:
    """A keyframe's depth map at working resolution and the points it produced.

    Attributes:
        view: The registered view.
        k: 3x3 pinhole intrinsics of the working resolution.
        depth: HxW depth along the optical axis (inf where unknown).
        points: Nx3 world points.
        colors: Nx3 uint8 colours.

    """

    view: View
    k: F64
    depth: npt.NDArray[np.float32]
    points: F64
    colors: npt.NDArray[np.uint8]


def _scaled(camera: CameraModel, scale: float) -> tuple[F64, F64, tuple[int, int]]:
    """Intrinsics, distortion and size of ``camera`` scaled by ``scale`` (pixel centres kept)."""
    k = camera.k.copy()
    k[0, 0] *= scale
    k[1, 1] *= scale
    k[0, 2] = (k[0, 2] + 0.5) * scale - 0.5
    k[1, 2] = (k[1, 2] + 0.5) * scale - 0.5
    size = (round(camera.width * scale), round(camera.height * scale))
    d = np.asarray(camera.d, dtype=np.float64)
    return k, d if d.size else np.zeros(5), size


def _depth_stats(view: View, model: SparseModel) -> tuple[float, float]:
    """Median depth of the sparse points a view sees and the span of their inverse depth."""
    rows = np.searchsorted(model.point_ids, view.point_ids)
    pts = model.points[rows]
    z = (pts @ view.rotation.T + view.translation)[:, 2]
    z = z[z > 0]
    if z.size < 10:
        return float('nan'), float('nan')
    near, far = np.percentile(z, [2, 98])
    # The same margins as the disparity search range of _pair_depth.
    return float(np.median(z)), float(1.3 / near - 0.7 / far)


def _pick_partners(
    i: int, views: list[View], stats: list[tuple[float, float]], options: DenseOptions
) -> list[int]:
    """Return the indices of the ``options.partners`` views to pair with ``views[i]``, best first.

    The first is the one closest to the target baseline ratio, the next ones the closest on the
    other side in capture order where there is one: seen from both sides, a rock's flanks that
    one partner hides are in the other's view. Baselines short enough for the scene's disparity
    range (with the margins of :func:`_pair_depth`) to fit the matcher's 256 disparities are
    preferred: a deep scene (a low camera looking across the ground) needs a short one. When no
    neighbour is that close the best of the others is taken: the pile, nearer than the far
    ground, is then still in range.
    """
    depth, span = stats[i]
    width = min(options.work_width, views[i].camera.width)
    max_baseline = 240.0 / (views[i].camera.fx * width / views[i].camera.width * span)
    ranked: list[tuple[bool, float, int]] = []
    for j in range(max(0, i - options.pair_window), min(len(views), i + options.pair_window + 1)):
        if j == i:
            continue
        baseline = float(np.linalg.norm(views[j].center - views[i].center))
        ratio = baseline / depth
        axes = float(views[i].rotation[2] @ views[j].rotation[2])
        if not 0.02 <= ratio <= 0.6 or axes < np.cos(np.radians(40)):
            continue
        cost = abs(float(np.log(ratio / options.target_baseline)))
        ranked.append((baseline > max_baseline, cost, j))
    ranked.sort()
    if not ranked:
        return []
    first = ranked[0][2]
    rest = sorted(ranked[1:], key=lambda r: ((r[2] > i) == (first > i), r[0], r[1]))
    return [first] + [j for _, _, j in rest[: options.partners - 1]]


def refine_disparity(
    left: npt.NDArray[np.float32],
    right: npt.NDArray[np.float32],
    disp: npt.NDArray[np.float32],
    window: int,
    iterations: int,
) -> npt.NDArray[np.float32]:
    """Sub-pixel disparities by Gauss-Newton steps on the windowed intensity difference.

    ``left[v, u]`` is matched with ``right[v, u - disp[v, u]]``. Each step warps ``right`` by the
    current disparities and solves, per pixel, the least-squares shift of the warped image (with
    an intensity offset, so a brightness change between the views does not move it) over the
    ``window`` x ``window`` neighbourhood. A disparity that moves more than one pixel away from
    its start, where the matcher is right to a pixel, or whose window has no texture, is NaN.

    Args:
        left: HxW grey image (float32).
        right: HxW grey image of the partner, rectified with ``left``.
        disp: HxW starting disparities [px]; NaN where unknown.
        window: Window edge [px].
        iterations: Gauss-Newton steps.

    Returns:
        The refined disparities (NaN where unknown or rejected).

    """
    h, w = left.shape
    grad = np.asarray(cv2.Sobel(right, cv2.CV_32F, 1, 0, ksize=3), dtype=np.float32) / 8.0
    cols = np.broadcast_to(np.arange(w, dtype=np.float32), (h, w))
    rows = np.ascontiguousarray(np.broadcast_to(np.arange(h, dtype=np.float32)[:, None], (h, w)))
    known = np.isfinite(disp)
    start = np.where(known, disp, 0.0).astype(np.float32)
    d = start.copy()

    def box(img: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        return np.asarray(cv2.blur(img, (window, window)), dtype=np.float32)

    left_c = left - box(left)
    texture = box(left_c * left_c)
    for _ in range(iterations):
        mx = np.ascontiguousarray(cols - d)
        warped = np.asarray(cv2.remap(right, mx, rows, cv2.INTER_CUBIC), dtype=np.float32)
        gx = np.asarray(cv2.remap(grad, mx, rows, cv2.INTER_CUBIC), dtype=np.float32)
        # right(u - d - s) ~ warped - gx s: minimise sum((left - warped + gx s) - offset)^2.
        e = left - warped
        e -= box(e)
        gx -= box(gx)
        gg = box(gx * gx)
        step = -box(gx * e) / np.maximum(gg, 1e-6)
        d += np.clip(step, -0.5, 0.5)
    # Too little texture for a step to mean anything: under a tenth of a grey level per pixel.
    ok = known & (np.abs(d - start) <= 1.0) & (texture > 0.01) & (gg > 1e-4)
    return np.where(ok, d, np.nan).astype(np.float32)


def _pair_depth(
    image_dir: Path,
    a: View,
    b: View,
    model: SparseModel,
    options: DenseOptions,
    cache: dict[str, npt.NDArray[np.uint8]],
) -> DepthView | None:
    """Depth map of view ``a`` from the rectified pair (a, b)."""

    def load(view: View) -> npt.NDArray[np.uint8]:
        if view.name not in cache:
            bgr = cv2.imread(str(image_dir / view.name), cv2.IMREAD_COLOR)
            if bgr is None:
                raise OSError(f'cannot read {image_dir / view.name}')
            cache[view.name] = np.asarray(bgr, dtype=np.uint8)
        return cache[view.name]

    k1, d1, size = _scaled(a.camera, min(1.0, options.work_width / a.camera.width))
    k2, d2, _ = _scaled(b.camera, size[0] / b.camera.width)
    rel_r = b.rotation @ a.rotation.T
    rel_t = b.translation - rel_r @ a.translation
    r1, r2, p1, p2, _, _, _ = cv2.stereoRectify(
        k1, d1, k2, d2, size, rel_r, rel_t, flags=cv2.CALIB_ZERO_DISPARITY, alpha=-1
    )
    vertical = abs(p2[1, 3]) > abs(p2[0, 3])
    shift = float(p2[1, 3] if vertical else p2[0, 3])
    f, cx, cy = float(p1[0, 0]), float(p1[0, 2]), float(p1[1, 2])

    rows = np.searchsorted(model.point_ids, a.point_ids)
    cam = model.points[rows] @ a.rotation.T + a.translation
    z_rect = (cam @ r1.T)[:, 2]
    z_rect = z_rect[z_rect > 0]
    if z_rect.size < 10:
        return None
    disp_lo = abs(shift) / np.percentile(z_rect, 98) * 0.7
    disp_hi = abs(shift) / np.percentile(z_rect, 2) * 1.3
    min_disp = int(np.floor(disp_lo))
    num_disp = int(np.clip(16 * np.ceil((disp_hi - min_disp) / 16), 16, 256))

    rect = []
    for view, k, d, r, p in ((a, k1, d1, r1, p1), (b, k2, d2, r2, p2)):
        small = cv2.resize(load(view), size, interpolation=cv2.INTER_AREA)
        mx, my = cv2.initUndistortRectifyMap(k, d, r, p, size, cv2.CV_32FC1)
        rect.append(cv2.remap(small, mx, my, cv2.INTER_LINEAR))
    colour = rect[0]
    greys = [cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) for img in rect]
    if vertical:
        greys = [np.ascontiguousarray(g.T) for g in greys]
    if shift > 0:
        greys = [np.ascontiguousarray(g[:, ::-1]) for g in greys]
    block = options.block_size
    sgbm = cv2.StereoSGBM.create(
        minDisparity=min_disp,
        numDisparities=num_disp,
        blockSize=block,
        P1=8 * block * block,
        P2=32 * block * block,
        disp12MaxDiff=1,
        uniquenessRatio=10,
        speckleWindowSize=100,
        speckleRange=2,
        # Four paths, both ways along rows and columns: the default single top-down pass pulls
        # disparities towards the rows above, so surfaces receding along the columns (the ground
        # and the pile seen from a cart) came out about 0.3 px of disparity (0.2 %) too deep.
        mode=cv2.STEREO_SGBM_MODE_HH4,
    )
    disp = sgbm.compute(greys[0], greys[1]).astype(np.float32) / 16.0
    valid = disp > max(min_disp, 0) + 0.5
    if options.refine_window:
        floats = [g.astype(np.float32) for g in greys]
        disp = refine_disparity(
            floats[0], floats[1], np.where(valid, disp, np.nan).astype(np.float32),
            options.refine_window, options.refine_iterations,
        )  # fmt: skip
        valid = np.isfinite(disp) & (disp > 0.5)
    if shift > 0:
        disp, valid = disp[:, ::-1], valid[:, ::-1]
    if vertical:
        disp, valid = disp.T, valid.T
    mask = np.zeros_like(valid)
    mask[:: options.stride, :: options.stride] = True
    v, u = np.nonzero(valid & mask)
    if u.size == 0:
        return None
    z = abs(shift) / disp[v, u]
    p_rect = np.stack([(u - cx) * z / f, (v - cy) * z / f, z], axis=1)
    p_cam = p_rect @ r1  # rectified -> camera a: R1^T applied to row vectors
    world = (p_cam - a.translation) @ a.rotation
    colors = colour[v, u][:, ::-1].astype(np.uint8)

    # Depth map on the pinhole grid of view a (distortion ignored: every check uses this grid).
    w, h = size
    depth = np.full((h, w), np.inf, dtype=np.float32)
    uv = p_cam @ k1.T
    pu = np.round(uv[:, 0] / uv[:, 2]).astype(np.int64)
    pv = np.round(uv[:, 1] / uv[:, 2]).astype(np.int64)
    inside = (pu >= 0) & (pu < w) & (pv >= 0) & (pv < h) & (p_cam[:, 2] > 0)
    order = np.argsort(-p_cam[inside, 2])
    depth[pv[inside][order], pu[inside][order]] = p_cam[inside, 2][order]
    if options.stride > 1:
        # Fill the holes the stride leaves so a neighbour's check finds a value.
        kernel = np.ones((options.stride + 1, options.stride + 1), np.uint8)
        depth = np.asarray(cv2.erode(depth, kernel), dtype=np.float32)
    return DepthView(view=a, k=k1, depth=depth, points=world, colors=colors)


def _agreement(dv: DepthView, other: DepthView, tolerance: float) -> npt.NDArray[np.bool_]:
    """Whether each point of ``dv`` matches the depth ``other`` sees along the same ray."""
    cam = dv.points @ other.view.rotation.T + other.view.translation
    h, w = other.depth.shape
    z = cam[:, 2]
    safe = np.where(z > 0, z, 1.0)
    u = np.round(cam[:, 0] / safe * other.k[0, 0] + other.k[0, 2]).astype(np.int64)
    v = np.round(cam[:, 1] / safe * other.k[1, 1] + other.k[1, 2]).astype(np.int64)
    inside = (z > 0) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    ok = np.zeros(len(z), dtype=bool)
    seen = other.depth[v[inside], u[inside]]
    ok[inside] = np.abs(seen - z[inside]) < tolerance * z[inside]
    return ok


class _VoxelSums:
    """Per-voxel sums of points, colours and view directions, added to view by view.

    The fused cloud is the mean of each voxel's points, as a voxel down-sampling of every
    consistent point at once would give, without ever holding all of them: batches wait until
    they outnumber the voxels already summed (and ``min_batch``), then merge: each point is
    sorted a few times over the whole run, not once per view.
    """

    # Voxel indices are packed into one int64, 21 bits per axis; farther points are dropped.
    _HALF = 1 << 20

    def __init__(self, voxel: float, min_batch: int = 1_000_000):
        self.voxel = voxel
        self.min_batch = min_batch
        self.added = 0
        self.keys = np.zeros(0, dtype=np.int64)
        self.sums = np.zeros((0, 9), dtype=np.float64)
        self.counts = np.zeros(0, dtype=np.float64)
        self.pending: list[tuple[npt.NDArray[np.int64], F64]] = []
        self.pending_points = 0

    def add(self, points: F64, colors: npt.NDArray[np.uint8], centre: F64) -> None:
        """Add points seen from the optical centre ``centre`` with their colours."""
        index = np.floor(points / self.voxel).astype(np.int64)
        inside = np.all(np.abs(index) < self._HALF, axis=1)
        index = index[inside] + self._HALF
        keys = (index[:, 0] << 42) | (index[:, 1] << 21) | index[:, 2]
        dirs = centre - points[inside]
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        values = np.hstack([points[inside], colors[inside] / 255.0, dirs])
        self.pending.append((keys, values))
        self.added += len(keys)
        self.pending_points += len(keys)
        if self.pending_points > max(len(self.keys), self.min_batch):
            self._merge()

    def _merge(self) -> None:
        keys = np.concatenate([self.keys, *(k for k, _ in self.pending)])
        weights = np.concatenate([self.counts, *(np.ones(len(k)) for k, _ in self.pending)])
        self.keys, inverse = np.unique(keys, return_inverse=True)
        del keys
        n = len(self.keys)
        self.counts = np.bincount(inverse, weights=weights, minlength=n).astype(np.float64)
        # Summed a column at a time: the whole batch and the sums concatenated at once were the
        # stage's peak memory (2.7 GiB at 80 keyframes of 1280x960).
        old, batches = self.sums, [v for _, v in self.pending]
        self.pending, self.pending_points = [], 0
        sums = np.empty((n, 9), dtype=np.float64)
        for c in range(9):
            column = np.concatenate([old[:, c], *(v[:, c] for v in batches)])
            sums[:, c] = np.bincount(inverse, weights=column, minlength=n)
        self.sums = sums

    def cloud(self) -> o3d.geometry.PointCloud:
        """Return the voxel means: points, colours, and as normals the mean view directions.

        The sums are handed over (divided in place, the object left empty): a copy of them beside
        open3d's was the stage's peak memory.
        """
        self._merge()
        mean = self.sums
        mean /= self.counts[:, None]
        self.keys, self.counts = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.float64)
        self.sums = np.zeros((0, 9), dtype=np.float64)
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(mean[:, :3]))
        pcd.colors = o3d.utility.Vector3dVector(mean[:, 3:6])
        pcd.normals = o3d.utility.Vector3dVector(mean[:, 6:])
        return pcd


def dense_cloud(
    image_dir: Path, model: SparseModel, order: list[str], options: DenseOptions
) -> tuple[o3d.geometry.PointCloud, dict[str, Any]]:
    """Fuse SGBM depth maps of the registered keyframes into an oriented, coloured cloud.

    Args:
        image_dir: The ``keyframes/`` folder.
        model: The sparse model.
        order: Keyframe file names in capture order (pairs are looked for among neighbours).
        options: Tuning.

    Returns:
        The cloud (model units) and figures about the run.

    """
    views = [model.views[name] for name in order if name in model.views]
    depth_stats = [_depth_stats(v, model) for v in views]
    depths = [s[0] for s in depth_stats]
    voxel = options.voxel
    if voxel <= 0 and views:
        camera = views[0].camera
        f_work = camera.fx * min(1.0, options.work_width / camera.width)
        voxel = options.stride * float(np.nanmedian(depths)) / f_work
    sums = _VoxelSums(voxel)
    cache: dict[str, npt.NDArray[np.uint8]] = {}
    maps: dict[int, list[DepthView]] = {}
    raw, made, w = 0, 0, options.check_window

    def check(i: int) -> None:
        """Keep the points of the depth maps of view ``i`` that other depth maps agree with."""
        for n, dv in enumerate(maps[i]):
            agree = np.zeros(len(dv.points), dtype=np.int64)
            for k in range(i - w, i + w + 1):
                for m, other in enumerate(maps.get(k, [])):
                    if (k, m) != (i, n):
                        agree += _agreement(dv, other, options.depth_tolerance)
            keep = agree >= options.min_agree
            sums.add(dv.points[keep], dv.colors[keep], dv.view.center)

    # Streamed: a view's depth maps are checked once the last neighbour's exist and dropped once
    # no later view needs them, and the points that pass go straight into the voxel sums, so
    # memory holds 2 w + 1 views' maps and the fused cloud whatever the number of keyframes.
    for i in progress(range(len(views)), 'stereo', unit='view'):
        partners = _pick_partners(i, views, depth_stats, options) if np.isfinite(depths[i]) else []
        pair_maps = (
            _pair_depth(image_dir, views[i], views[j], model, options, cache) for j in partners
        )
        maps[i] = [dv for dv in pair_maps if dv is not None]
        made += bool(maps[i])
        raw += sum(len(dv.points) for dv in maps[i])
        if i - w >= 0:
            check(i - w)
        maps.pop(i - 2 * w, None)
        # Only neighbours' images are needed again.
        for name in [n for n in cache if n not in {v.name for v in views[max(0, i - 5) : i + 6]}]:
            del cache[name]
    for i in range(max(0, len(views) - w), len(views)):
        check(i)
    if sums.added < 100:
        raise CaptureError(
            'dense',
            f'{made} of {len(views)} keyframes gave a depth map and '
            'too few depths agreed between views',
            'Record with more overlap between neighbouring views and a sideways motion',
        )
    fused = sums.cloud()
    fused, _ = fused.remove_statistical_outlier(nb_neighbors=20, std_ratio=2.0)
    _orient(fused, voxel)
    stats = {
        'method': 'sgbm-pairs',
        'gpu': False,
        'views': len(views),
        'depth_maps': made,
        'raw_points': raw,
        'consistent_points': sums.added,
        'points': len(fused.points),
        'voxel': voxel,
    }
    return fused, stats


def _orient(cloud: o3d.geometry.PointCloud, voxel: float) -> None:
    """Estimate normals, pointing them to the side the (averaged) stored view directions face."""
    towards = np.asarray(cloud.normals).copy()
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=4 * voxel, max_nn=30))
    normals = np.asarray(cloud.normals)
    flip = np.sum(normals * towards, axis=1) < 0
    normals[flip] *= -1
    cloud.normals = o3d.utility.Vector3dVector(normals)


def _colmap_dense(image_dir: Path, sparse_dir: Path, out_dir: Path) -> o3d.geometry.PointCloud:
    """COLMAP PatchMatch stereo and fusion (CUDA builds of pycolmap only)."""
    mvs = out_dir / 'mvs'
    pycolmap.undistort_images(mvs, sparse_dir, image_dir)
    pycolmap.patch_match_stereo(mvs)
    pycolmap.stereo_fusion(mvs / 'fused.ply', mvs, output_type='PLY')
    cloud = o3d.io.read_point_cloud(mvs / 'fused.ply')
    return cloud


def run_dense(
    image_dir: Path,
    sparse_dir: Path,
    model: SparseModel,
    order: list[str],
    out_dir: Path,
    options: DenseOptions,
) -> DenseSummary:
    """Compute the dense cloud and write ``dense.ply`` and ``dense.json`` into ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    if options.use_gpu and bool(getattr(pycolmap, 'has_cuda', False)):
        cloud = _colmap_dense(image_dir, sparse_dir, out_dir)
        stats: dict[str, Any] = {
            'method': 'colmap-patchmatch',
            'gpu': True,
            'points': len(cloud.points),
        }
    else:
        cloud, stats = dense_cloud(image_dir, model, order, options)
    o3d.io.write_point_cloud(out_dir / 'dense.ply', cloud, write_ascii=False)
    summary = from_json(DenseSummary, stats, 'dense')
    save(summary, out_dir / 'dense.json')
    return summary
