from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import open3d as o3d
from recon_synth import look_at, render, scene_mesh

from stockpile_ros.camera import CameraModel
from stockpile_ros.recon.dense import (
    DenseOptions,
    _depth_stats,
    _pair_depth,
    _pick_partners,
    _VoxelSums,
    refine_disparity,
)
from stockpile_ros.recon.sfm import SparseModel, View


def test_depth_of_ground_seen_obliquely_is_unbiased(tmp_path: Path) -> None:
    # A surface receding along the image rows is where a one-pass (top-down) semi-global matcher
    # pulls disparities towards the rows above: depths came out 0.6 % too deep here.
    mesh = scene_mesh(rocks=0)
    cam = CameraModel.from_fov(640, 480, 60.0)
    target = np.array([0.0, 0.0, 0.0])
    views = []
    for i, x in enumerate((-0.15, 0.15)):
        rot, trans = look_at(np.array([x, -1.6, 1.0]), target)
        name = f'{i}.png'
        cv2.imwrite(str(tmp_path / name), render(mesh, cam.k, (cam.width, cam.height), rot, trans))
        views.append(View(name, cam, rot, trans, np.arange(400)))
    ground = np.random.default_rng(0).uniform([-0.6, -0.6, 0.0], [0.6, 0.6, 0.0], (400, 3))
    model = SparseModel(
        {v.name: v for v in views}, np.arange(400), ground, np.zeros((400, 3), np.uint8)
    )
    dv = _pair_depth(tmp_path, views[0], views[1], model, DenseOptions(), {})
    assert dv is not None and len(dv.points) > 20_000
    centre = views[0].center
    rays = dv.points - centre
    dist = np.linalg.norm(rays, axis=1)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    query = np.hstack([np.broadcast_to(centre, rays.shape), rays / dist[:, None]])
    true = scene.cast_rays(o3d.core.Tensor(query.astype(np.float32)))['t_hit'].numpy()
    rel = dist[np.isfinite(true)] / true[np.isfinite(true)] - 1.0
    assert abs(float(np.median(rel))) < 0.002
    assert float(np.percentile(np.abs(rel), 75)) < 0.01


def test_partners_are_taken_on_both_sides_where_there_are_any() -> None:
    # Nine views 0.2 m apart on a straight pass 2 m from the pile: the target baseline (a quarter
    # of the depth) is about two steps.
    cam = CameraModel.from_fov(640, 480, 60.0)
    pile = np.random.default_rng(1).uniform([-0.5, -0.3, 0.0], [0.5, 0.3, 0.4], (300, 3))
    views = []
    for i in range(9):
        x = -0.8 + 0.2 * i
        rot, trans = look_at(np.array([x, -2.0, 0.6]), np.array([x, 0.0, 0.0]))
        views.append(View(f'{i}.png', cam, rot, trans, np.arange(300)))
    model = SparseModel(
        {v.name: v for v in views}, np.arange(300), pile, np.zeros((300, 3), np.uint8)
    )
    stats = [_depth_stats(v, model) for v in views]
    one, two = DenseOptions(partners=1), DenseOptions(partners=2)
    middle = _pick_partners(4, views, stats, two)
    assert middle[:1] == _pick_partners(4, views, stats, one)
    assert len(middle) == 2 and min(middle) < 4 < max(middle)
    first = _pick_partners(0, views, stats, two)
    assert len(first) == 2 and min(first) > 0


def _shifted_pair(shift: float) -> tuple[np.ndarray, np.ndarray]:
    """A textured 8-bit pair in which ``left[v, u]`` shows ``right[v, u - shift]``."""
    rng = np.random.default_rng(2)
    h, w = 120, 160
    base = cv2.GaussianBlur(rng.uniform(0, 255, (h, w + 64)).astype(np.float32), (0, 0), 1.5)
    cols = np.broadcast_to(np.arange(w, dtype=np.float32) + 32, (h, w))
    rows = np.ascontiguousarray(np.broadcast_to(np.arange(h, dtype=np.float32)[:, None], (h, w)))
    left, right = (
        np.clip(np.round(cv2.remap(base, np.ascontiguousarray(cols + s), rows, cv2.INTER_CUBIC)),
                0, 255).astype(np.uint8)
        for s in (0.0, shift)
    )  # fmt: skip
    return left, right


def test_refinement_removes_the_pull_towards_whole_pixels() -> None:
    # SGBM's parabola fit puts a quarter-pixel shift near the whole pixel beside it (the
    # "pixel locking" that terraces a smooth surface); the refinement finds the shift itself.
    for shift in (8.25, 8.75):
        left, right = _shifted_pair(shift)
        sgbm = cv2.StereoSGBM.create(minDisparity=0, numDisparities=16, blockSize=5, P1=200,
                                     P2=800, mode=cv2.STEREO_SGBM_MODE_HH4)  # fmt: skip
        disp = sgbm.compute(left, right).astype(np.float32) / 16.0
        disp[disp < 1] = np.nan
        inner = (slice(10, -10), slice(30, -10))
        refined = refine_disparity(left.astype(np.float32), right.astype(np.float32), disp, 7, 3)
        assert abs(float(np.nanmedian(disp[inner])) - shift) > 0.1
        assert abs(float(np.nanmedian(refined[inner])) - shift) < 0.01
        assert float(np.mean(np.isfinite(refined[inner]))) > 0.95


def test_refinement_rejects_a_start_more_than_a_pixel_off_and_flat_windows() -> None:
    left, right = _shifted_pair(8.5)
    start = np.full(left.shape, 8.5, dtype=np.float32)
    start[:, 60:] = 11.0
    left[:, :20] = right[:, :20] = 128
    refined = refine_disparity(left.astype(np.float32), right.astype(np.float32), start, 7, 3)
    assert np.isnan(refined[10:-10, 65:-10]).mean() > 0.9
    assert np.isnan(refined[10:-10, :15]).all()
    assert np.isfinite(refined[10:-10, 30:50]).mean() > 0.95


def test_voxel_sums_added_view_by_view_equal_the_voxel_means_of_all_points() -> None:
    rng = np.random.default_rng(3)
    batches = [rng.uniform(-1.0, 1.0, (rng.integers(50, 400), 3)) for _ in range(12)]
    colours = [rng.integers(0, 256, (len(b), 3)).astype(np.uint8) for b in batches]
    centres = [rng.uniform(2.0, 3.0, 3) for _ in batches]
    sums = _VoxelSums(0.25, min_batch=100)  # merges several times on the way
    for pts, col, centre in zip(batches, colours, centres, strict=True):
        sums.add(pts, col, centre)
    cloud = sums.cloud()
    points = np.concatenate(batches)
    keys, inverse = np.unique(np.floor(points / 0.25), axis=0, return_inverse=True)
    inverse = inverse.ravel()
    expected = np.stack([np.bincount(inverse, points[:, c]) for c in range(3)], axis=1)
    expected /= np.bincount(inverse)[:, None]
    got = np.asarray(cloud.points)
    assert sums.added == len(points) and len(got) == len(keys)
    np.testing.assert_allclose(got[np.lexsort(got.T)], expected[np.lexsort(expected.T)], atol=1e-12)
    normals = np.asarray(cloud.normals)
    assert np.all(np.sum(normals * (np.mean(centres, axis=0) - got), axis=1) > 0)
