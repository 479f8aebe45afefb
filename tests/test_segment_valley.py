"""The valley test (a crease at the scale of a few edge lengths), the hand-back of valley faces and
the split of a region that a wider valley cuts in two."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt
import pytest
from segment_fixtures import height_field

from stockpile_ros.segment.adjacency import FaceAdjacency, face_adjacency, face_geometry
from stockpile_ros.segment.cleanup import hand_back
from stockpile_ros.segment.params import SegmentParams, median_edge
from stockpile_ros.segment.segmentation import segment_mesh
from stockpile_ros.segment.valleys import (
    MAX_SMOOTHING_PASSES,
    smoothing_passes,
    split_at_valleys,
    valley_depths,
)

F64 = npt.NDArray[np.float64]


def _domes(x: F64, y: F64) -> F64:
    """Two 5 cm domes 9 cm apart, their crease rounded over about a centimetre (a soft max)."""
    radius, rounding = 0.05, 0.01
    d = [np.sqrt(np.maximum(radius**2 - (x - cx) ** 2 - y**2, 0.0)) for cx in (-0.045, 0.045)]
    # The soft max of two zeros is rounding * log 2: taken off, the ground lies at z = 0.
    soft = rounding * (np.logaddexp(d[0] / rounding, d[1] / rounding) - np.log(2.0))
    return np.asarray(soft)


# The domes are the rocks of interest: 10 cm across. The valley split at its measured depth (off
# by default since the neck split).
DOMES = SegmentParams(min_rock_b=0.1, split_depth_ratio=0.067)


def _valley_area_near(v: F64, f: npt.NDArray[np.int64], x0: float) -> tuple[float, float]:
    geom = face_geometry(v, f)
    valley = (
        valley_depths(v, f, geom, [0.0075], median_edge(v, f), face_adjacency(f).vertex_edges)[0]
        > 0.0005
    )
    near = np.abs(geom.centroids[:, 0] - x0) < 0.01
    return float(geom.areas[valley & near].sum()), float(geom.areas[valley & ~near].sum())


@pytest.mark.parametrize('kind', ['valley', 'roof'])
def test_a_valley_is_found_along_the_crease_and_a_roof_is_not(kind: str) -> None:
    slope = 0.3 if kind == 'valley' else -0.3
    v, f = height_field(lambda x, y: slope * np.abs(x), 0.1, 81)
    near, far = _valley_area_near(v, f, 0.0)
    assert far == 0.0
    assert (near > 0.0) == (kind == 'valley')


def test_the_valley_scale_is_metric_not_a_count_of_faces() -> None:
    coarse = _valley_area_near(*height_field(lambda x, y: 0.3 * np.abs(x), 0.1, 81), 0.0)[0]
    fine = _valley_area_near(*height_field(lambda x, y: 0.3 * np.abs(x), 0.1, 241), 0.0)[0]
    assert fine == pytest.approx(coarse, rel=0.25)


def test_hand_back_splits_a_band_where_the_fronts_meet() -> None:
    # A strip of 10 faces in a row: 1 | free x 8 | 2.
    adj = FaceAdjacency(10, np.arange(9), np.arange(1, 10))
    labels = np.array([1] + [0] * 8 + [2], dtype=np.int32)
    free = np.array([False] + [True] * 8 + [False])
    assert hand_back(labels, adj, free).tolist() == [1] * 5 + [2] * 5
    # Fronts that stop after two rings leave the middle of the band to no region.
    assert hand_back(labels, adj, free, rings=2).tolist() == [1] * 3 + [0] * 4 + [2] * 3
    # Fronts that may only cross edges running right: region 2 takes nothing.
    rightwards = adj.dst > adj.src
    assert hand_back(labels, adj, free, along=rightwards).tolist() == [1] * 9 + [2]


def test_the_top_of_a_rock_sunk_between_two_others_is_not_handed_to_them() -> None:
    # Two 5 cm domes 1 cm apart at their feet, and a 12 mm dome sunk in the gap: its exposed
    # top, about 12 mm across, lies in their valley and is within a valley radius of both.
    def dome(x: F64, y: F64, cx: float, radius: float) -> F64:
        return np.sqrt(np.maximum(radius**2 - (x - cx) ** 2 - y**2, 0.0))

    def big(x: F64, y: F64) -> F64:
        return np.maximum(dome(x, y, -0.055, 0.05), dome(x, y, 0.055, 0.05))

    v, f = height_field(lambda x, y: np.maximum(big(x, y), dome(x, y, 0.0, 0.012)), 0.1, 161)
    seg = segment_mesh(v, f, DOMES)
    c, areas = seg.geometry.centroids, seg.geometry.areas
    top = dome(c[:, 0], c[:, 1], 0.0, 0.012) > big(c[:, 0], c[:, 1]) + 1e-4
    domes = [
        seg.labels[np.argmin(np.linalg.norm(c[:, :2] - [x, 0.0], axis=1))] for x in (-0.055, 0.055)
    ]
    assert len(set(domes)) == 2 and min(domes) > 0
    # The fronts go down the domes' flanks into the valley and stop at its floor, where the
    # sunk rock rises again (handed back by distance alone, 75 % of its top went to the domes).
    assert areas[top & np.isin(seg.labels, domes)].sum() < 0.25 * areas[top].sum()


def test_the_search_stops_at_a_rounded_crease() -> None:
    v, f = height_field(_domes, 0.1, 161)
    seg = segment_mesh(v, f, DOMES)
    assert seg.raw_regions == 2
    xy = seg.geometry.centroids[:, :2]
    tops = [np.argmin(np.linalg.norm(xy - [x, 0.0], axis=1)) for x in (-0.045, 0.045)]
    assert seg.labels[tops[0]] != seg.labels[tops[1]]
    assert min(seg.labels[tops]) > 0
    # Valley faces went back to the domes (the crease is within a valley radius of both): all
    # that is left unlabelled is ground, but for a few faces on the crease's floor where its
    # depth dips along it (no front going down reaches them).
    ground = SegmentParams().ground_tolerance_edges * seg.scale.edge
    above = (seg.labels == 0) & (seg.geometry.centroids[:, 2] >= ground)
    assert seg.geometry.areas[above].sum() < 0.001 * seg.geometry.areas[seg.labels > 0].sum()
    # Without the valley test the face-to-face criterion alone breaks the same mesh into pieces.
    assert segment_mesh(v, f, replace(DOMES, valley_depth_ratio=0.0)).raw_regions > 2


def test_depths_at_several_scales_match_one_scale_at_a_time() -> None:
    v, f = height_field(_domes, 0.1, 81)
    geom = face_geometry(v, f)
    edge = median_edge(v, f)
    both = valley_depths(v, f, geom, [0.015, 0.0075], edge, face_adjacency(f).vertex_edges)
    for radius, depth in zip([0.015, 0.0075], both, strict=True):
        np.testing.assert_allclose(
            depth, valley_depths(v, f, geom, [radius], edge, face_adjacency(f).vertex_edges)[0]
        )


def test_a_tiny_or_degenerate_edge_cannot_make_the_smoothing_run_for_ever() -> None:
    assert smoothing_passes(0.0075, 0.0025) == 18
    assert smoothing_passes(0.0, 0.0025) == 1
    for edge in (1e-9, 1e-200, 0.0):
        assert smoothing_passes(1.0, edge) == MAX_SMOOTHING_PASSES
    # A radius of a billion edge lengths (2e18 rounds uncapped) on a small mesh comes back, after
    # the capped number of rounds: deep in the valley, level far from it.
    v, f = height_field(lambda x, y: 0.3 * np.abs(x), 0.1, 21)
    (depth,) = valley_depths(
        v, f, face_geometry(v, f), [1e9 * 0.01], 0.01, face_adjacency(f).vertex_edges
    )
    assert np.all(np.isfinite(depth))
    centre = np.abs(face_geometry(v, f).centroids[:, 0]) < 0.01
    assert depth[centre].mean() > 0


def test_a_region_cut_by_a_valley_into_two_large_parts_is_split() -> None:
    # A strip of 10 faces, one region; faces 4 and 5 are deep: parts of 4 faces on either side.
    adj = FaceAdjacency(10, np.arange(9), np.arange(1, 10))
    labels = np.ones(10, dtype=np.int32)
    areas = np.ones(10)
    deep = np.zeros(10, dtype=bool)
    deep[[4, 5]] = True
    split = split_at_valleys(labels, adj, areas, deep, min_share=0.3)
    assert split[:5].tolist() == [split[0]] * 5
    assert split[5:].tolist() == [split[9]] * 5
    assert split[0] != split[9]
    # Parts under the minimum share, or a deep band at one end, leave the region whole.
    assert split_at_valleys(labels, adj, areas, deep, min_share=0.5).tolist() == [1] * 10
    end = np.zeros(10, dtype=bool)
    end[[8, 9]] = True
    assert split_at_valleys(labels, adj, areas, end, min_share=0.1).tolist() == [1] * 10


def test_split_faces_go_back_to_their_own_region_only() -> None:
    # 1 1 [1 1 1] 2 2: the deep faces of region 1 sit next to region 2 but stay in region 1's parts.
    adj = FaceAdjacency(12, np.arange(11), np.arange(1, 12))
    labels = np.array([1] * 9 + [2] * 3, dtype=np.int32)
    deep = np.zeros(12, dtype=bool)
    deep[[3, 4, 8]] = True
    split = split_at_valleys(labels, adj, np.ones(12), deep, min_share=0.2)
    assert len(set(split[:9].tolist())) == 2
    assert split[8] == split[7]
    assert split[9:].tolist() == [2, 2, 2]


def test_two_domes_in_one_region_are_split_at_the_crease_between_them() -> None:
    v, f = height_field(_domes, 0.1, 161)
    geom = face_geometry(v, f)
    params = DOMES
    seg = segment_mesh(v, f, params)
    edge = seg.scale.edge
    ground = params.ground_tolerance_edges * edge
    labels = np.where(geom.centroids[:, 2] > ground, 1, 0).astype(np.int32)
    radius = seg.scale.split_radius
    deep = (
        valley_depths(v, f, geom, [radius], edge, face_adjacency(f).vertex_edges)[0]
        > params.split_depth_ratio * radius
    )
    split = split_at_valleys(labels, seg.adjacency, geom.areas, deep, params.split_min_share)
    xy = geom.centroids[:, :2]
    tops = [np.argmin(np.linalg.norm(xy - [x, 0.0], axis=1)) for x in (-0.045, 0.045)]
    assert len(set(split[tops].tolist())) == 2
    assert min(split[tops]) > 0
    # Every face of the region went to one dome or the other.
    assert np.all(split[labels > 0] > 0)
    # One dome alone is not split.
    one = np.where(xy[:, 0] < 0, labels, 0).astype(np.int32)
    assert set(split_at_valleys(one, seg.adjacency, geom.areas, deep, 0.1).tolist()) <= {0, 1}
