from __future__ import annotations

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
    fast = grow_regions(adj.across_sides(fwd > t, back > t), seeds)
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
    # 0 -> 1 -> 2 and 3 -> 2 (2 leads nowhere): seed order 3, 0 gives {3, 2} then {0, 1}.
    targets = np.array([[1], [2], [2], [2]])
    labels = grow_regions(targets, np.array([3, 0, 1, 2]))
    assert labels.tolist() == [2, 2, 1, 1]


def test_across_sides_lays_out_passing_neighbours_by_side() -> None:
    # Face 1 meets face 0 along its side 0 (vertices 2-1) and face 2 along its side 1 (1-3).
    f = np.array([[0, 1, 2], [2, 1, 3], [1, 4, 3]])
    adj = face_adjacency(f)
    assert adj.sides is not None
    assert [(int(a), int(b)) for a, b in zip(*adj.sides, strict=True)] == [(1, 3), (4, 8)]
    table = adj.across_sides(np.array([True, False]), np.array([True, True]))
    assert table.tolist() == [[0, 1, 0], [0, 1, 1], [2, 2, 1]]


def test_adjacency_of_two_triangles() -> None:
    adj = face_adjacency(np.array([[0, 1, 2], [2, 1, 3], [4, 5, 6]]))
    assert isinstance(adj, FaceAdjacency)
    assert adj.i.tolist() == [0] and adj.j.tolist() == [1]
    assert adj.neighbour_count().tolist() == [1, 1, 0]


def _adjacency_by_dict(f: np.ndarray) -> list[tuple[int, int, int, int]]:
    """Face pairs and their sides in order of their edge (smaller vertex, larger vertex).

    Along an edge the sides are linked two by two in order: a link of one face's two sides
    (degenerate) is dropped.
    """
    edges: dict[tuple[int, int], list[int]] = {}
    for side, (a, b) in enumerate(zip(f.ravel(), f[:, [1, 2, 0]].ravel(), strict=True)):
        edges.setdefault((min(a, b), max(a, b)), []).append(side)
    pairs = []
    for key in sorted(edges):
        sides = edges[key]
        links = zip(sides[0::2], sides[1::2], strict=False)
        pairs += [(p // 3, q // 3, p, q) for p, q in links if p // 3 != q // 3]
    return pairs


@pytest.mark.parametrize('seed', range(20))
def test_adjacency_equals_edge_dictionary(seed: int) -> None:
    # Few vertices: non-manifold fans, degenerate faces and rows of one vertex ending with the
    # column the next row starts with are all common.
    rng = np.random.default_rng(seed)
    f = rng.integers(0, 7, size=(int(rng.integers(1, 40)), 3))
    adj = face_adjacency(f)
    assert adj.sides is not None
    got = zip(adj.i.tolist(), adj.j.tolist(), *(s.tolist() for s in adj.sides), strict=True)
    assert list(got) == _adjacency_by_dict(f)


@pytest.mark.parametrize('seed', range(10))
def test_vertex_edges_are_the_unique_edges(seed: int) -> None:
    rng = np.random.default_rng(seed)
    f = rng.integers(0, 9, size=(int(rng.integers(1, 40)), 3))
    a, b = f.ravel(), f[:, [1, 2, 0]].ravel()
    want = sorted({(min(x, y), max(x, y)) for x, y in zip(a.tolist(), b.tolist(), strict=True)})
    u, w = face_adjacency(f).vertex_edges
    assert list(zip(u.tolist(), w.tolist(), strict=True)) == want
