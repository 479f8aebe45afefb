from __future__ import annotations

import cv2
import numpy as np
import pytest

from stockpile_ros.camera import CameraModel
from stockpile_ros.tools.sim.camera_path import CartPath, PathConfig, quat_from_matrix
from stockpile_ros.tools.sim.pile import PileConfig, parse_gradation
from stockpile_ros.tools.sim.render import BOARD_LABEL, Renderer, linear_to_srgb8
from stockpile_ros.tools.sim.scene import Scene, SceneConfig, build_scene
from stockpile_ros.tools.sim.texture import charuco_board
from stockpile_ros.tools.sim.truth import VisibilityAccumulator


@pytest.fixture(scope='module')
def scene() -> Scene:
    pile = PileConfig(rocks=4, gradation=parse_gradation('0.12:0.2'), subdivisions=3)
    return build_scene(11, SceneConfig(pile=pile, ground_px=256))


def _look_down(at: np.ndarray, height: float) -> tuple[np.ndarray, np.ndarray]:
    """Camera straight above ``at``: optical z down, x along world x."""
    rot = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
    return np.array([at[0], at[1], height]), rot


def test_labels_agree_with_truth_meshes_projected_through_the_true_pose(scene: Scene) -> None:
    cam = CameraModel.from_fov(200, 150, 60)
    renderer = Renderer(scene.rocks, cam, scene.rock_textures, scene.ground, scene.board, threads=1)
    position, rot = CartPath(PathConfig(heights=(0.9,), distance=0.8), 1.0).camera_pose(0.5)
    res = renderer.render(position, rot)
    assert res.linear.shape == (150, 200, 3) and np.isfinite(res.linear).all()
    assert set(np.unique(res.labels)) >= {0, 1, 2, 3, 4}

    # Independent z-buffer: splat every truth vertex through the true pose and intrinsics.
    zbuf = np.full((150, 200), np.inf)
    zlab = np.zeros((150, 200), dtype=np.int32)
    for rock in scene.rocks:
        cam_pts = (rock.mesh.vertices - position) @ rot
        uv = cam_pts[:, :2] / cam_pts[:, 2:3] * [cam.fx, cam.fy] + [cam.cx, cam.cy]
        px = np.round(uv).astype(int)
        ok = (px[:, 0] >= 0) & (px[:, 0] < 200) & (px[:, 1] >= 0) & (px[:, 1] < 150)
        for (u, v), z in zip(px[ok], cam_pts[ok, 2], strict=True):
            if z < zbuf[v, u]:
                zbuf[v, u], zlab[v, u] = z, rock.id
    agree_depth = np.abs(zbuf - res.depth) < 0.004
    assert agree_depth.sum() > 200
    assert np.mean(zlab[agree_depth] == res.labels[agree_depth]) > 0.98

    # Back-projected rock pixels lie on the surface of the rock they are labelled with.
    import open3d as o3d

    v, u = np.nonzero(res.labels > 0)
    rays = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones(len(u))], axis=1)
    world = position + (rays * res.depth[v, u][:, None]) @ rot.T
    for rock in scene.rocks:
        mine = res.labels[v, u] == rock.id
        rs = o3d.t.geometry.RaycastingScene()
        rs.add_triangles(
            o3d.core.Tensor(rock.mesh.vertices.astype(np.float32)),
            o3d.core.Tensor(rock.mesh.faces.astype(np.uint32)),
        )
        dist = rs.compute_distance(o3d.core.Tensor(world[mine].astype(np.float32))).numpy()
        assert dist.max() < 2e-3


def test_charuco_board_detected_where_the_truth_says(scene: Scene) -> None:
    board = scene.board
    assert board is not None
    cam = CameraModel.from_fov(640, 480, 50)
    renderer = Renderer(scene.rocks, cam, scene.rock_textures, scene.ground, board, threads=1)
    corners = board.charuco_corners_world()
    position, rot = _look_down(corners.mean(axis=0), 0.7)
    res = renderer.render(position, rot)
    assert (res.labels == BOARD_LABEL).sum() > 1000
    img = linear_to_srgb8(res.linear)
    detector = cv2.aruco.CharucoDetector(charuco_board(board))
    found, ids, _, _ = detector.detectBoard(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY))
    assert ids is not None and len(ids) >= 10
    truth = corners[ids.ravel()]
    cam_pts = (truth - position) @ rot
    uv = cam_pts[:, :2] / cam_pts[:, 2:3] * [cam.fx, cam.fy] + [cam.cx, cam.cy]
    err = np.linalg.norm(found.reshape(-1, 2) - uv, axis=1)
    assert err.max() < 0.6


def test_visibility_counts_only_what_a_view_hit(scene: Scene) -> None:
    cam = CameraModel.from_fov(160, 120, 60)
    renderer = Renderer(scene.rocks, cam, scene.rock_textures, scene.ground, None, threads=1)
    acc = VisibilityAccumulator(scene.rocks)
    top = max(scene.rocks, key=lambda r: r.mesh.vertices[:, 2].max())
    position, rot = _look_down(top.mesh.vertices.mean(axis=0), 1.0)
    acc.add(renderer.render(position, rot).rock_triangles)
    seen_from_above = acc.fractions()
    # From straight above at most the upper half of a rock shows; the top rock shows a good part.
    assert all(0.0 <= f <= 0.7 for f in seen_from_above.values())
    assert seen_from_above[top.id] > 0.2
    path = CartPath(PathConfig(kind='orbit', heights=(0.6,), distance=0.9), 4.0)
    for t in np.linspace(0, 4, 5):
        acc.add(renderer.render(*path.camera_pose(float(t))).rock_triangles)
    more = acc.fractions()
    assert all(more[k] >= seen_from_above[k] for k in more)
    assert sum(more.values()) > sum(seen_from_above.values())


def test_quaternion_round_trip() -> None:
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(2)
    for _ in range(50):
        r = Rotation.random(random_state=rng.integers(1 << 30)).as_matrix()
        q = quat_from_matrix(r)
        np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), r, atol=1e-9)


def test_motion_blur_smears_along_the_motion_only() -> None:
    from stockpile_ros.tools.sim.record import finish_image, motion_blur

    img = np.zeros((41, 41, 3), dtype=np.float32)
    img[20, 20] = 1.0
    out = motion_blur(img, np.array([8.0, 0.0]))
    assert out.sum() == pytest.approx(3.0, rel=1e-5)  # energy kept
    row = out[20, :, 0]
    assert (row > 0).sum() >= 8 and out[:, 20, 0].sum() == pytest.approx(row[20])
    assert motion_blur(img, np.array([0.3, 0.2])) is img  # under a pixel: untouched
    flat = np.full((30, 30, 3), 0.2, dtype=np.float32)
    noisy = finish_image(flat, np.random.default_rng(0), 2.0).astype(float)
    clean = finish_image(flat, np.random.default_rng(0), 0.0).astype(float)
    assert clean.std() == 0 and 1.0 < noisy.std() < 3.0
    assert abs(noisy.mean() - clean.mean()) < 0.5
