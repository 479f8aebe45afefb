from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import open3d as o3d
from recon_synth import look_at, render, scene_mesh

from stockpile_ros.camera import CameraModel
from stockpile_ros.recon.dense import DenseOptions, _depth_stats, _pair_depth, _pick_partners
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
