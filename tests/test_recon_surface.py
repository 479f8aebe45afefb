from __future__ import annotations

import numpy as np
import open3d as o3d

from stockpile_ros.recon.surface import PoissonOptions, poisson_surface


def _dome(n: int = 20000) -> tuple[np.ndarray, np.ndarray]:
    """Points of an open upper hemisphere (radius 1) on a ground disc: nothing seen below z = 0."""
    rng = np.random.default_rng(0)
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2])
    xy = rng.uniform(-2, 2, (n, 2))
    disc = np.column_stack([xy, np.zeros(n)])[np.linalg.norm(xy, axis=1) > 1.02]
    up = np.tile([0.0, 0.0, 1.0], (len(disc), 1))
    return np.vstack([v, disc]), np.vstack([v, up])


def _far(mesh: o3d.geometry.TriangleMesh, points: np.ndarray) -> float:
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    verts = o3d.geometry.PointCloud(mesh.vertices)
    return float(np.max(np.asarray(verts.compute_point_cloud_distance(cloud))))


def test_trimming_removes_the_bubble_under_the_surface() -> None:
    points, normals = _dome()
    raw, _ = poisson_surface(points, normals, None, PoissonOptions(7, 0.0, 0.0, 1.0))
    trimmed, info = poisson_surface(points, normals, None, PoissonOptions(7))
    # Untrimmed, Poisson closes the open surface with a bubble far from every point.
    assert _far(raw, points) > 0.3
    assert _far(trimmed, points) < 5 * info['point_spacing']
    assert np.asarray(trimmed.vertices)[:, 2].min() > -0.1
    assert info['faces'] < info['faces_before_trimming']


def test_colours_and_simplification() -> None:
    points, normals = _dome(8000)
    colors = np.tile([0.2, 0.5, 0.8], (len(points), 1))
    mesh, info = poisson_surface(points, normals, colors, PoissonOptions(6, target_faces=2000))
    assert len(mesh.triangles) <= 2000 and info['faces'] == len(mesh.triangles)
    np.testing.assert_allclose(
        np.asarray(mesh.vertex_colors).mean(axis=0), [0.2, 0.5, 0.8], atol=0.02
    )
