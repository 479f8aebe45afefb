"""Work done a block at a time gives exactly what it gives over whole arrays."""

from __future__ import annotations

import numpy as np
import pytest

from stockpile_ros.segment import blocks
from stockpile_ros.segment.adjacency import face_adjacency, face_geometry
from stockpile_ros.segment.criterion import edge_score, edge_scores


def test_blocks_cover_the_range_once_in_order(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(blocks, 'BLOCK', 4)
    assert [(s.start, s.stop) for s in blocks.blocks(10)] == [(0, 4), (4, 8), (8, 10)]
    assert list(blocks.blocks(0)) == []


@pytest.mark.parametrize('size', [1, 7, 1000])
def test_geometry_and_scores_in_blocks_equal_those_over_whole_arrays(
    monkeypatch: pytest.MonkeyPatch, size: int
) -> None:
    # 400 faces in blocks of 1, of 7 (the last one short) and in a single short block.
    rng = np.random.default_rng(5)
    v = rng.normal(size=(120, 3))
    f = rng.integers(0, 120, size=(400, 3))
    f[0] = [3, 3, 4]  # degenerate: zero normal, zero area
    whole = face_geometry(v, f)
    monkeypatch.setattr(blocks, 'BLOCK', size)
    g = face_geometry(v, f)
    for got, want in zip(
        (g.centroids, g.normals, g.areas),
        (whole.centroids, whole.normals, whole.areas),
        strict=True,
    ):
        assert np.array_equal(got, want)
    cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    norm = np.linalg.norm(cross, axis=1)
    assert np.allclose(g.areas, 0.5 * norm, rtol=1e-12, atol=0)
    flat = norm == 0
    assert flat[0]
    assert np.allclose(g.normals[~flat], cross[~flat] / norm[~flat, None], rtol=0, atol=1e-12)
    assert not g.normals[flat].any()
    assert np.allclose(g.centroids, (v[f[:, 0]] + v[f[:, 1]] + v[f[:, 2]]) / 3.0, rtol=1e-12)
    adj = face_adjacency(f)
    assert len(adj.i) > 50
    fwd, back = edge_scores(g.centroids, g.normals, adj.i, adj.j)
    c, n = g.centroids.tolist(), g.normals.tolist()
    for k, (a, b) in enumerate(zip(adj.i.tolist(), adj.j.tolist(), strict=True)):
        assert fwd[k] == edge_score(c[a], c[b], n[a], n[b])
        assert back[k] == edge_score(c[b], c[a], n[b], n[a])
