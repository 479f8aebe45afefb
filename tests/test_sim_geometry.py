from __future__ import annotations

import math

import numpy as np
import pytest

from stockpile_ros.errors import StockpileError
from stockpile_ros.tools.sim.pile import PileConfig, build_pile, parse_gradation
from stockpile_ros.tools.sim.rocks import (
    SHAPES,
    RockMesh,
    icosphere,
    mesh_area,
    mesh_volume,
    principal_dimensions,
    random_rock,
    solid_moments,
)


def _closed_and_oriented(mesh: RockMesh) -> bool:
    f = mesh.faces
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    # Closed and consistently oriented: every directed edge once, and its reverse once.
    uniq = np.unique(directed, axis=0)
    if len(uniq) != len(directed):
        return False
    as_set = {tuple(e) for e in uniq.tolist()}
    return all((b, a) in as_set for a, b in as_set)


def test_sphere_volume_area_and_dimensions_match_analytic() -> None:
    v, f = icosphere(5)
    sphere = RockMesh(v * 0.1, f)
    assert mesh_volume(sphere) == pytest.approx(4 / 3 * math.pi * 0.1**3, rel=2e-3)
    assert mesh_area(sphere) == pytest.approx(4 * math.pi * 0.1**2, rel=2e-3)
    a, _, c, _ = principal_dimensions(sphere)
    assert a == pytest.approx(0.2, rel=1e-3) and c == pytest.approx(0.2, rel=1e-3)


