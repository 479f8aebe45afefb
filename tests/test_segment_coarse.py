"""Valley depths at wide radii come from a coarser graph and agree with smoothing the mesh."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest
from segment_fixtures import height_field

from stockpile_ros.segment import valleys
from stockpile_ros.segment.adjacency import face_adjacency, face_geometry
from stockpile_ros.segment.params import median_edge
from stockpile_ros.segment.valleys import valley_depths

F64 = npt.NDArray[np.float64]


def _two_caps(x: F64, y: F64) -> F64:
    # Spheres of radius 0.6 m on two 1 m cells side by side: a crease at x = 0, ground round them.
    d2 = (np.abs(x) - 0.5) ** 2 + y**2
    return np.asarray(np.sqrt(np.maximum(0.36 - d2, 0.0)))


def test_a_wide_radius_on_the_coarse_graph_finds_the_valleys_of_the_mesh(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    v, f = height_field(_two_caps, 1.0, 121)
    geom = face_geometry(v, f)
    edge = median_edge(v, f)
    radius = 8 * edge
    assert radius / valleys.COARSE_CELLS >= valleys.COARSE_MIN_EDGES * edge
    (coarse,) = valley_depths(v, f, geom, [radius], edge, face_adjacency(f).vertex_edges)
    monkeypatch.setattr(valleys, 'COARSE_MIN_EDGES', float('inf'))
    (mesh,) = valley_depths(v, f, geom, [radius], edge, face_adjacency(f).vertex_edges)
    x, y, z = geom.centroids.T
    # On the rocks (the ground is left out of the search) and away from the mesh's border, where
    # the cubes of the coarse graph are cut.
    rock = (z > edge) & (np.abs(x) < 1 - radius) & (np.abs(y) < 1 - radius)
    assert np.corrcoef(coarse[rock], mesh[rock])[0, 1] > 0.95
    threshold = 0.067 * radius
    assert np.mean((coarse > threshold)[rock] == (mesh > threshold)[rock]) > 0.95
    # The crease between the caps is a valley either way, their tops are not.
    crease = (np.abs(x) < edge) & (np.abs(y) < 0.2)
    tops = np.hypot(np.abs(x) - 0.5, y) < 0.1
    for depth in (coarse, mesh):
        assert np.mean(depth[crease] > threshold) > 0.9
        assert not np.any(depth[tops] > threshold)
