from __future__ import annotations

import numpy as np
import pytest
from segment_fixtures import height_field

from stockpile_ros.segment.adjacency import face_adjacency, face_geometry
from stockpile_ros.segment.cleanup import drop_unanchored, label_parts, merge_convex_borders


def _split(kind: str, depth: float = 0.05, slope: float = 0.5, floor: float = 0.0) -> np.ndarray:
    sign = -1.0 if kind == 'roof' else 1.0
    v, f = height_field(lambda x, y: sign * slope * np.abs(x), 1.0, 21)
    geom = face_geometry(v, f)
    adj = face_adjacency(f, len(v))
    labels = np.where(geom.centroids[:, 0] < 0, 1, 2).astype(np.int32)
    return merge_convex_borders(v, geom, labels, adj, f, depth, 5, floor)


def test_regions_convex_across_their_border_are_joined() -> None:
    assert set(np.unique(_split('roof')).tolist()) == {1}


def test_regions_meeting_in_a_valley_stay_apart() -> None:
    assert set(np.unique(_split('valley')).tolist()) == {1, 2}


@pytest.mark.parametrize('kind', ['roof', 'valley'])
def test_zero_depth_joins_nothing(kind: str) -> None:
    assert set(np.unique(_split(kind, 0.0)).tolist()) == {1, 2}


@pytest.mark.parametrize(('floor', 'joined'), [(0.0, False), (0.005, False), (0.02, True)])
def test_a_valley_shallower_than_the_least_depth_is_joined(floor: float, joined: bool) -> None:
    # A valley 1 cm deep under the pair's hull (slope 0.02 over half a metre each side): deep
    # for a join of 0.5 % of the regions' root area, shallower than a floor of 2 cm.
    merged = _split('valley', depth=0.005, slope=0.02, floor=floor)
    assert (set(np.unique(merged).tolist()) == {1}) is joined


def _caps(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    # Two round caps side by side, meeting in a crease.
    r = np.minimum(np.hypot(x + 0.25, y), np.hypot(x - 0.25, y))
    return np.sqrt(np.maximum(0.25**2 - r**2, 0.0))


def test_pieces_of_two_caps_join_into_one_region_per_cap() -> None:
    # Each cap cut into quarters: the quarters of a cap lie on its hull and join (each border
    # judged again as its regions grow), the caps stay apart.
    v, f = height_field(_caps, 1.0, 81)
    geom = face_geometry(v, f)
    adj = face_adjacency(f, len(v))
    x, y, z = geom.centroids.T
    cap = (x > 0).astype(np.int32)
    quarter = 1 + 4 * cap + 2 * (y > 0) + (np.abs(x) > 0.25)
    labels = np.where(z > 0.01, quarter, 0).astype(np.int32)
    merged = merge_convex_borders(v, geom, labels, adj, f, 0.05, 5)
    assert set(np.unique(merged[(labels > 0) & (cap == 0)]).tolist()) == {1}
    assert set(np.unique(merged[(labels > 0) & (cap == 1)]).tolist()) == {5}
    assert not merged[labels == 0].any()


def test_left_out_fragments_join_where_convex_and_are_left_out_again_otherwise() -> None:
    # The fragment merge left out a quarter of the left cap (a piece of it) and the whole right
    # cap (a rock in its own right): each is a region again for the join, the quarter joins its
    # cap, and the right cap, joined to nothing that is not left out, is left out again.
    v, f = height_field(_caps, 1.0, 81)
    geom = face_geometry(v, f)
    adj = face_adjacency(f, len(v))
    x, y, z = geom.centroids.T
    up = z > 0.01
    loose = up & ((x > 0) | ((x < -0.25) & (y > 0)))
    labels = np.where(up & ~loose, 7, 0).astype(np.int32)
    parts = label_parts(labels, adj, loose)
    # Two parts (the quarter and the right cap), numbered after every existing id.
    assert set(np.unique(parts[loose]).tolist()) == {8, 9}
    assert (parts[~loose] == labels[~loose]).all()
    merged = drop_unanchored(merge_convex_borders(v, geom, parts, adj, f, 0.05, 5), loose)
    left = set(np.unique(merged[up & (x < 0)]).tolist())
    assert len(left) == 1 and 0 not in left
    assert not merged[x > 0].any()