def test_box_volume_moments_and_axes() -> None:
    # A cube from the icosphere's directions projected on the box surface is not exact; use the
    # 12-triangle box directly: 0.4 x 0.2 x 0.1, rotated and shifted.
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
    faces = np.array(
        [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
         [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    )  # fmt: skip
    size = np.array([0.4, 0.2, 0.1])
    angle = 0.7
    rot = np.array(
        [[math.cos(angle), -math.sin(angle), 0], [math.sin(angle), math.cos(angle), 0], [0, 0, 1]]
    )
    box = RockMesh((corners - 0.5) * size @ rot.T + [1.0, 2.0, 0.05], faces)
    assert _closed_and_oriented(box)
    vol, centroid, central = solid_moments(box)
    assert vol == pytest.approx(0.008)
    np.testing.assert_allclose(centroid, [1.0, 2.0, 0.05], atol=1e-12)
    # Second moment of a box about its centre: V * diag(l^2) / 12 in its own axes.
    expected = rot @ np.diag(vol * size**2 / 12) @ rot.T
    np.testing.assert_allclose(central, expected, atol=1e-12)
    a, b, c, axes = principal_dimensions(box)
    assert (a, b, c) == pytest.approx((0.4, 0.2, 0.1))
    assert abs(axes[:, 0] @ rot[:, 0]) == pytest.approx(1.0)


@pytest.mark.parametrize('shape', sorted(SHAPES))
def test_random_rock_is_closed_and_has_the_requested_b(shape: str) -> None:
    rng = np.random.default_rng(5)
    rock = random_rock(rng, 0.2, shape, subdivisions=3)
    assert _closed_and_oriented(rock)
    a, b, c, _ = principal_dimensions(rock)
    assert b == pytest.approx(0.2)
    assert a >= b >= c > 0
    vol = mesh_volume(rock)
    # Between the inscribed-ish and the bounding box volume, and the centroid at the origin.
    assert 0.2 * a * b * c < vol < a * b * c
    np.testing.assert_allclose(solid_moments(rock)[1], 0.0, atol=1e-9)
    if shape == 'flat':
        assert c / b < 0.6
    if shape == 'elongated':
        assert a / b > 1.6


def _sharpest_bend(rock: RockMesh) -> float:
    """The 99th percentile of the angle between neighbouring faces' normals [degrees]."""
    v, f = rock.vertices, rock.faces
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    face = np.tile(np.arange(len(f)), 3)
    key = np.minimum(edges[:, 0], edges[:, 1]) * len(v) + np.maximum(edges[:, 0], edges[:, 1])
    order = np.argsort(key)
    key, face = key[order], face[order]
    pair = key[1:] == key[:-1]
    cos = np.einsum('ij,ij->i', n[face[:-1][pair]], n[face[1:][pair]])
    return float(np.degrees(np.arccos(np.clip(np.percentile(cos, 1), -1.0, 1.0))))


def test_rounding_wears_the_edges_and_draws_nothing() -> None:
    sharp, worn = [], []
    for seed in range(6):
        rng_a, rng_b = np.random.default_rng(seed), np.random.default_rng(seed)
        angular = random_rock(rng_a, 0.2, 'equant', subdivisions=3)
        rounded = random_rock(rng_b, 0.2, 'equant', subdivisions=3, rounding=0.3)
        # The same draws: a bed with rounded rocks has the same sizes, shapes and places.
        assert rng_a.random() == rng_b.random()
        assert _closed_and_oriented(rounded)
        assert principal_dimensions(rounded)[1] == pytest.approx(0.2)
        sharp.append(_sharpest_bend(angular))
        worn.append(_sharpest_bend(rounded))
    # The hull's edges bend 40-60 degrees across one face edge; worn round, under half of it.
    assert min(sharp) > 35.0
    assert max(w / s for w, s in zip(worn, sharp, strict=True)) < 0.5


def test_gradation_parsing_and_sampling_by_mass() -> None:
    g = parse_gradation('D15=0.1,D50=0.15,D85=0.22')
    assert g.percent_passing[0] == 0 and g.percent_passing[-1] == 100
    assert 0.1 in g.sizes and 0.22 in g.sizes
    sizes = g.sample(np.random.default_rng(0), 40000)
    mass = sizes**3
    order = np.argsort(sizes)
    pp = np.cumsum(mass[order]) / mass.sum() * 100
    d50 = sizes[order][np.searchsorted(pp, 50)]
    d15 = sizes[order][np.searchsorted(pp, 15)]
    assert d50 == pytest.approx(0.15, rel=0.03)
    assert d15 == pytest.approx(0.1, rel=0.04)
    for bad in ('abc', '0.3:0.1', 'D50=0.2', 'D50=0.2,D15=0.3'):
        with pytest.raises(StockpileError):
            parse_gradation(bad)


def test_pile_rocks_rest_on_the_ground_or_on_rocks_without_overlap() -> None:
    cfg = PileConfig(rocks=6, gradation=parse_gradation('0.1:0.2'), subdivisions=3)
    rocks = build_pile(np.random.default_rng(3), cfg)
    assert [r.id for r in rocks] == list(range(1, 7))
    lows = [r.mesh.vertices[:, 2].min() for r in rocks]
    assert min(lows) == pytest.approx(0.0, abs=0.01)
    assert all(low > -0.01 for low in lows)
    # No vertex of any rock lies deep inside another rock (checked by ray parity with open3d).
    import open3d as o3d

    for i, r in enumerate(rocks):
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(
            o3d.core.Tensor(r.mesh.vertices.astype(np.float32)),
            o3d.core.Tensor(r.mesh.faces.astype(np.uint32)),
        )
        for j, other in enumerate(rocks):
            if i == j:
                continue
            pts = o3d.core.Tensor(other.mesh.vertices.astype(np.float32))
            inside = scene.compute_occupancy(pts).numpy() > 0.5
            if inside.any():
                depth = scene.compute_distance(pts).numpy()[inside]
                assert depth.max() < 0.006, (i + 1, j + 1, depth.max())
    # Touching: every rock off the ground is within a few mm of another rock.
    for r in rocks:
        if r.mesh.vertices[:, 2].min() > 0.005:
            gaps = []
            for other in rocks:
                if other is r:
                    continue
                scene = o3d.t.geometry.RaycastingScene()
                scene.add_triangles(
                    o3d.core.Tensor(other.mesh.vertices.astype(np.float32)),
                    o3d.core.Tensor(other.mesh.faces.astype(np.uint32)),
                )
                pts = o3d.core.Tensor(r.mesh.vertices.astype(np.float32))
                gaps.append(float(scene.compute_distance(pts).numpy().min()))
            assert min(gaps) < 0.01


@pytest.mark.parametrize('kind', ['arc', 'straight', 'orbit'])
def test_every_path_keeps_the_pile_centre_in_view(kind: str) -> None:
    from stockpile_ros.camera import CameraModel
    from stockpile_ros.tools.sim.camera_path import CartPath, PathConfig

    cam = CameraModel.from_fov(640, 480, 70)
    path = CartPath(PathConfig(kind=kind, heights=(0.8, 1.5), distance=1.5, length=2.0), 9.0)
    centre = np.array([0.0, 0.0, path.cfg.aim_height])
    for t in np.linspace(0.0, 9.0, 37):
        position, rot = path.camera_pose(float(t))
        np.testing.assert_allclose(rot.T @ rot, np.eye(3), atol=1e-12)
        assert np.linalg.det(rot) == pytest.approx(1.0)
        x = rot.T @ (centre - position)
        assert x[2] > 0
        u, v = cam.fx * x[0] / x[2] + cam.cx, cam.fy * x[1] / x[2] + cam.cy
        assert 0 <= u < 640 and 0 <= v < 480
        assert rot[2, 0] == pytest.approx(0.0, abs=1e-12)  # no roll: image x stays level
    assert path.camera_pose(0.0)[0][2] == pytest.approx(0.8)
    assert path.camera_pose(9.0)[0][2] == pytest.approx(1.5)
    if kind == 'orbit':
        start, end = path.base_pose(0.0)[0], path.base_pose(path.pass_time)[0]
        np.testing.assert_allclose(start, end, atol=1e-9)
