from __future__ import annotations

import itertools

import numpy as np
import pytest
from segment_fixtures import small_pile

from stockpile_ros.segment.adjacency import FaceAdjacency, face_adjacency, face_geometry
from stockpile_ros.segment.criterion import edge_scores
from stockpile_ros.segment.region import grow_regions
from stockpile_ros.tools.reference_bfs import reference_bfs


def _noisy_sphere(seed: int) -> tuple[np.ndarray, np.ndarray]:
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=30)
    v = np.asarray(mesh.vertices)
    v = v * (1 + np.random.default_rng(seed).normal(scale=0.03, size=(len(v), 1)))
    return v, np.asarray(mesh.triangles, dtype=np.int64)


def _both(v: np.ndarray, f: np.ndarray, t: float, seeds: np.ndarray) -> tuple[np.ndarray, ...]:
    g = face_geometry(v, f)
    adj = face_adjacency(f)
    fwd, back = edge_scores(g.centroids, g.normals, adj.i, adj.j)
    src = np.concatenate([adj.i[fwd > t], adj.j[back > t]])
    dst = np.concatenate([adj.j[fwd > t], adj.i[back > t]])
    fast = grow_regions(len(f), src, dst, seeds)
    slow = reference_bfs(g.centroids, g.normals, adj, t, seeds)
    return fast, slow, adj, fwd > t, back > t


@pytest.mark.parametrize('t', [0.7, 0.81, 0.9, 1.0])
def test_vectorised_equals_reference_on_pile(t: float) -> None:
    v, f, _ = small_pile()
    fast, slow, *_ = _both(v, f, t, np.arange(len(f)))
    assert fast.max() > 1
    assert np.array_equal(fast, slow)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_vectorised_equals_reference_random_seed_order(seed: int) -> None:
    v, f = _noisy_sphere(seed)
    order = np.random.default_rng(seed).permutation(len(f))
    fast, slow, _, fwd, back = _both(v, f, 0.85, order)
    assert fast.max() > 1
    assert np.array_equal(fast, slow)
    # Mutual passing edges alone would not give these labels: the direction matters somewhere.
    assert np.any(fwd != back)


def test_partial_seed_list_leaves_unreached_faces_zero() -> None:
    v, f = _noisy_sphere(4)
    seeds = np.arange(0, len(f), 7)
    fast, slow, *_ = _both(v, f, 0.99, seeds)
    assert np.array_equal(fast, slow)
    assert np.any(fast == 0)


def test_grow_regions_directed_chain() -> None:
    # 0 -> 1 -> 2 and 3 -> 2: seed order 3, 0 gives {3, 2} then {0, 1}.
    src, dst = np.array([0, 1, 3]), np.array([1, 2, 2])
    labels = grow_regions(4, src, dst, np.array([3, 0, 1, 2]))
    assert labels.tolist() == [2, 2, 1, 1]


def test_adjacency_of_two_triangles() -> None:
    adj = face_adjacency(np.array([[0, 1, 2], [2, 1, 3], [4, 5, 6]]))
    assert isinstance(adj, FaceAdjacency)
    assert adj.i.tolist() == [0] and adj.j.tolist() == [1]
    assert adj.neighbour_count().tolist() == [1, 1, 0]


def _adjacency_by_dict(f: np.ndarray) -> list[tuple[int, int]]:
    """Face pairs in order of their edge (smaller vertex, larger vertex), chained along an edge."""
    edges: dict[tuple[int, int], list[int]] = {}
    for half, (a, b) in enumerate(zip(f.ravel(), f[:, [1, 2, 0]].ravel(), strict=True)):
        edges.setdefault((min(a, b), max(a, b)), []).append(half // 3)
    pairs = []
    for key in sorted(edges):
        chain = edges[key]
        pairs += [(min(p, q), max(p, q)) for p, q in itertools.pairwise(chain) if p != q]
    return pairs


@pytest.mark.parametrize('seed', range(20))
def test_adjacency_equals_edge_dictionary(seed: int) -> None:
    # Few vertices: non-manifold fans, degenerate faces and rows of one vertex ending with the
    # column the next row starts with are all common.
    rng = np.random.default_rng(seed)
    f = rng.integers(0, 7, size=(int(rng.integers(1, 40)), 3))
    adj = face_adjacency(f)
    assert list(zip(adj.i.tolist(), adj.j.tolist(), strict=True)) == _adjacency_by_dict(f)


@pytest.mark.parametrize('seed', range(10))
def test_vertex_edges_are_the_unique_edges(seed: int) -> None:
    rng = np.random.default_rng(seed)
    f = rng.integers(0, 9, size=(int(rng.integers(1, 40)), 3))
    a, b = f.ravel(), f[:, [1, 2, 0]].ravel()
    want = sorted({(min(x, y), max(x, y)) for x, y in zip(a.tolist(), b.tolist(), strict=True)})
    u, w = face_adjacency(f).vertex_edges
    assert list(zip(u.tolist(), w.tolist(), strict=True)) == want
