from __future__ import annotations

import numpy as np
import pytest

from stockpile_ros.segment.adjacency import face_adjacency, face_geometry
from stockpile_ros.segment.segmentation import merge_convex_borders


def _height_field(kind: str) -> tuple[np.ndarray, np.ndarray]:
    """A 21 x 21 grid over [-1, 1]^2, split along x = 0: a roof (convex) or a valley (concave)."""
    n = 21
    x, y = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n), indexing='ij')
    z = -0.5 * np.abs(x) if kind == 'roof' else 0.5 * np.abs(x)
    v = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    k = np.arange(n * n).reshape(n, n)
    a, b, c, d = k[:-1, :-1].ravel(), k[1:, :-1].ravel(), k[1:, 1:].ravel(), k[:-1, 1:].ravel()
    f = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return v, f


def _split(kind: str, depth: float = 0.05) -> np.ndarray:
    v, f = _height_field(kind)
    geom = face_geometry(v, f)
    adj = face_adjacency(f, len(v))
    labels = np.where(geom.centroids[:, 0] < 0, 1, 2).astype(np.int32)
    return merge_convex_borders(v, geom, labels, adj, f, depth, 5)


def test_regions_convex_across_their_border_are_joined() -> None:
    assert set(np.unique(_split('roof')).tolist()) == {1}


def test_regions_meeting_in_a_valley_stay_apart() -> None:
    assert set(np.unique(_split('valley')).tolist()) == {1, 2}


@pytest.mark.parametrize('kind', ['roof', 'valley'])
def test_zero_depth_joins_nothing(kind: str) -> None:
    assert set(np.unique(_split(kind, 0.0)).tolist()) == {1, 2}
