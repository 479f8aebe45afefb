from __future__ import annotations

import numpy as np
import pytest
from segment_fixtures import height_field

from stockpile_ros.segment.adjacency import face_adjacency, face_geometry
from stockpile_ros.segment.cleanup import merge_convex_borders


def _split(kind: str, depth: float = 0.05) -> np.ndarray:
    slope = -0.5 if kind == 'roof' else 0.5
    v, f = height_field(lambda x, y: slope * np.abs(x), 1.0, 21)
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
