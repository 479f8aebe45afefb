from __future__ import annotations

import numpy as np

from stockpile_ros.segment.adjacency import face_adjacency, face_geometry
from stockpile_ros.segment.criterion import PAPER_THRESHOLD, edge_score, edge_scores
from stockpile_ros.segment.params import SegmentParams
from stockpile_ros.segment.segmentation import segment_mesh


def _hinge(bend_deg: float, n: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Strip of quads along y: flat for x < 0, bent by ``bend_deg`` about the y axis for x > 0.

    Positive bends go down (a convex ridge along x = 0), negative go up (a concave valley).
    """
    phi = np.radians(bend_deg)
    xs = np.array([-2.0, -1.0, 0.0, 1.0, 2.0])
    verts = []
    for y in range(n + 1):
        for x in xs:
            if x <= 0:
                verts.append((x, float(y), 0.0))
            else:
                verts.append((x * np.cos(phi), float(y), -x * np.sin(phi)))
    verts_a = np.array(verts)
    nx = len(xs)
    faces = []
    for y in range(n):
        for k in range(nx - 1):
            a, b = y * nx + k, y * nx + k + 1
            c, d = a + nx, b + nx
            faces += [(a, b, d), (a, d, c)]  # counter-clockwise seen from +z: normals up
    return verts_a, np.array(faces)


def _crossing_scores(bend_deg: float) -> np.ndarray:
    v, f = _hinge(bend_deg)
    g = face_geometry(v, f)
    adj = face_adjacency(f)
    fwd, back = edge_scores(g.centroids, g.normals, adj.i, adj.j)
    left = g.centroids[:, 0] < 0
    cross = left[adj.i] != left[adj.j]
    return np.concatenate([fwd[cross], back[cross]])


def test_normals_point_up_on_the_flat_side() -> None:
    v, f = _hinge(0.0)
    assert np.allclose(face_geometry(v, f).normals, [0, 0, 1])


def test_convex_ridge_passes_and_concave_crease_stops() -> None:
    # Convex bends pass, even sharp ones: c . n_i > 0 adds to n_i . n_j.
    for bend in (20.0, 45.0, 70.0):
        assert np.all(_crossing_scores(bend) > PAPER_THRESHOLD), bend
    # A slight concave bend passes, a sharp concave crease stops growth.
    assert np.all(_crossing_scores(-10.0) > PAPER_THRESHOLD)
    assert np.all(_crossing_scores(-45.0) < PAPER_THRESHOLD)
    assert np.all(_crossing_scores(-60.0) < PAPER_THRESHOLD)


def test_search_crosses_ridge_but_not_valley() -> None:
    params = SegmentParams.paper()
    ridge = segment_mesh(*_hinge(50.0), params)
    valley = segment_mesh(*_hinge(-50.0), params)
    assert ridge.labels.max() == 1
    assert valley.labels.max() == 2
    left = valley.geometry.centroids[:, 0] < 0
    assert len(np.unique(valley.labels[left])) == 1
    assert len(np.unique(valley.labels[~left])) == 1


def test_scalar_and_vector_scores_are_identical() -> None:
    rng = np.random.default_rng(0)
    c = rng.normal(size=(50, 3))
    n = rng.normal(size=(50, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    i, j = np.arange(0, 25), np.arange(25, 50)
    fwd, back = edge_scores(c, n, i, j)
    for k in range(25):
        a, b = int(i[k]), int(j[k])
        assert fwd[k] == edge_score(tuple(c[a]), tuple(c[b]), tuple(n[a]), tuple(n[b]))
        assert back[k] == edge_score(tuple(c[b]), tuple(c[a]), tuple(n[b]), tuple(n[a]))
